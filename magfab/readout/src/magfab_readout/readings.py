"""What the readout decodes: a sample with its status flags and fault, the firmware's info line and its EEPROM
replies (the wire formats that carry them: :mod:`.frames`, docs/bundle.md section 3).

A status byte's bits: :data:`STATUS_OUTSIDE_REGION`, :data:`STATUS_CHIP_ERROR`, :data:`STATUS_FULL_SCALE`,
:data:`STATUS_RECOVERED`; a chip-error sample's fault word: the stage where the fault struck in its high byte
(:data:`FAULT_STAGES`), the firmware's error in its low byte (:data:`FAULTS`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional, Tuple

from . import _build

__all__ = ["STATUS_OUTSIDE_REGION", "STATUS_CHIP_ERROR", "STATUS_FULL_SCALE", "STATUS_RECOVERED", "FAULTS",
           "FAULT_STAGES", "StatusBits", "Sample", "DeviceInfo", "EepromReply", "temperature_C", "fault_name",
           "reading_fault", "full_scale_name", "flag_letters"]

STATUS_OUTSIDE_REGION = 0x01  # the reading is outside the calibrated region: the force is extrapolated
STATUS_CHIP_ERROR = 0x02  # NACK, ERROR bit, wrong byte count or timeout; the forces are NaN
STATUS_FULL_SCALE = 0x04  # a field axis is at the chip's full scale
STATUS_RECOVERED = 0x08  # the chip was reset since the last frame

#: The low byte of a fault word: the firmware's error (mf_errors.h, MF_E_* negated).
FAULTS = {1: "nack", 2: "bus error", 3: "bus timeout", 4: "chip ERROR bit", 5: "byte count", 6: "chip reset",
          7: "chip mode", 8: "register verify", 9: "transfer too long", 10: "no valid calibration"}
#: The high byte of a fault word: where it struck (mf_sample.h, MF_STAGE_*).
FAULT_STAGES = {1: "read", 2: "start", 3: "eeprom"}
_FLAG_LETTERS = ((STATUS_OUTSIDE_REGION, "o"), (STATUS_CHIP_ERROR, "E"), (STATUS_FULL_SCALE, "S"),
                 (STATUS_RECOVERED, "R"))


def temperature_C(raw: int) -> float:
    """Chip temperature in degC from the raw 16-bit reading."""
    return 25.0 + (raw - _build.TEMPERATURE_RAW_25C) / _build.TEMPERATURE_LSB_PER_C


def fault_name(word: Optional[int]) -> Optional[str]:
    """A fault word as words, e.g. ``'nack at read'`` (unknown codes by number); None for None or 0."""
    if not word:
        return None
    error, stage = word & 0xFF, word >> 8
    return "{} at {}".format(FAULTS.get(error, f"error {error}"),
                             FAULT_STAGES.get(stage, f"stage {stage}"))


def reading_fault(status: int, fault: Optional[int], counts: Optional[Tuple[int, int, int]]) -> Optional[str]:
    """The fault a reading carries, as words: for an axis at the chip's full scale (without a chip error) which
    axes (:func:`full_scale_name`), else the firmware's fault word (:func:`fault_name`)."""
    if status & STATUS_FULL_SCALE and not status & STATUS_CHIP_ERROR:
        return full_scale_name(counts)
    return fault_name(fault)


def full_scale_name(counts: Optional[Tuple[int, int, int]]) -> str:
    """A full-scale sample's fault, naming the axes at the chip's full scale where the raw counts are known (binary
    frames): e.g. ``'full scale on Bx+Bz'``; ``'full scale'`` from a text line."""
    if counts is None:
        return "full scale"
    axes = [name for name, c in zip(("Bx", "By", "Bz"), counts) if abs(c) >= _build.FULL_SCALE_COUNTS]
    return "full scale on " + "+".join(axes) if axes else "full scale"


def flag_letters(status: int) -> str:
    """Status flags as four letters, '-' where clear: o outside region, E chip error, S full scale, R recovered."""
    return "".join(letter if status & bit else "-" for bit, letter in _FLAG_LETTERS)


class StatusBits:
    """The status byte's bits as properties, for a reading that carries ``status`` (a :class:`Sample`, an array's
    ``TaxelReading``)."""

    status: int

    @property
    def outside_region(self) -> bool:
        """Status bit 0: the reading is outside the calibrated (Bz, Br) region."""
        return bool(self.status & STATUS_OUTSIDE_REGION)

    @property
    def chip_error(self) -> bool:
        """Status bit 1: the chip failed to give this sample; the forces are NaN."""
        return bool(self.status & STATUS_CHIP_ERROR)

    @property
    def full_scale(self) -> bool:
        """Status bit 2: a field axis is at the chip's full scale."""
        return bool(self.status & STATUS_FULL_SCALE)

    @property
    def recovered(self) -> bool:
        """Status bit 3: the chip was reset since the last frame."""
        return bool(self.status & STATUS_RECOVERED)


@dataclass(frozen=True)
class Sample(StatusBits):
    """One sample from the device.

    ``B_uT`` is (Bx, By, Bz) in microtesla; ``force_N`` is (Fx, Fy, Fz) in newton as the firmware computed it,
    minus the host's zero offset when one is set (``device_force_N`` keeps the firmware's value); both are NaN
    when the chip-error bit is set (the sample is kept for its sequence number, time and flags) and when an axis is
    at the chip's full scale (a clipped field is no force; ``B_uT`` and ``counts`` keep the reading, and
    :attr:`fault_name` names the axes);
    ``counts`` and ``temperature_raw`` are the raw chip readings (binary frames only); ``time_s`` is the
    device time since the first sample of a :class:`~magfab_readout.Device` stream (None from the decoder);
    ``fault`` is the fault word of a chip-error sample (:func:`fault_name`, :attr:`fault_name`), else None;
    ``taxel`` the index of the chip an array's reading came from (0 for a single taxel's force frames, whose
    ``force_N`` is NaN: the host computes an array's forces).
    """

    seq: int
    t_us: int
    status: int
    B_uT: Tuple[float, float, float]
    force_N: Tuple[float, float, float]
    temperature_C: Optional[float]
    source: str  # "binary" or "text"
    counts: Optional[Tuple[int, int, int]] = None
    temperature_raw: Optional[int] = None
    time_s: Optional[float] = None
    device_force_N: Optional[Tuple[float, float, float]] = field(default=None, compare=False)
    fault: Optional[int] = None
    taxel: int = 0

    def __post_init__(self) -> None:
        if self.device_force_N is None:
            object.__setattr__(self, "device_force_N", self.force_N)

    @property
    def fault_name(self) -> Optional[str]:
        """What failed and where, e.g. ``'chip reset at read'``, or for a sample at the chip's full scale which axes
        (``'full scale on Bz'``); None for a good sample."""
        return reading_fault(self.status, self.fault, self.counts)

    @property
    def flags(self) -> str:
        """The status as letters (see :func:`flag_letters`)."""
        return flag_letters(self.status)


@dataclass(frozen=True)
class DeviceInfo:
    """The firmware's answer to 'i': which spec and calibration it was built with, and the chip settings."""

    spec_name: str
    calibration_hash: str  # first 16 hex digits of the calibration's sha256
    gain_sel: int
    resolution: int
    osr: int
    dig_filt: int
    line: str
    taxels: int = 1  # an array's image: the number of chips it reads

    @property
    def settings(self) -> Tuple[int, int, int, int]:
        """(gain_sel, resolution, osr, dig_filt)."""
        return self.gain_sel, self.resolution, self.osr, self.dig_filt


@dataclass(frozen=True)
class EepromReply:
    """The firmware's answer to an EEPROM command (docs/bundle.md section 4): ``kind`` 'W' (a write: ``status``
    0 written, 1 bad CRC, 2 outside the EEPROM; ``record`` 0 when the calibration record is now valid, 10 when
    not) or 'R' (a read: ``data``)."""

    kind: str
    address: int
    length: int = 0
    status: int = 0
    record: int = 0
    data: bytes = b""
