"""Which physical sensor an array board carries, and the taxel calibrations the host reads it with: the sensor records
(:mod:`.records`) for an array's package, as :mod:`.board_sensor` is for a single taxel's.

An array's board holds no calibration (docs/bundle.md section 4, record version 3): the host evaluates each taxel's.
``upload --sensor ID`` writes the array's record carrying the **set hash** of the sensor's current taxel calibrations
(:func:`set_sha256`) where the package's record carries taxel 0's calibration hash, and the identity block naming the
sensor, the newest of those calibrations' dates and the same set hash. ``info``, ``stream``, ``record`` and ``check``
then read that block, and when the board carries the set hash of the current calibrations of the sensor it names (or
of ``--sensor ID``), the host evaluates each taxel with that sensor's calibration of it from its record instead of the
package's. A sensor takes part only once every taxel has a calibration of the skin in use: ``upload --sensor``
refuses one that lacks any, naming the taxel.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import sys
from typing import Any, Dict, List, Optional, Sequence, Tuple

from . import records
from .board_sensor import current_calibration, named_sensor, refuse_other_design
from .calibration_json import calibration_sha256
from .cli_shared import UsageError
from .device import CalibrationMismatch, Device
from .frames import DeviceInfo
from .identity import Identity
from .taxels import ArrayCalibration, WrongFirmware

__all__ = ["ArrayLink", "SensorSet", "checked_info", "link", "sensor_set", "set_sha256"]


def set_sha256(shas: Sequence[str]) -> str:
    """The set hash of an array's taxel calibrations: the SHA-256 (hex) of their calibration SHA-256s (each the
    canonical hash of docs/bundle.md section 2, 64 lower-case hex digits) in taxel order, joined by commas, as
    ASCII. Its first 16 hex digits are what the board's record and identity block carry."""
    return hashlib.sha256(",".join(s.lower() for s in shas).encode("ascii")).hexdigest()


@dataclasses.dataclass(frozen=True)
class SensorSet:
    """A sensor's current calibration of every taxel: the ``events``, the calibration.json ``data`` of each, their
    hashes, the set hash and the newest calibration's date (UTC ISO 8601)."""

    events: Tuple[Dict[str, Any], ...]
    data: Tuple[dict, ...]
    shas: Tuple[str, ...]
    sha256: str
    date: str

    def identity(self, sensor_id: str) -> Identity:
        return Identity(sensor_id, self.date, self.sha256[:16])


def _collect(sensor: records.Sensor, taxels: int, strict: bool) -> SensorSet:
    """The sensor's set; with ``strict`` every guard is a :class:`UsageError` (board_sensor.current_calibration),
    else the records' own :class:`~.records.RecordError` passes through."""
    events: List[Dict[str, Any]] = []
    data: List[dict] = []
    for k in range(taxels):
        event, cal = current_calibration(sensor, k) if strict else sensor.current_calibration(k)
        events.append(event)
        data.append(cal)
    shas = tuple(calibration_sha256(c) for c in data)
    date = max(str(e.get("date", "")) for e in events)
    return SensorSet(tuple(events), tuple(data), shas, set_sha256(shas), date)


def sensor_set(sensor: records.Sensor, taxels: int) -> SensorSet:
    """The sensor's current calibration of each of ``taxels`` taxels, fitted to this package's design;
    :class:`UsageError` naming the first taxel without one, or one fitted to another design."""
    return _collect(sensor, taxels, strict=True)


@dataclasses.dataclass(frozen=True)
class ArrayLink:
    """What :func:`link` found: the board's ``identity`` (None without one), the ``sensor`` whose record applies
    (None: the package's calibrations), its current ``calibrations`` when the board carries them, and the ``array``
    to read the board with (the package's, or the sensor's calibrations)."""

    identity: Optional[Identity]
    sensor: Optional[records.Sensor]
    calibrations: Optional[SensorSet]
    array: ArrayCalibration


def link(device: Device, info: DeviceInfo, args: argparse.Namespace, array: ArrayCalibration) -> ArrayLink:
    """Read the board's identity and, when the board carries the set hash of the current taxel calibrations of the
    sensor it names (or of ``args.sensor``), read it with those (:attr:`ArrayLink.array`).

    With ``--sensor ID``: :class:`UsageError` when the record is missing, or the board names another sensor, or a
    calibration was fitted to another design; :class:`~.device.CalibrationMismatch` when the sensor has a calibration
    of every taxel and the board carries another set. Without it, a sensor without a record here, or without every
    taxel calibrated, leaves the package's calibrations in place."""
    found, sensor = named_sensor(device, args)
    wanted = getattr(args, "sensor", None)
    if sensor is None:
        return ArrayLink(found, None, None, array)
    try:
        current = _collect(sensor, array.taxels, strict=False)
        for event in current.events:
            refuse_other_design(sensor, event)
    except records.RecordError as exc:
        if wanted and exc.what != "sensor":  # a record that cannot be read, not a taxel without a calibration yet
            raise UsageError(str(exc)) from None
        return ArrayLink(found, sensor if wanted else None, None, array)
    except UsageError:
        if wanted:
            raise
        return ArrayLink(found, None, None, array)
    if current.sha256[:16] == info.calibration_hash.lower():
        return ArrayLink(found, sensor, current, array.with_calibrations(current.data, current.sha256[:16]))
    if wanted:
        raise CalibrationMismatch(
            f"the board on {device.port} carries calibrations {info.calibration_hash}, not sensor {sensor.id}'s "
            f"current taxel calibrations {current.sha256[:16]} (the newest of {current.date}): write them with "
            f"magfab-readout upload --sensor {sensor.id}")
    return ArrayLink(found, None, None, array)


def checked_info(device: Device, array: ArrayCalibration, info=None) -> DeviceInfo:
    """The board's info line (``info``, or asked now), refused when it reads another number of chips
    than the array has, or carries another hash than ``array.board_hash`` (the package's: taxel 0's calibration.json;
    a sensor's: its set hash)."""
    info = device.info() if info is None else info
    if info.taxels != array.taxels:
        raise WrongFirmware("the board on {} reads {} chip{} but this readout package is for an array of {} taxels: "
                            "flash this build's firmware, or install the readout package of the board's build".format(
                                device.port, info.taxels, "" if info.taxels == 1 else "s", array.taxels))
    for warning in device.check_info(info, array.board_hash):
        print("magfab-readout: warning: " + warning, file=sys.stderr)
    return info
