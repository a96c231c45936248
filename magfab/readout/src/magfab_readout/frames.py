"""The firmware's serial formats: binary force frames with a CRC, text lines, and the info line.

Binary frame (little-endian, 31 bytes)::

    0  2  sync 0xA5 0x5A          9  6  Bx, By, Bz raw counts (int16, RES offsets removed)
    2  1  frame type 0x01         15 2  temperature raw (uint16)
    3  1  sequence (wraps)        17 12 Fx, Fy, Fz newton (float32)
    4  1  status flags            29 2  CRC-16/CCITT-FALSE over bytes 2..28
    5  4  time, us (uint32)

On a chip-error frame (status bit 1) bytes 15..16 carry the fault word instead of the temperature: the stage
where the fault struck in the high byte, the error in the low byte (:data:`FAULTS`, :func:`fault_name`).

Text line: ``F,<seq>,<t_us>,<status>,<Fx_N>,<Fy_N>,<Fz_N>,<Bx_uT>,<By_uT>,<Bz_uT>,<T_C>*XXXX``, a chip-error line
with ``,<fault>`` (the fault word in decimal) before the ``*``; info line:
``I,magfab,<spec name>,<calibration sha256 first 16 hex>,<gain_sel>,<resolution>,<osr>,<dig_filt>*XXXX``.
``XXXX`` is the CRC-16/CCITT-FALSE of the bytes before the ``*`` in four upper-case hex digits (as NMEA's
``*hh``): a person still reads the line, a script checks it.

An earlier array image sent a field frame (type 0x02, 20 bytes) per chip per cycle instead of force frames: the
taxel's field, no force (the host computes each taxel's force from every taxel's field, docs/bundle.md section
5)::

    0  2  sync 0xA5 0x5A          10 6  Bx, By, Bz raw counts (int16, RES offsets removed)
    2  1  frame type 0x02         16 2  temperature raw (uint16), the fault word on a chip-error frame
    3  1  sequence (per cycle)    18 2  CRC-16/CCITT-FALSE over bytes 2..17
    4  1  status flags (this chip's)
    5  4  time, us (uint32): when this chip was read
    9  1  taxel index

Every frame of one cycle carries the same sequence number. The array image of this package sends one cycle frame
(type 0x03) a cycle instead, every chip's reading behind one head and one CRC (11 bytes a chip against 20)::

    0  2  sync 0xA5 0x5A          8  1  chips n (1..16)
    2  1  frame type 0x03         9  11 per chip, in taxel order: status flags (1), its read time after the head's
    3  1  sequence (per cycle)          (uint16 us), Bx, By, Bz raw counts (int16), temperature raw (uint16), the
    4  4  time, us (uint32): when         fault word on a chip-error reading
          the cycle's first chip   9+11n 2 CRC-16/CCITT-FALSE over bytes 2 .. 8+11n
          was read

It decodes to the same samples as n field frames. Text line
``B,<taxel>,<seq>,<t_us>,<status>,<Bx_uT>,<By_uT>,<Bz_uT>,<T_C>*XXXX`` (``,<fault>`` before the ``*`` on a chip
error); an array's info line ends with ``,<taxels>``.

:class:`Decoder` takes bytes as they arrive, in either mode or both mixed (the info line comes in the middle
of a binary stream), resynchronises on the sync bytes after noise or a lost byte, refuses frames whose CRC
fails and lines whose checksum is missing or wrong, and counts every kind of trouble in :class:`DecoderStats`.
It never yields a force the firmware did not mean: a sample with the chip-error bit comes with NaN forces
and field whatever its frame carries, and a sample whose forces are not finite or lie beyond
:data:`FORCE_LIMIT_N` (or, in a text line, whose field is beyond :data:`FIELD_LIMIT_UT`) is refused.
"""

from __future__ import annotations

import binascii
import math
import re
import struct
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Tuple, Union

from . import _build
from .readings import (
    FAULT_STAGES,
    FAULTS,
    STATUS_CHIP_ERROR,
    STATUS_FULL_SCALE,
    STATUS_OUTSIDE_REGION,
    STATUS_RECOVERED,
    DeviceInfo,
    EepromReply,
    Sample,
    fault_name,
    full_scale_name,
    reading_fault,
    temperature_C,
)

__all__ = [
    "SYNC", "FRAME_LENGTH", "FRAME_FORCE", "STATUS_OUTSIDE_REGION", "STATUS_CHIP_ERROR", "STATUS_FULL_SCALE",
    "STATUS_RECOVERED", "FORCE_LIMIT_N", "FIELD_LIMIT_UT", "Sample", "DeviceInfo", "DecoderStats", "Decoder",
    "crc16_ccitt_false", "line_checksum", "encode_frame", "encode_text_line", "encode_info_line", "decode_frames",
    "temperature_C", "FAULTS", "FAULT_STAGES", "fault_name", "full_scale_name", "reading_fault", "FRAME_FIELD",
    "FIELD_FRAME_LENGTH", "encode_field_frame", "FRAME_CYCLE", "CYCLE_HEAD_LENGTH", "CYCLE_CHIP_LENGTH",
    "MAX_CYCLE_CHIPS", "encode_cycle_frame", "cycle_frame_length",
    "encode_field_line", "frame_length",
]

SYNC = b"\xa5\x5a"
FRAME_LENGTH = 31
FRAME_FORCE = 0x01
FRAME_FIELD = 0x02  # an array's: one chip's field, the taxel index, no force
FIELD_FRAME_LENGTH = 20
FRAME_CYCLE = 0x03  # an array's: every chip's field of one cycle, one head and one CRC
CYCLE_HEAD_LENGTH = 9
CYCLE_CHIP_LENGTH = 11
MAX_CYCLE_CHIPS = 16  # the firmware's MF_MAX_TAXELS: a head claiming more is noise
MAX_LINE = 200  # longest text or info line accepted, bytes
#: Largest |force| a sample may carry, N: 1 kN (100 kgf) is far past what a tactile tip's elastomer survives,
#: so a larger value is a fault, never a reading (the scan CSV's band, magfab/formats/scan_csv.py).
FORCE_LIMIT_N = 1000.0
#: Largest |field| a text line may carry, uT: 1 T is past any magnetometer chip's full scale.
FIELD_LIMIT_UT = 1.0e6

_INT = re.compile(r"[0-9]{1,10}")
_LINE_STARTS = (b"F,", b"I,", b"W,", b"R,", b"B,")
#: What the firmware prints for a float (mf_format_float): [-]digits.digits, d.dddde+XX beyond 1e9, nan, inf.
_FLOAT = re.compile(r"-?[0-9]{1,10}(?:\.[0-9]{1,6})?(?:e\+[0-9]{2})?|nan|-?inf")
_CHECKED = re.compile(rb"(.*)\*([0-9A-F]{4})")
#: Where a frame or a line may start: the sync bytes or a line's first two characters (the leftmost match).
_START = re.compile(re.escape(SYNC) + rb"|[" + b"".join(p[:1] for p in _LINE_STARTS) + rb"],")
_UNPRINTABLE = re.compile(rb"[^\x20-\x7e\r]")
#: Tests set it to count the bytes each search for a start examines (the decoder's work, without a clock).
_scan_hook: Optional[Callable[[int], None]] = None

_BODY = struct.Struct("<BBBI3hH3f")  # bytes 2..28: type, seq, status, time, counts, temperature, forces
_FIELD_BODY = struct.Struct("<BBBIB3hH")  # bytes 2..17: type, seq, status, time, taxel, counts, temperature
_CYCLE_HEAD = struct.Struct("<BBIB")  # bytes 2..8: type, seq, time, chips
_CYCLE_CHIP = struct.Struct("<BH3hH")  # per chip: status, time after the head's, counts, temperature
_CRC = struct.Struct("<H")


def crc16_ccitt_false(data: bytes) -> int:
    """CRC-16/CCITT-FALSE: polynomial 0x1021, initial value 0xFFFF, no reflection, no final XOR (the standard
    library's CRC-CCITT, ``binascii.crc_hqx``, started at 0xFFFF)."""
    return binascii.crc_hqx(bytes(data), 0xFFFF)


def line_checksum(body: bytes) -> bytes:
    """``*XXXX``: the CRC-16/CCITT-FALSE of a text or info line's ``body`` (everything before the ``*``)."""
    return b"*%04X" % crc16_ccitt_false(body)


def _checked_body(raw: bytes) -> Optional[bytes]:
    """The body of a line ``body*XXXX`` whose checksum is right, else None."""
    m = _CHECKED.fullmatch(raw)
    if m is None or line_checksum(m.group(1)) != b"*" + m.group(2):
        return None
    return m.group(1)


@dataclass
class DecoderStats:
    """What the decoder saw: good frames and lines, and every kind of trouble."""

    frames: int = 0  # binary frames with a good CRC and plausible values (or the chip-error bit)
    lines: int = 0  # text sample lines with a good checksum and plausible values (or the chip-error bit)
    infos: int = 0  # info lines
    replies: int = 0  # answers to EEPROM commands (W and R lines)
    crc_errors: int = 0  # sync found but the CRC failed
    unknown_frames: int = 0  # good CRC, frame type this reader does not know
    bad_lines: int = 0  # printable lines starting 'F,' or 'I,' without a right checksum, or that do not parse
    refused: int = 0  # good CRC or checksum, no chip-error bit, but a force not finite or beyond FORCE_LIMIT_N
    skipped_bytes: int = 0  # bytes that were not part of any frame or line
    lost: int = 0  # samples missing according to the sequence numbers
    bytes: int = 0  # everything fed in

    @property
    def samples(self) -> int:
        """Samples decoded, binary and text."""
        return self.frames + self.lines

    @property
    def crc_error_rate(self) -> float:
        """Fraction of binary frame candidates whose CRC failed and text lines whose checksum failed."""
        attempts = self.frames + self.lines + self.crc_errors + self.bad_lines
        return (self.crc_errors + self.bad_lines) / attempts if attempts else 0.0


def encode_frame(seq: int, t_us: int, status: int, counts: Tuple[int, int, int], temperature_raw: int,
                 force_N: Tuple[float, float, float]) -> bytes:
    """One binary force frame, exactly as the firmware sends it (a chip-error frame: ``temperature_raw`` is
    the fault word)."""
    body = _BODY.pack(FRAME_FORCE, seq & 0xFF, status & 0xFF, t_us & 0xFFFFFFFF,
                      int(counts[0]), int(counts[1]), int(counts[2]), int(temperature_raw) & 0xFFFF,
                      float(force_N[0]), float(force_N[1]), float(force_N[2]))
    return SYNC + body + _CRC.pack(crc16_ccitt_false(body))


def encode_field_frame(taxel: int, seq: int, t_us: int, status: int, counts: Tuple[int, int, int],
                       temperature_raw: int) -> bytes:
    """One binary field frame of an array's image (a chip-error frame: ``temperature_raw`` is the fault word)."""
    body = _FIELD_BODY.pack(FRAME_FIELD, seq & 0xFF, status & 0xFF, t_us & 0xFFFFFFFF, taxel & 0xFF,
                            int(counts[0]), int(counts[1]), int(counts[2]), int(temperature_raw) & 0xFFFF)
    return SYNC + body + _CRC.pack(crc16_ccitt_false(body))


def encode_cycle_frame(seq: int, t_us: int, chips: List[Tuple[int, int, Tuple[int, int, int], int]]) -> bytes:
    """One cycle frame of an array's image: ``chips`` in taxel order, each (status, its read time after ``t_us``,
    counts, temperature word; on a chip error the fault word), exactly as the firmware sends it."""
    body = _CYCLE_HEAD.pack(FRAME_CYCLE, seq & 0xFF, t_us & 0xFFFFFFFF, len(chips)) + b"".join(
        _CYCLE_CHIP.pack(status & 0xFF, min(max(int(dt), 0), 0xFFFF), int(c[0]), int(c[1]), int(c[2]),
                         int(t_raw) & 0xFFFF) for status, dt, c, t_raw in chips)
    return SYNC + body + _CRC.pack(crc16_ccitt_false(body))


def cycle_frame_length(chips: int) -> int:
    """Bytes of a cycle frame of ``chips`` chips."""
    return CYCLE_HEAD_LENGTH + CYCLE_CHIP_LENGTH * chips + 2


def frame_length(kind: int, chips: int = 1) -> int:
    """Bytes of a binary frame of type ``kind`` (a cycle frame's: of ``chips`` chips, its byte 8; an unknown type is
    checked as a force frame's length)."""
    if kind == FRAME_CYCLE:
        return cycle_frame_length(chips)
    return FIELD_FRAME_LENGTH if kind == FRAME_FIELD else FRAME_LENGTH


def _candidate_length(buf: bytes, i: int) -> Optional[int]:
    """The length of the frame whose sync is at ``buf[i]``: None while its type (or a cycle frame's head) has not
    arrived, 0 for a cycle frame's head claiming no chips or more than :data:`MAX_CYCLE_CHIPS` (noise)."""
    cycle = buf[i + 2:i + 3] == bytes([FRAME_CYCLE])
    if len(buf) - i < (CYCLE_HEAD_LENGTH if cycle else 3):
        return None
    if not cycle:
        return frame_length(buf[i + 2])
    return frame_length(FRAME_CYCLE, buf[i + 8]) if 1 <= buf[i + 8] <= MAX_CYCLE_CHIPS else 0


def _number(x: float, decimals: int) -> str:
    if math.isnan(x):
        return "nan"
    return "{:.{}f}".format(x, decimals)  # as the firmware: a small negative number prints as -0.0000


def _sealed_line(fields: List[str], status: int, B_uT: Tuple[float, float, float], temperature: Optional[float],
                 fault: int) -> bytes:
    """``fields`` then the field and temperature to 2 decimals ('nan' where there is none), the fault word on a
    chip-error line, and the checksum (:func:`line_checksum`)."""
    fields = fields + [_number(b, 2) for b in B_uT]
    fields.append(_number(float("nan") if temperature is None else temperature, 2))
    if status & STATUS_CHIP_ERROR:
        fields.append(str(fault & 0xFFFF))
    body = ",".join(fields).encode("ascii")
    return body + line_checksum(body) + b"\n"


def encode_text_line(seq: int, t_us: int, status: int, force_N: Tuple[float, float, float],
                     B_uT: Tuple[float, float, float], temperature: Optional[float], fault: int = 0) -> bytes:
    """One text sample line: forces to 4 decimals, field and temperature to 2 ('nan' where there is none), the
    fault word on a chip-error line, then the checksum (:func:`line_checksum`)."""
    fields = ["F", str(seq & 0xFF), str(t_us & 0xFFFFFFFF), str(status & 0xFF)] + [_number(f, 4) for f in force_N]
    return _sealed_line(fields, status, B_uT, temperature, fault)


def encode_field_line(taxel: int, seq: int, t_us: int, status: int, B_uT: Tuple[float, float, float],
                      temperature: Optional[float], fault: int = 0) -> bytes:
    """One text field line of an array's image (as :func:`encode_text_line`, the taxel first and no forces)."""
    fields = ["B", str(taxel & 0xFF), str(seq & 0xFF), str(t_us & 0xFFFFFFFF), str(status & 0xFF)]
    return _sealed_line(fields, status, B_uT, temperature, fault)


def encode_info_line(spec_name: str, calibration_hash: str, gain_sel: int, resolution: int, osr: int,
                     dig_filt: int, taxels: int = 1) -> bytes:
    """The firmware's info line (answer to 'i'), with its checksum; an array's ends with its number of taxels."""
    body = f"I,magfab,{spec_name},{calibration_hash[:16]},{gain_sel},{resolution},{osr},{dig_filt}"
    if taxels != 1:
        body += f",{taxels}"
    return body.encode("utf-8") + line_checksum(body.encode("utf-8")) + b"\n"


def _printable(chunk: bytes) -> bool:
    """Every byte printable ASCII (32..126) or a carriage return."""
    return _UNPRINTABLE.search(chunk) is None


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
        self._last_seq: Dict[int, int] = {}  # per taxel

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
                keep = 1 if buf[-1:] in (b"\xa5", b"F", b"I", b"W", b"R", b"B") and len(buf) > i else 0
                stats.skipped_bytes += len(buf) - i - keep
                i = len(buf) - keep
                break
            stats.skipped_bytes += j - i
            i = j
            if buf.startswith(SYNC, i):
                length = _candidate_length(buf, i)
                if length is None or len(buf) - i < length:
                    break
                if length == 0:
                    stats.skipped_bytes += 1  # no cycle of that many chips: noise, resynchronise
                    i += 1
                    continue
                step = self._frame(buf[i:i + length], out)
            else:
                step = self._line(buf, i, out)
                if step == 0:
                    break
            i += step
        self._buffer = buf[i:]
        return out

    @staticmethod
    def _next_candidate(buf: bytes, start: int) -> int:
        """The first start of a frame or line at or after ``start``, -1 if none. One search for the leftmost of
        all the starts, so it reads only up to the one it returns: the candidates of one buffer are searched in
        one pass whatever they turn out to be (a search per kind of start reads to the buffer's end for every
        kind that is absent, at every candidate, which is quadratic)."""
        m = _START.search(buf, start)
        if _scan_hook is not None:
            _scan_hook((m.end() if m else len(buf)) - start)
        return m.start() if m else -1

    def _frame(self, frame: bytes, out: list) -> int:
        """Bytes consumed by the frame ``frame`` (as long as :func:`frame_length` of its type)."""
        end = len(frame) - 2
        (crc,) = _CRC.unpack_from(frame, end)
        if crc16_ccitt_false(frame[2:end]) != crc:
            self.stats.crc_errors += 1
            self.stats.skipped_bytes += 1
            return 1  # resynchronise: the next sync may start inside this candidate
        if frame[2] == FRAME_FIELD:
            return self._field_frame(frame, out)
        if frame[2] == FRAME_CYCLE:
            return self._cycle_frame(frame, out)
        kind, seq, status, t_us, bx, by, bz, t_raw, fx, fy, fz = _BODY.unpack_from(frame, 2)
        if kind != FRAME_FORCE:
            self.stats.unknown_frames += 1
            return FRAME_LENGTH
        self._sequence(seq)
        if status & (STATUS_CHIP_ERROR | STATUS_FULL_SCALE) or _plausible((fx, fy, fz)):
            self.stats.frames += 1
        if status & STATUS_CHIP_ERROR:
            out.append(Sample(seq, t_us, status, _NAN3, _NAN3, None, "binary", (bx, by, bz), t_raw,
                              fault=t_raw or None))
        elif status & STATUS_FULL_SCALE or _plausible((fx, fy, fz)):
            B = (bx * self.lsb_xy_uT, by * self.lsb_xy_uT, bz * self.lsb_z_uT)
            temp = temperature_C(t_raw) if self.temperature else None
            force = _NAN3 if status & STATUS_FULL_SCALE else (fx, fy, fz)  # a clipped field gives no force
            out.append(Sample(seq, t_us, status, B, force, temp, "binary", (bx, by, bz), t_raw))
        else:
            self.stats.refused += 1
        return FRAME_LENGTH

    def _field_frame(self, frame: bytes, out: list) -> int:
        _kind, seq, status, t_us, taxel, bx, by, bz, t_raw = _FIELD_BODY.unpack_from(frame, 2)
        self._field_sample(out, taxel, seq, t_us, status, (bx, by, bz), t_raw)
        return FIELD_FRAME_LENGTH

    def _cycle_frame(self, frame: bytes, out: list) -> int:
        _kind, seq, t_us, chips = _CYCLE_HEAD.unpack_from(frame, 2)
        for k in range(chips):
            status, dt, bx, by, bz, t_raw = _CYCLE_CHIP.unpack_from(frame, CYCLE_HEAD_LENGTH + CYCLE_CHIP_LENGTH * k)
            self._field_sample(out, k, seq, (t_us + dt) & 0xFFFFFFFF, status, (bx, by, bz), t_raw)
        return len(frame)

    def _field_sample(self, out: list, taxel: int, seq: int, t_us: int, status: int,
                      counts: Tuple[int, int, int], t_raw: int) -> None:
        """One array chip's reading (a field frame's, or one of a cycle frame's) as a sample, counted as a frame."""
        self._sequence(seq, taxel)
        self.stats.frames += 1
        if status & STATUS_CHIP_ERROR:
            out.append(Sample(seq, t_us, status, _NAN3, _NAN3, None, "binary", counts, t_raw,
                              fault=t_raw or None, taxel=taxel))
        else:
            bx, by, bz = counts
            B = (bx * self.lsb_xy_uT, by * self.lsb_xy_uT, bz * self.lsb_z_uT)
            temp = temperature_C(t_raw) if self.temperature else None
            out.append(Sample(seq, t_us, status, B, _NAN3, temp, "binary", counts, t_raw, taxel=taxel))

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
        body = _checked_body(raw[:-1] if raw.endswith(b"\r") else raw)
        item = self._parse_line(body.decode("ascii")) if body is not None else None
        if item is None:
            self.stats.bad_lines += 1
        elif item is not _REFUSED:
            out.append(item)
        return end - i + 1

    def _parse_line(self, text: str) -> Union[Sample, DeviceInfo, object, None]:
        """The sample or info line a checked line body holds; None when it does not parse, ``_REFUSED`` for a
        sample whose values are refused (counted)."""
        if text.startswith("I,magfab,"):
            return self._info(text)
        if text[:2] in ("W,", "R,"):
            return self._reply(text)
        if text[:2] == "B,":
            return self._field_line(text)
        parts = text.split(",")
        fault = parts.pop() if len(parts) == 12 and _INT.fullmatch(parts[-1]) else None
        if parts[0] != "F" or len(parts) != 11 or not all(_INT.fullmatch(p) for p in parts[1:4]) \
                or not all(_FLOAT.fullmatch(p) for p in parts[4:]):
            return None
        seq, t_us, status = int(parts[1]), int(parts[2]), int(parts[3])
        if not (seq < 256 and t_us < 2**32 and status < 256):
            return None
        if fault is not None and (not status & STATUS_CHIP_ERROR or int(fault) > 0xFFFF):
            return None  # a fault word ends only a chip-error line (one without it: an unknown fault)
        values = [float(p) for p in parts[4:]]
        self._sequence(seq)
        if status & STATUS_CHIP_ERROR:
            self.stats.lines += 1
            return Sample(seq, t_us, status, _NAN3, _NAN3, None, "text", fault=int(fault) if fault else None)
        force, B, temp = (values[0], values[1], values[2]), (values[3], values[4], values[5]), values[6]
        full = bool(status & STATUS_FULL_SCALE)
        if not (full or _plausible(force)) or not all(abs(b) <= FIELD_LIMIT_UT for b in B):
            self.stats.refused += 1
            return _REFUSED
        self.stats.lines += 1
        if full:  # a clipped field gives no force, whatever the line carries
            force = _NAN3
        return Sample(seq, t_us, status, B, force, temp if not math.isnan(temp) else None, "text")

    def _info(self, text: str) -> Optional[DeviceInfo]:
        """An info line: a single taxel's six fields after the name, an array's seven (the last its taxels; the
        hash's 16 characters never pass for a number, so a name with commas stays unambiguous)."""
        body = text[len("I,magfab,"):]
        for count in (6, 5):
            parts = body.rsplit(",", count)
            if len(parts) != count + 1:
                continue
            name, calibration_hash, *settings = parts
            if re.fullmatch(r"[0-9A-Fa-f]{16}", calibration_hash) and all(_INT.fullmatch(x) for x in settings):
                self.stats.infos += 1
                values = [int(x) for x in settings]
                taxels = values.pop() if count == 6 else 1
                gain_sel, resolution, osr, dig_filt = values
                return DeviceInfo(name, calibration_hash.lower(), gain_sel, resolution, osr, dig_filt, text, taxels)
        return None

    def _field_line(self, text: str) -> Union[Sample, object, None]:
        """``B,<taxel>,<seq>,<t_us>,<status>,<Bx>,<By>,<Bz>,<T>[,<fault>]`` (checked body)."""
        parts = text.split(",")
        fault = parts.pop() if len(parts) == 10 and _INT.fullmatch(parts[-1]) else None
        if len(parts) != 9 or not all(_INT.fullmatch(p) for p in parts[1:5]) \
                or not all(_FLOAT.fullmatch(p) for p in parts[5:]):
            return None
        taxel, seq, t_us, status = (int(p) for p in parts[1:5])
        if not (taxel < 256 and seq < 256 and t_us < 2**32 and status < 256):
            return None
        if fault is not None and (not status & STATUS_CHIP_ERROR or int(fault) > 0xFFFF):
            return None
        self._sequence(seq, taxel)
        if status & STATUS_CHIP_ERROR:
            self.stats.lines += 1
            return Sample(seq, t_us, status, _NAN3, _NAN3, None, "text", fault=int(fault) if fault else None,
                          taxel=taxel)
        values = [float(p) for p in parts[5:]]
        B, temp = tuple(values[0:3]), values[3]
        if not all(abs(b) <= FIELD_LIMIT_UT for b in B):
            self.stats.refused += 1
            return _REFUSED
        self.stats.lines += 1
        return Sample(seq, t_us, status, B, _NAN3, temp if not math.isnan(temp) else None, "text",  # type: ignore[arg-type]
                      taxel=taxel)

    def _reply(self, text: str) -> Optional[EepromReply]:
        parts = text.split(",")
        if parts[0] == "W" and len(parts) == 5 and all(_INT.fullmatch(p) for p in parts[1:]):
            self.stats.replies += 1
            return EepromReply("W", *(int(p) for p in parts[1:]))  # type: ignore[arg-type]
        if (parts[0] == "R" and len(parts) == 3 and _INT.fullmatch(parts[1])
                and re.fullmatch(r"([0-9A-F]{2})*", parts[2])):
            self.stats.replies += 1
            data = bytes.fromhex(parts[2])
            return EepromReply("R", int(parts[1]), len(data), data=data)
        return None

    def _sequence(self, seq: int, taxel: int = 0) -> None:
        """Samples lost, counted per taxel (an array's frames of one cycle share a sequence number)."""
        last = self._last_seq.get(taxel)
        if last is not None:
            self.stats.lost += (seq - last - 1) % 256
        self._last_seq[taxel] = seq


_NAN3 = (math.nan, math.nan, math.nan)
_REFUSED = object()


def _plausible(force: Tuple[float, ...]) -> bool:
    """Every component finite and within :data:`FORCE_LIMIT_N` (NaN fails the comparison)."""
    return all(abs(f) <= FORCE_LIMIT_N for f in force)


def decode_frames(data: bytes, lsb_xy_uT: float = _build.LSB_XY_UT, lsb_z_uT: float = _build.LSB_Z_UT) -> list:
    """Decode a whole byte string at once: the samples and info lines in it, in order (see :class:`Decoder`)."""
    return Decoder(lsb_xy_uT, lsb_z_uT).feed(data)
