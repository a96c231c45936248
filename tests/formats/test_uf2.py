"""UF2 images and boot2's checksum (magfab.formats.uf2): the checksum against the CRC catalogue's check value and
against zlib's CRC-32 run on bit-reversed data; every written block against the format's layout read with struct and
the spec's own numbers; what is written reads back; every kind of malformed file, generated at random over its blocks,
is refused in one UF2Error line, never another exception."""

from __future__ import annotations

import struct
import zlib

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab.errors import InputError
from magfab.formats.uf2 import UF2Error, boot2_sealed, crc32_mpeg2, read, seal_boot2, write

PAGE = 256
ADDRESS = st.integers(0, 4096).map(lambda k: 0x10000000 + PAGE * k)
IMAGE = st.binary(min_size=1, max_size=3000)


def _reverse8(b: int) -> int:
    return int(f"{b:08b}"[::-1], 2)


def _reverse32(v: int) -> int:
    return int(f"{v:032b}"[::-1], 2)


def test_the_checksum_is_the_catalogues_crc32_mpeg2():
    """CRC-32/MPEG-2's check value (the CRC catalogue: "123456789" gives 0x0376E6E7)."""
    assert crc32_mpeg2(b"123456789") == 0x0376E6E7
    assert crc32_mpeg2(b"") == 0xFFFFFFFF


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=600))
def test_the_checksum_agrees_with_zlib_on_reversed_bits(data):
    """An independent CRC: zlib's reflected CRC-32 (same polynomial and initial value, final XOR 0xFFFFFFFF) of the
    data with each byte's bits reversed is the unreflected register reversed."""
    reflected = zlib.crc32(bytes(_reverse8(b) for b in data)) ^ 0xFFFFFFFF
    assert crc32_mpeg2(data) == _reverse32(reflected)


@settings(max_examples=100, deadline=None)
@given(st.binary(max_size=252), st.integers(0, 255 * 8 - 1))
def test_a_sealed_boot2_checks_and_any_flipped_bit_breaks_it(code, bit):
    boot2 = seal_boot2(code)
    assert len(boot2) == 256 and boot2[:len(code)] == code and boot2_sealed(boot2)
    broken = bytearray(boot2)
    broken[bit // 8] ^= 1 << (bit % 8)
    assert not boot2_sealed(bytes(broken))


def test_boot2_longer_than_its_room_is_refused():
    with pytest.raises(UF2Error, match="at most 252"):
        seal_boot2(bytes(253))
    assert not boot2_sealed(bytes(255))


@settings(max_examples=80, deadline=None)
@given(IMAGE, ADDRESS)
def test_every_block_is_the_formats_and_the_image_reads_back(image, address):
    """Each block read with struct against the numbers of microsoft/uf2 and the RP2040 datasheet (2.8.4.2)."""
    data = write(image, address)
    pages = -(-len(image) // PAGE)
    assert len(data) == 512 * pages
    padded = image + b"\xff" * (pages * PAGE - len(image))
    for n in range(pages):
        block = data[512 * n:512 * (n + 1)]
        head = struct.unpack("<8I", block[:32])
        assert head == (0x0A324655, 0x9E5D5157, 0x2000, address + PAGE * n, 256, n, pages, 0xE48BFF56)
        assert block[32:288] == padded[PAGE * n:PAGE * (n + 1)]
        assert block[288:508] == bytes(220)
        assert struct.unpack("<I", block[508:]) == (0x0AB16F30,)
    assert read(data) == (address, padded)
    assert write(image, address) == data  # deterministic


@pytest.mark.parametrize(("image", "address", "what"), [
    (b"", 0x10000000, "empty"), (b"x", 0x10000080, "page"), (b"x", 0x20000000, "page"),
    (bytes(512), 0x10FFFF00, "past the end")])
def test_an_image_that_cannot_be_placed_is_refused(image, address, what):
    with pytest.raises(UF2Error, match=what):
        write(image, address)


def _corrupt(data: bytearray, block: int, kind: str) -> None:
    at = 512 * block
    if kind == "magic":
        data[at] ^= 0x01
    elif kind == "end magic":
        data[at + 511] ^= 0x80
    elif kind == "family":
        struct.pack_into("<I", data, at + 28, 0x00FF00FF)
    elif kind == "flag":
        struct.pack_into("<I", data, at + 8, 0)
    elif kind == "size":
        struct.pack_into("<I", data, at + 16, 476)
    elif kind == "address":
        struct.pack_into("<I", data, at + 12, struct.unpack_from("<I", data, at + 12)[0] + 4)
    elif kind == "outside":
        struct.pack_into("<I", data, at + 12, 0x20000000)
    elif kind == "number":
        struct.pack_into("<I", data, at + 20, struct.unpack_from("<I", data, at + 20)[0] + 1)
    elif kind == "count":
        struct.pack_into("<I", data, at + 24, 0)
    elif kind == "padding":
        data[at + 300] = 1
    elif kind == "duplicate":
        other = 512 * ((block + 1) % (len(data) // 512))
        data[other + 12:other + 16] = data[at + 12:at + 16]
    elif kind == "gap":
        struct.pack_into("<I", data, at + 12, 0x10F00000)
    elif kind == "truncated":
        del data[len(data) - 1 - block:]


KINDS = ("magic", "end magic", "family", "flag", "size", "address", "outside", "number", "count", "padding",
         "duplicate", "gap", "truncated")


@settings(max_examples=300, deadline=None)
@given(st.binary(min_size=PAGE + 1, max_size=2000), ADDRESS, st.sampled_from(KINDS), st.data())
def test_every_kind_of_malformed_file_is_refused_in_one_line(image, address, kind, data):
    written = bytearray(write(image, address))
    block = data.draw(st.integers(0, len(written) // 512 - 1))
    _corrupt(written, block, kind)
    with pytest.raises(UF2Error) as err:
        read(bytes(written))
    assert isinstance(err.value, InputError) and "\n" not in str(err.value)


def test_another_family_is_refused_unless_asked_for():
    data = write(b"abc", family=0x68ED2B88)
    with pytest.raises(UF2Error, match="family 0x68ED2B88"):
        read(data)
    assert read(data, family=0x68ED2B88)[1][:3] == b"abc"


@settings(max_examples=200, deadline=None)
@given(st.binary(max_size=2048), st.binary(min_size=32, max_size=32))
def test_arbitrary_bytes_are_read_or_refused_never_crash(noise, header):
    """Random files, and random headers inside UF2's magic numbers: an image or one UF2Error line."""
    framed = struct.pack("<2I", 0x0A324655, 0x9E5D5157) + header[8:] + noise[:476].ljust(476, b"\0") \
        + struct.pack("<I", 0x0AB16F30)
    for data in (noise, framed):
        refusal = ""
        try:
            start, image = read(data)
        except UF2Error as err:
            refusal = str(err)
        if refusal:
            assert "\n" not in refusal
        else:
            assert start % PAGE == 0 and len(image) % PAGE == 0
