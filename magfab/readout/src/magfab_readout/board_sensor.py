"""Which physical sensor a board carries, and the calibration it runs: the sensor records (:mod:`.records`) as the
readout's commands use them.

``upload --sensor ID`` writes the sensor's current calibration (from its record, not the package's) and the
identity block (:mod:`.identity`) naming the sensor; ``info``, ``record``, ``stream --check`` and ``check`` then read
that block, and when the board runs the current calibration of the sensor it names (or of ``--sensor ID``), that
calibration is the one the host checks the board against and computes with, where otherwise only the package's
embedded one is. ``check --sensor ID`` appends its verdict to the record.

The guards are usage errors (:class:`~.cli_shared.UsageError`, exit status 2, nothing written): no record or no
calibration yet, a calibration fitted to another design than this package's, a board that names another sensor.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import Any, Dict, Optional, Tuple

from . import _build, records
from .calibration import Calibration
from .calibration_json import calibration_sha256
from .cli_shared import UsageError
from .device import CalibrationMismatch, Device
from .frames import DeviceInfo
from .identity import Identity

__all__ = ["Link", "add_options", "current_calibration", "link", "named_sensor", "open_record", "refuse_named_board",
           "refuse_other_design", "refuse_other_sensor", "sensor_line"]


def add_options(parser: argparse.ArgumentParser, what: str) -> None:
    """``--sensor ID`` (meaning ``what``) and ``--sensors ROOT`` on a command's parser."""
    group = parser.add_argument_group("sensor record")
    group.add_argument("--sensor", metavar="ID", help=what)
    group.add_argument("--sensors", metavar="ROOT", help="the sensor records' root folder (default: $"
                       f"{records.ROOT_ENV} when set, else the nearest sensors/ folder here or above)")


def _root(args: argparse.Namespace) -> Path:
    return records.find_root(Path(args.sensors) if getattr(args, "sensors", None) else None)


def open_record(args: argparse.Namespace, sensor_id: str) -> records.Sensor:
    """The record of ``sensor_id`` under the root the options name; :class:`UsageError` when there is none."""
    try:
        return records.open_sensor(_root(args), sensor_id)
    except records.RecordError as exc:
        raise UsageError(str(exc)) from None


def current_calibration(sensor: records.Sensor, taxel: Optional[int] = None) -> Tuple[Dict[str, Any], dict]:
    """(calibration event, calibration.json) of the sensor's current calibration, fitted to this package's design;
    :class:`UsageError` when it has none yet or when it was fitted to another design (spec hash)."""
    try:
        event, data = sensor.current_calibration(taxel)
    except records.RecordError as exc:
        raise UsageError(str(exc)) from None
    refuse_other_design(sensor, event)
    return event, data


def refuse_other_design(sensor: records.Sensor, event: Dict[str, Any]) -> None:
    """:class:`UsageError` when the calibration ``event`` was fitted to another design than this package's."""
    try:
        spec = event.get("spec_sha256") or sensor.info.get("spec_sha256")
    except records.RecordError as exc:
        raise UsageError(str(exc)) from None
    if spec != _build.SPEC_SHA256:
        raise UsageError("sensor {}: its calibration of {} was fitted to another design (spec {}) than this readout "
                         "package's (spec {}, {}): install the readout package of the sensor's build".format(
                             sensor.id, event.get("date", "?"), str(spec)[:16], _build.SPEC_SHA256[:16],
                             _build.SPEC_NAME))


def refuse_other_sensor(device: Device, found: Optional[Identity], sensor_id: str, hint: str) -> None:
    """:class:`UsageError` when the board's identity names another sensor than ``sensor_id``."""
    if found is not None and found.sensor_id != sensor_id:
        raise UsageError(f"the board on {device.port} reports sensor {found.sensor_id}, not {sensor_id}: {hint}")


def refuse_named_board(device: Device, force: bool) -> Optional[Identity]:
    """The board's identity; :class:`UsageError` when it names a sensor and ``force`` is not given: a plain
    ``upload`` would put the package's provisional calibration over that sensor's measured one."""
    found = device.read_identity()
    if found is not None and not force:
        raise UsageError(f"this board is sensor {found.sensor_id}: upload --sensor {found.sensor_id}, or --force")
    return found


def sensor_line(found: Optional[Identity], running: str) -> str:
    """``info``'s line naming the sensor the board's EEPROM names, and its calibration's date."""
    if found is None:
        return "sensor:  no sensor ID on this board (upload --sensor ID)\n"
    line = f"sensor:  {found.sensor_id}, calibration of {found.calibration_date} ({found.calibration_sha16})"
    if found.calibration_sha16 != running.lower():
        line += (f"; the board runs calibration {running} since, not that one (magfab-readout upload --sensor "
                 f"{found.sensor_id} writes the sensor's current one)")
    return line + "\n"


@dataclasses.dataclass(frozen=True)
class Link:
    """What :func:`link` found: the board's ``identity`` (None without one), the ``sensor`` whose record applies
    (None: the package's calibration), and the calibration ``event`` of that record the board runs: its current one,
    or (``superseded``) an earlier one the record keeps, e.g. the old skin's after a re-skin."""

    identity: Optional[Identity]
    sensor: Optional[records.Sensor]
    event: Optional[Dict[str, Any]]
    superseded: bool = False

    def running_note(self, running: str) -> str:
        """One line on a calibration the board runs that is not the one it names: the old skin's
        (:meth:`superseded_note`), or one no record here keeps (e.g. a calibration file written with ``upload
        --force`` over a board that names a sensor); "" when the board runs what it names, or names nothing."""
        if self.superseded:
            return self.superseded_note()
        found = self.identity
        if found is None or self.event is not None or found.calibration_sha16 == running.lower():
            return ""
        return (f"the board names sensor {found.sensor_id} and its calibration of {found.calibration_date} "
                f"({found.calibration_sha16}) but runs calibration {running}: its forces are that calibration's; "
                f"magfab-readout upload --sensor {found.sensor_id} writes the sensor's current one")

    def superseded_note(self) -> str:
        """One line on a superseded calibration the board runs ("" when it runs the current one, or none)."""
        if not self.superseded or self.sensor is None or self.event is None:
            return ""
        return (f"the board runs sensor {self.sensor.id}'s calibration of {self.event.get('date', '?')} (skin "
                f"{self.event.get('epoch', '?')}), not one of the skin in use (skin {self.sensor.epoch()}): its forces "
                f"are that calibration's; calibrate this skin and write it with magfab-readout upload --sensor "
                f"{self.sensor.id}")


def _kept(sensor: records.Sensor, running: str) -> Optional[Tuple[Dict[str, Any], dict]]:
    """(event, calibration.json) of the newest calibration in ``sensor``'s record whose hash is ``running`` (the
    board's), of any skin; None when the record keeps none."""
    for event in reversed(list(sensor.calibrations())):
        sha = event["files"].get("calibration.json")
        if sha is None:
            continue
        try:
            data = sensor.json_file(sha, "calibration.json")
        except records.RecordError:
            continue
        if calibration_sha256(data)[:16] == running.lower():
            return event, data
    return None


def _superseded(device: Device, info: DeviceInfo, found: Optional[Identity], sensor: records.Sensor) -> Link:
    """The board runs a calibration its sensor's record keeps but no longer current (the old skin's): that one, as
    the device's, flagged; else the package's calibration (:class:`Link` with no sensor)."""
    kept = _kept(sensor, info.calibration_hash)
    if kept is None:
        return Link(found, None, None)
    device.calibration = Calibration(kept[1])
    return Link(found, sensor, kept[0], superseded=True)


def named_sensor(device: Device, args: argparse.Namespace) -> Tuple[Optional[Identity], Optional[records.Sensor]]:
    """(the board's identity, the record that applies): ``--sensor ID``'s (:class:`UsageError` when it has none or
    the board names another sensor), else the record of the sensor the board names when it is found here, else
    None."""
    found = device.read_identity()
    wanted = getattr(args, "sensor", None)
    if wanted:
        sensor = open_record(args, wanted)
        refuse_other_sensor(device, found, wanted, "connect that sensor's board, or name this one's")
        return found, sensor
    if found is None:
        return None, None
    try:
        return found, records.open_sensor(_root(args), found.sensor_id)
    except records.RecordError:  # no root here, or none holding that sensor's record
        return found, None


def link(device: Device, info: DeviceInfo, args: argparse.Namespace) -> Link:
    """Read the board's identity and, when the board runs the current calibration of the sensor it names (or of
    ``args.sensor``), make that calibration ``device.calibration`` (what ``check_info`` and the host's forces use).

    With ``--sensor ID``: :class:`UsageError` when the record is missing, or the board names another sensor, or
    the calibration was fitted to another design; :class:`~.device.CalibrationMismatch` when the sensor has a
    calibration and the board runs another. Without it, a board's sensor without a record here leaves the package's
    calibration in place, and a board running an earlier calibration its record keeps (the old skin's, after a
    re-skin) is read with that one, flagged ``superseded``."""
    found, sensor = named_sensor(device, args)
    wanted = getattr(args, "sensor", None)
    if sensor is None:
        return Link(found, None, None)
    try:
        event, data = sensor.current_calibration()
    except records.RecordError as exc:
        if wanted and exc.what != "sensor":  # a record that cannot be read, not one without a calibration yet
            raise UsageError(str(exc)) from None
        if wanted:
            return Link(found, sensor, None)  # the board runs the package's calibration
        return _superseded(device, info, found, sensor)  # a new skin's board may still run the old skin's
    try:
        refuse_other_design(sensor, event)
    except UsageError:
        if wanted:
            raise
        return Link(found, None, None)
    sha = calibration_sha256(data)
    if sha[:16] == info.calibration_hash.lower():
        device.calibration = Calibration(data)
        return Link(found, sensor, event)
    if wanted:
        raise CalibrationMismatch(
            f"the board on {device.port} runs calibration {info.calibration_hash}, not sensor {sensor.id}'s current "
            f"calibration {sha[:16]} (of {event.get('date', '?')}): write it with magfab-readout upload --sensor "
            f"{sensor.id}")
    return _superseded(device, info, found, sensor)
