"""The firmware's serial formats: binary force frames with a CRC, text lines, and the info line.

Binary frame (little-endian, 31 bytes)::

    0  2  sync 0xA5 0x5A          9  6  Bx, By, Bz raw counts (int16, RES offsets removed)
    2  1  frame type 0x01         15 2  temperature raw (uint16)
    3  1  sequence (wraps)        17 12 Fx, Fy, Fz newton (float32)
    4  1  status flags            29 2  CRC-16/CCITT-FALSE over bytes 2..28
    5  4  time, us (uint32)

Text line: ``F,<seq>,<t_us>,<status>,<Fx_N>,<Fy_N>,<Fz_N>,<Bx_uT>,<By_uT>,<Bz_uT>,<T_C>``; info line:
``I,magfab,<spec name>,<calibration sha256 first 16 hex>,<gain_sel>,<resolution>,<osr>,<dig_filt>``.

:class:`Decoder` takes bytes as they arrive, in either mode or both mixed (the info line comes in the middle
of a binary stream), resynchronises on the sync bytes after noise or a lost byte, refuses frames whose CRC
fails and counts every kind of trouble in :class:`DecoderStats`.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from typing import List, Optional, Tuple, Union

from . import _build

__all__ = [
    "SYNC", "FRAME_LENGTH", "FRAME_FORCE", "STATUS_OUTSIDE_REGION", "STATUS_CHIP_ERROR", "STATUS_FULL_SCALE",
    "STATUS_RECOVERED", "Sample", "DeviceInfo", "DecoderStats", "Decoder", "crc16_ccitt_false",
    "encode_frame", "encode_text_line", "encode_info_line", "decode_frames", "temperature_C",
]

SYNC = b"\xa5\x5a"
FRAME_LENGTH = 31
FRAME_FORCE = 0x01
STATUS_OUTSIDE_REGION = 0x01  # the reading is outside the calibrated region: the force is extrapolated
STATUS_CHIP_ERROR = 0x02  # NACK, ERROR bit, wrong byte count or timeout; the forces are NaN
STATUS_FULL_SCALE = 0x04  # a field axis is at the chip's full scale
STATUS_RECOVERED = 0x08  # the chip was reset since the last frame
MAX_LINE = 200  # longest text or info line accepted, bytes

_BODY = struct.Struct("<BBBI3hH3f")  # bytes 2..28: type, seq, status, time, counts, temperature, forces
_CRC = struct.Struct("<H")
_FLAG_LETTERS = ((STATUS_OUTSIDE_REGION, "o"), (STATUS_CHIP_ERROR, "E"), (STATUS_FULL_SCALE, "S"),
                 (STATUS_RECOVERED, "R"))


def _crc_table() -> List[int]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) if crc & 0x8000 else (crc << 1)
        table.append(crc & 0xFFFF)
    return table


_TABLE = _crc_table()


def crc16_ccitt_false(data: bytes) -> int:
    """CRC-16/CCITT-FALSE: polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR."""
    crc = 0xFFFF
    for byte in data:
        crc = ((crc << 8) & 0xFFFF) ^ _TABLE[((crc >> 8) ^ byte) & 0xFF]
    return crc


def temperature_C(raw: int) -> float:
    """Chip temperature in degC from the raw 16-bit reading."""
    return 25.0 + (raw - _build.TEMPERATURE_RAW_25C) / _build.TEMPERATURE_LSB_PER_C


def flag_letters(status: int) -> str:
    """Status flags as four letters, '-' where clear: o outside region, E chip error, S full scale, R recovered."""
    return "".join(letter if status & bit else "-" for bit, letter in _FLAG_LETTERS)


@dataclass(frozen=True)
class Sample:
    """One sample from the device.

    ``B_uT`` is (Bx, By, Bz) in microtesla; ``force_N`` is (Fx, Fy, Fz) in newton as the firmware computed it,
    minus the host's zero offset when one is set (``device_force_N`` keeps the firmware's value);
    ``counts`` and ``temperature_raw`` are the raw chip readings (binary frames only); ``time_s`` is the
    device time since the first sample of a :class:`~magfab_readout.Device` stream (None from the decoder).
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

    def __post_init__(self) -> None:
        if self.device_force_N is None:
            object.__setattr__(self, "device_force_N", self.force_N)

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

    @property
    def settings(self) -> Tuple[int, int, int, int]:
        """(gain_sel, resolution, osr, dig_filt)."""
        return self.gain_sel, self.resolution, self.osr, self.dig_filt


@dataclass
class DecoderStats:
    """What the decoder saw: good frames and lines, and every kind of trouble."""

    frames: int = 0  # binary frames with a good CRC
    lines: int = 0  # text sample lines
    infos: int = 0  # info lines
    crc_errors: int = 0  # sync found but the CRC failed
    unknown_frames: int = 0  # good CRC, frame type this reader does not know
    bad_lines: int = 0  # printable lines starting 'F,' or 'I,' that do not parse
    skipped_bytes: int = 0  # bytes that were not part of any frame or line
    lost: int = 0  # samples missing according to the sequence numbers
    bytes: int = 0  # everything fed in

    @property
    def samples(self) -> int:
        """Samples decoded, binary and text."""
        return self.frames + self.lines

    @property
    def crc_error_rate(self) -> float:
        """Fraction of binary frame candidates whose CRC failed."""
        attempts = self.frames + self.crc_errors
        return self.crc_errors / attempts if attempts else 0.0


def encode_frame(seq: int, t_us: int, status: int, counts: Tuple[int, int, int], temperature_raw: int,
                 force_N: Tuple[float, float, float]) -> bytes:
    """One binary force frame, exactly as the firmware sends it."""
    body = _BODY.pack(FRAME_FORCE, seq & 0xFF, status & 0xFF, t_us & 0xFFFFFFFF,
                      int(counts[0]), int(counts[1]), int(counts[2]), int(temperature_raw) & 0xFFFF,
                      float(force_N[0]), float(force_N[1]), float(force_N[2]))
    return SYNC + body + _CRC.pack(crc16_ccitt_false(body))


def _number(x: float, decimals: int) -> str:
    if math.isnan(x):
        return "nan"
    return "{:.{}f}".format(x, decimals)  # as the firmware: a small negative number prints as -0.0000


def encode_text_line(seq: int, t_us: int, status: int, force_N: Tuple[float, float, float],
                     B_uT: Tuple[float, float, float], temperature: Optional[float]) -> bytes:
    """One text sample line: forces to 4 decimals, field and temperature to 2 ('nan' where there is none)."""
    fields = ["F", str(seq & 0xFF), str(t_us & 0xFFFFFFFF), str(status & 0xFF)]
    fields += [_number(f, 4) for f in force_N]
    fields += [_number(b, 2) for b in B_uT]
    fields.append(_number(float("nan") if temperature is None else temperature, 2))
    return (",".join(fields) + "\n").encode("ascii")


def encode_info_line(spec_name: str, calibration_hash: str, gain_sel: int, resolution: int, osr: int,
                     dig_filt: int) -> bytes:
    """The firmware's info line (answer to 'i')."""
    text = "I,magfab,{},{},{},{},{},{}\n".format(spec_name, calibration_hash[:16], gain_sel, resolution, osr, dig_filt)
    return text.encode("utf-8")


def _printable(chunk: bytes) -> bool:
    return all(32 <= b < 127 or b == 13 for b in chunk)


class Decoder:
    """Incremental decoder of the firmware's byte stream (binary frames, text lines and info lines, mixed).

    ``feed(data)`` returns the :class:`Sample` and :class:`DeviceInfo` objects completed by ``data``; bytes of
    an unfinished frame or line are kept for the next call. Counts in binary frames become microtesla with
    ``lsb_xy_uT`` / ``lsb_z_uT`` (the firmware's chip settings by default).
    """

    def __init__(self, lsb_xy_uT: float = _build.LSB_XY_UT, lsb_z_uT: float = _build.LSB_Z_UT,
                 temperature: bool = _build.TEMPERATURE_ENABLED) -> None:
        self.lsb_xy_uT = float(lsb_xy_uT)
        self.lsb_z_uT = float(lsb_z_uT)
        self.temperature = bool(temperature)
        self.stats = DecoderStats()
        self._buffer = b""
        self._last_seq: Optional[int] = None

    def feed(self, data: bytes) -> List[Union[Sample, DeviceInfo]]:
        """Decode what ``data`` completes; see the class docstring."""
        stats = self.stats
        stats.bytes += len(data)
        buf = self._buffer + bytes(data)
        out: List[Union[Sample, DeviceInfo]] = []
        i = 0
        while True:
            j = self._next_candidate(buf, i)
            if j < 0:
                keep = 1 if buf[-1:] in (b"\xa5", b"F", b"I") and len(buf) > i else 0
                stats.skipped_bytes += len(buf) - i - keep
                i = len(buf) - keep
                break
            stats.skipped_bytes += j - i
            i = j
            if buf.startswith(SYNC, i):
                if len(buf) - i < FRAME_LENGTH:
                    break
                step = self._frame(buf[i:i + FRAME_LENGTH], out)
            else:
                step = self._line(buf, i, out)
                if step == 0:
                    break
            i += step
        self._buffer = buf[i:]
        return out

    @staticmethod
    def _next_candidate(buf: bytes, start: int) -> int:
        found = [k for k in (buf.find(SYNC, start), buf.find(b"F,", start), buf.find(b"I,", start)) if k >= 0]
        return min(found) if found else -1

    def _frame(self, frame: bytes, out: list) -> int:
        """Bytes consumed by the frame at the start of ``frame`` (31 bytes long)."""
        (crc,) = _CRC.unpack_from(frame, 29)
        if crc16_ccitt_false(frame[2:29]) != crc:
            self.stats.crc_errors += 1
            self.stats.skipped_bytes += 1
            return 1  # resynchronise: the next sync may start inside this candidate
        kind, seq, status, t_us, bx, by, bz, t_raw, fx, fy, fz = _BODY.unpack_from(frame, 2)
        if kind != FRAME_FORCE:
            self.stats.unknown_frames += 1
            return FRAME_LENGTH
        self.stats.frames += 1
        self._sequence(seq)
        B = (bx * self.lsb_xy_uT, by * self.lsb_xy_uT, bz * self.lsb_z_uT)
        temp = temperature_C(t_raw) if self.temperature and not status & STATUS_CHIP_ERROR else None
        out.append(Sample(seq, t_us, status, B, (fx, fy, fz), temp, "binary", (bx, by, bz), t_raw))
        return FRAME_LENGTH

    def _line(self, buf: bytes, i: int, out: list) -> int:
        """Bytes consumed by the line candidate at ``i``; 0 when it is not complete yet."""
        end = buf.find(b"\n", i, i + MAX_LINE)
        if end < 0:
            tail = buf[i:i + MAX_LINE]
            if len(tail) < MAX_LINE and _printable(tail):
                return 0  # wait for the rest of the line
            self.stats.skipped_bytes += 1
            return 1
        raw = buf[i:end]
        if not _printable(raw):
            self.stats.skipped_bytes += 1  # an 'F,' or 'I,' inside binary data
            return 1
        item = self._parse_line(raw.decode("ascii").rstrip("\r"))
        if item is None:
            self.stats.bad_lines += 1
        else:
            out.append(item)
        return end - i + 1

    def _parse_line(self, text: str) -> Union[Sample, DeviceInfo, None]:
        try:
            if text.startswith("I,magfab,"):
                name, calibration_hash, gain, res, osr, dig = text[len("I,magfab,"):].rsplit(",", 5)
                int(calibration_hash, 16)
                info = DeviceInfo(name, calibration_hash.lower(), int(gain), int(res), int(osr), int(dig), text)
                self.stats.infos += 1
                return info
            parts = text.split(",")
            if parts[0] != "F" or len(parts) != 11:
                return None
            seq, t_us, status = int(parts[1]), int(parts[2]), int(parts[3])
            if not (0 <= seq < 256 and 0 <= t_us < 2**32 and 0 <= status < 256):
                return None
            values = [float(p) for p in parts[4:]]
        except ValueError:
            return None
        self.stats.lines += 1
        self._sequence(seq)
        temp = values[6] if not math.isnan(values[6]) else None
        return Sample(seq, t_us, status, (values[3], values[4], values[5]), (values[0], values[1], values[2]),
                      temp, "text")

    def _sequence(self, seq: int) -> None:
        if self._last_seq is not None:
            self.stats.lost += (seq - self._last_seq - 1) % 256
        self._last_seq = seq


def decode_frames(data: bytes, lsb_xy_uT: float = _build.LSB_XY_UT, lsb_z_uT: float = _build.LSB_Z_UT) -> list:
    """Decode a whole byte string at once: the samples and info lines in it, in order (see :class:`Decoder`)."""
    return Decoder(lsb_xy_uT, lsb_z_uT).feed(data)
