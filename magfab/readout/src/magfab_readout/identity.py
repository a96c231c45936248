"""The board's sensor identity: a 64-byte block at the end of the ATmega328P's EEPROM (docs/bundle.md section 4)
naming the physical sensor the board carries, the date of the calibration ``upload --sensor ID`` wrote, and that
calibration's hash.

It lies outside the calibration record (which :func:`eeprom.pack` keeps below :data:`ADDRESS`), so the image never
reads it, the build's .eep (the record's bytes only) never overwrites it, and any image with the generic EEPROM
commands keeps it: no firmware change. Layout, little-endian::

    offset  bytes  field
         0      2  magic "MS"
         2      1  version 1
         3      1  the ID's length n (1..32)
         4     32  the sensor ID (ASCII, records.ID_PATTERN), zero-padded
        36      4  the calibration's date, seconds since 1970-01-01 UTC (uint32)
        40     16  the calibration's sha256, first 16 hex digits (lower case)
        56      6  zero
        62      2  CRC-16/CCITT-FALSE of bytes 0..61

Anything else there (an erased EEPROM's 0xFF, a bad CRC, another version) reads as no identity, never an error.
The format only, standard library, importable without a build (magfab reads it too); ``Device.read_identity`` and
``Device.write_identity`` move it over the serial port.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import re
import struct
from typing import Any, Optional

from . import eeprom
from .records import ID_PATTERN, RecordError, parse_date

__all__ = ["ADDRESS", "SIZE", "Identity", "IdentityError", "pack", "unpack"]

SIZE = 64
#: Where the block starts: the EEPROM's last :data:`SIZE` bytes (the calibration record ends before it).
ADDRESS = eeprom.SIZE - SIZE
assert ADDRESS == eeprom.RECORD_MAX
MAGIC = b"MS"
VERSION = 1
ID_MAX = 32
_BODY = struct.Struct("<2sBB32sI16s6x")  # 62 bytes, then the CRC
_SHA16 = re.compile(r"[0-9a-f]{16}")
_EPOCH = _dt.datetime(1970, 1, 1, tzinfo=_dt.timezone.utc)


class IdentityError(ValueError):
    """An identity the block cannot hold: which field, its value, and what is allowed."""

    def __init__(self, key: str, value: object, allowed: str) -> None:
        super().__init__(f"identity.{key} = {value!r}: {allowed}")


@dataclasses.dataclass(frozen=True)
class Identity:
    """Which sensor a board carries: its ``sensor_id``, the ``calibration_date`` (UTC ISO 8601 to the second, as
    the records write it) and ``calibration_sha16`` (the calibration's sha256, first 16 hex digits)."""

    sensor_id: str
    calibration_date: str
    calibration_sha16: str


def _seconds(date: str) -> int:
    try:
        iso = parse_date(date)
    except RecordError:
        raise IdentityError("calibration_date", date, "must be an ISO 8601 date") from None
    when = _dt.datetime.fromisoformat(iso[:-1] + "+00:00")
    seconds = int((when - _EPOCH).total_seconds())
    if not 0 <= seconds < 2 ** 32:
        raise IdentityError("calibration_date", date, "must be from 1970 to 2106 (uint32 seconds)")
    return seconds


def pack(identity: Identity) -> bytes:
    """The block's :data:`SIZE` bytes; :class:`IdentityError` for an ID, date or hash it cannot hold."""
    sid = identity.sensor_id
    if not isinstance(sid, str) or not re.fullmatch(ID_PATTERN, sid):
        raise IdentityError("sensor_id", sid, "must be 1 to 32 of A-Z a-z 0-9 . _ - starting with a letter or digit")
    sha16 = identity.calibration_sha16
    if not isinstance(sha16, str) or not _SHA16.fullmatch(sha16):
        raise IdentityError("calibration_sha16", sha16, "must be 16 lower-case hex digits")
    body = _BODY.pack(MAGIC, VERSION, len(sid), sid.encode("ascii"), _seconds(identity.calibration_date),
                      sha16.encode("ascii"))
    return body + struct.pack("<H", eeprom.crc16(body))


def unpack(data: Any) -> Optional[Identity]:
    """The identity in ``data`` (the block's bytes), or None when they hold none: erased, cut short, another
    magic or version, a bad CRC, or fields no :func:`pack` writes."""
    block = bytes(data)
    if len(block) < SIZE:
        return None
    block = block[:SIZE]
    if struct.unpack_from("<H", block, _BODY.size)[0] != eeprom.crc16(block[:_BODY.size]):
        return None
    magic, version, n, raw_id, seconds, raw_sha = _BODY.unpack_from(block)
    if magic != MAGIC or version != VERSION or not 1 <= n <= ID_MAX or any(raw_id[n:]):
        return None
    try:
        sid, sha16 = raw_id[:n].decode("ascii"), raw_sha.decode("ascii")
    except UnicodeDecodeError:
        return None
    if not re.fullmatch(ID_PATTERN, sid) or not _SHA16.fullmatch(sha16):
        return None
    when = (_EPOCH + _dt.timedelta(seconds=seconds)).replace(tzinfo=None).isoformat() + "Z"
    return Identity(sid, when, sha16)

