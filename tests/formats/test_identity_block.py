"""The board's sensor identity block (readout package's identity.py, docs/bundle.md section 4): what it packs reads
back, anything else in those 64 bytes reads as no identity and never raises, and no calibration record a spec
can build reaches it."""

from __future__ import annotations

import datetime
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab import derive, load_spec
from magfab.export import firmware
from magfab.readout.src.magfab_readout import eeprom, identity
from magfab.readout.src.magfab_readout.records import ID_PATTERN

IDS = st.from_regex(ID_PATTERN, fullmatch=True).filter(lambda s: s.isascii())
DATES = st.datetimes(min_value=datetime.datetime(1970, 1, 1), max_value=datetime.datetime(2106, 2, 7)).map(
    lambda d: d.replace(microsecond=0).isoformat() + "Z")
SHA16 = st.text("0123456789abcdef", min_size=16, max_size=16)
IDENTITIES = st.builds(identity.Identity, IDS, DATES, SHA16)


def test_the_block_is_the_eeproms_last_64_bytes_after_the_largest_record():
    assert identity.ADDRESS + identity.SIZE == eeprom.SIZE == 1024
    assert eeprom.RECORD_MAX == identity.ADDRESS == 960


@settings(max_examples=300, deadline=None)
@given(IDENTITIES)
def test_pack_then_unpack_gives_the_identity_back(ident):
    block = identity.pack(ident)
    assert len(block) == identity.SIZE
    assert identity.unpack(block) == ident
    assert identity.unpack(block + b"\xff" * 10) == ident  # more bytes read than the block: only its own count


@settings(max_examples=300, deadline=None)
@given(IDENTITIES, st.integers(0, identity.SIZE - 1), st.integers(1, 255))
def test_any_changed_byte_reads_as_no_identity(ident, at, flip):
    """CRC-16 sees every error within 16 bits: one changed byte anywhere is never read as an identity."""
    block = bytearray(identity.pack(ident))
    block[at] ^= flip
    assert identity.unpack(bytes(block)) is None


@settings(max_examples=500, deadline=None)
@given(st.binary(min_size=0, max_size=80))
def test_arbitrary_bytes_never_raise(data):
    found = identity.unpack(data)
    assert found is None or identity.pack(found) == data[:identity.SIZE]


@settings(max_examples=200, deadline=None)
@given(IDENTITIES, st.data())
def test_a_block_resealed_with_bad_fields_reads_as_no_identity(ident, data):
    """Fields no pack writes (an ID's length past 32 or padding after it, a non-hex hash, another version), with
    the CRC made right again: refused by the fields' own checks."""
    block = bytearray(identity.pack(ident))
    what = data.draw(st.sampled_from(["length 0", "length 33", "padding", "hash", "version", "magic"]))
    if what == "length 0":
        block[3] = 0
    elif what == "length 33":
        block[3] = 33
    elif what == "padding":
        if block[3] == 32:
            block[3] = 31  # the ID's last character becomes padding that is not zero
        else:
            block[4 + block[3]] = ord("x")
    elif what == "hash":
        block[40] = ord("G")
    elif what == "version":
        block[2] = 2
    else:
        block[0:2] = b"MF"  # a calibration record's magic
    body = bytes(block[:62])
    assert identity.unpack(body + struct.pack("<H", eeprom.crc16(body))) is None


def test_erased_eeprom_reads_as_no_identity():
    assert identity.unpack(b"\xff" * identity.SIZE) is None
    assert identity.unpack(b"\x00" * identity.SIZE) is None
    assert identity.unpack(b"") is None


@pytest.mark.parametrize("field, value", [("sensor_id", "-leading-dash"), ("sensor_id", "x" * 33),
                                          ("sensor_id", "caf\u00e9"), ("calibration_sha16", "ABCDEF0123456789"),
                                          ("calibration_sha16", "0123"), ("calibration_date", "yesterday"),
                                          ("calibration_date", "1969-12-31T23:59:59Z"),
                                          ("calibration_date", "2106-02-07T06:28:16Z")])
def test_pack_refuses_what_the_block_cannot_hold(field, value):
    fields = {"sensor_id": "finger-01", "calibration_date": "2026-11-28T20:15:00Z",
              "calibration_sha16": "0123456789abcdef", field: value}
    with pytest.raises(identity.IdentityError, match=f"identity.{field} = "):
        identity.pack(identity.Identity(**fields))


def test_a_date_with_a_zone_is_stored_as_utc():
    ident = identity.Identity("f", "2026-11-28T21:15:00+01:00", "0123456789abcdef")
    assert identity.unpack(identity.pack(ident)).calibration_date == "2026-11-28T20:15:00Z"


# ---- the calibration record stays clear of the block -------------------------------------------------------------


def _largest_layout(order: int, points: int) -> dict:
    """A layout (eeprom.layout's shape) of ``order`` with a hull of ``points`` vertices: what pack sizes by."""
    rows = [{"i": i, "fz": [0.5] * (order - i + 1), "fr": [0.25] * (order - i + 1)} for i in range(order, -1, -1)]
    hull = [(100.0 * k, float(k * k)) for k in range(points)]
    lay = dict.fromkeys(eeprom.FLOATS, 1.0)
    lay.update(order=order, rows=rows, hull=hull, fan=[(x - hull[0][0], y - hull[0][1]) for x, y in hull],
               edges=[(1.0, 0.0, 0.0)] * points, thermal=(25.0, 0.001, 0.001, -0.001))
    return lay


def _largest_settings() -> dict:
    """The default build's image settings with the longest spec name, the temperature converted and a reference
    chip: version 5, the longest record there is."""
    settings_ = dict(firmware.image_settings(derive(load_spec(None))))
    settings_.update(name="n" * 64, flags=settings_["flags"] | eeprom.FLAG_TEMPERATURE,
                     reference=0x0D if settings_["i2c_address"] != 0x0D else 0x0E, reference_shift=3)
    return settings_


def test_the_largest_record_a_spec_builds_fits_before_the_identity():
    """The spec allows calibration.order up to 8 and the fit keeps at most models.region.HULL_MAX_VERTICES (8) hull
    vertices; with the 64-byte name and version 5's blocks that record takes 770 bytes, under the 960 before the
    identity (it took the same under the old 1024 limit: no spec that builds today is refused)."""
    from magfab.models.region import HULL_MAX_VERTICES
    from magfab.spec import Calibration as SpecCalibration

    top = SpecCalibration.model_fields["order"].metadata
    assert any(getattr(m, "le", None) == eeprom.MAX_ORDER for m in top)
    record = eeprom.pack(_largest_layout(eeprom.MAX_ORDER, HULL_MAX_VERTICES), "0" * 16, _largest_settings())
    assert record[2] == eeprom.VERSION_REFERENCE and len(record) == 770 <= eeprom.RECORD_MAX
    addresses = [int(line[3:7], 16) + int(line[1:3], 16) for line in eeprom.intel_hex(record).decode().split()]
    assert max(addresses) <= identity.ADDRESS  # the .eep avrdude writes ends before the block


def test_a_record_reaching_the_identity_is_refused():
    """A calibration.json from elsewhere with a longer hull: 17 points fit at order 8 with every block, 18 not."""
    settings_ = _largest_settings()
    assert len(eeprom.pack(_largest_layout(8, 17), "0" * 16, settings_)) == 950
    with pytest.raises(eeprom.EepromError, match="the record takes 970 B, the EEPROM holds 960 B before the sensor "
                                                 "identity"):
        eeprom.pack(_largest_layout(8, 18), "0" * 16, settings_)
