"""UF2 images for the RP2040 (the file a board in BOOTSEL mode takes on its USB drive) and the checksum of the
RP2040's second-stage boot (boot2).

UF2 (Microsoft's USB Flashing Format, github.com/microsoft/uf2, "File format"): a file of 512-byte blocks, each
little-endian::

    0    magic 0x0A324655 ("UF2\\n")      4    magic 0x9E5D5157
    8    flags (0x2000: the family ID is given)
    12   address the payload is written to
    16   payload size                    20   block number (from 0)
    24   number of blocks in the file    28   family ID
    32   payload, then zeros to 476 bytes
    508  magic 0x0AB16F30

The RP2040 bootrom takes only blocks with the family ID flag and the RP2040's family, 0xE48BFF56, a payload of 256
bytes, and an address in flash (0x10000000 up to 0x11000000) on a 256-byte page (RP2040 datasheet, section 2.8.4.2
"UF2 Format Details"). :func:`write` writes such a file, one block per page, the image padded to whole pages with
0xFF (erased flash); :func:`read` takes one back, checking every block, and refuses any other with
:class:`UF2Error` (one line, naming the block and what is wrong).

boot2 is the first 256 bytes of flash. The bootrom copies them to RAM and runs them only if their last four bytes are
the CRC-32 of the first 252 (polynomial 0x04C11DB7, initial value 0xFFFFFFFF, no reflection of input or output, no
final XOR: the CRC catalogue's CRC-32/MPEG-2, check value 0x0376E6E7), little-endian (datasheet, section 2.8.1.3,
the flash boot sequence's checksum). :func:`seal_boot2` appends it, :func:`boot2_sealed` checks it.

An RP2040 build copies this file into its ``firmware/rp2040/`` as ``uf2.py``, where the Makefile runs it on the
user's Python alone (:func:`main`: boot2 sealed, the image after it and a record's UF2 in one file).
"""

from __future__ import annotations

import argparse
import os
import struct
import sys
from pathlib import Path

if __name__.startswith("magfab."):  # magfab's import of this file: an InputError, exit 2
    from magfab.errors import InputError as _Base
else:  # the copy in an RP2040 build's firmware/rp2040/, run by its Makefile on the user's Python alone
    _Base = ValueError  # type: ignore[misc, assignment]

__all__ = ["UF2Error", "write", "read", "write_regions", "read_regions", "crc32_mpeg2", "seal_boot2", "boot2_sealed",
           "MAGIC_START0", "MAGIC_START1", "MAGIC_END", "FLAG_FAMILY_ID", "RP2040_FAMILY", "BLOCK_SIZE", "PAGE_SIZE",
           "FLASH_START", "FLASH_END", "BOOT2_SIZE"]

MAGIC_START0, MAGIC_START1, MAGIC_END = 0x0A324655, 0x9E5D5157, 0x0AB16F30
FLAG_FAMILY_ID = 0x00002000
RP2040_FAMILY = 0xE48BFF56
#: A block, its header, and the room for a payload (microsoft/uf2).
BLOCK_SIZE, HEADER_SIZE, DATA_SIZE = 512, 32, 476
#: The RP2040's payload: one flash page.
PAGE_SIZE = 256
#: The RP2040's flash as a UF2 file may address it (datasheet, section 2.8.4.2).
FLASH_START, FLASH_END = 0x10000000, 0x11000000
#: boot2: its size, and the bytes its checksum covers.
BOOT2_SIZE, BOOT2_CHECKED = 256, 252

_HEADER = struct.Struct("<8I")
_END = struct.Struct("<I")


class UF2Error(_Base):
    """A file that is not an RP2040 UF2 image as :func:`read` takes it, or an image :func:`write` cannot place."""


def _table() -> tuple[int, ...]:
    out = []
    for byte in range(256):
        c = byte << 24
        for _ in range(8):
            c = ((c << 1) ^ 0x04C11DB7) if c & 0x80000000 else (c << 1)
        out.append(c & 0xFFFFFFFF)
    return tuple(out)


_CRC = _table()


def crc32_mpeg2(data: bytes) -> int:
    """CRC-32/MPEG-2 of ``data`` (module doc): what the bootrom computes over boot2's first 252 bytes."""
    c = 0xFFFFFFFF
    for b in data:
        c = ((c << 8) & 0xFFFFFFFF) ^ _CRC[((c >> 24) ^ b) & 0xFF]
    return c


def seal_boot2(code: bytes) -> bytes:
    """boot2 as the bootrom runs it: ``code`` (at most 252 bytes) padded with zeros to 252, then its checksum."""
    if len(code) > BOOT2_CHECKED:
        raise UF2Error(f"boot2 is {len(code)} bytes: at most {BOOT2_CHECKED} fit before its checksum")
    body = bytes(code).ljust(BOOT2_CHECKED, b"\0")
    return body + struct.pack("<I", crc32_mpeg2(body))


def boot2_sealed(flash: bytes) -> bool:
    """Whether the first 256 bytes of ``flash`` are a boot2 the bootrom would run (its checksum holds)."""
    if len(flash) < BOOT2_SIZE:
        return False
    return struct.unpack_from("<I", flash, BOOT2_CHECKED)[0] == crc32_mpeg2(flash[:BOOT2_CHECKED])


def write(image: bytes, address: int = FLASH_START, family: int = RP2040_FAMILY) -> bytes:
    """The UF2 file that writes ``image`` to flash at ``address`` (on a page): one block per 256-byte page, the last
    page padded with 0xFF. The same image gives the same bytes."""
    return write_regions([(address, image)], family)


def write_regions(regions: list[tuple[int, bytes]], family: int = RP2040_FAMILY) -> bytes:
    """The UF2 file that writes each ``(address, bytes)`` of ``regions`` (each on a page, none overlapping another's
    pages): one block per page, in the order given, each region's last page padded with 0xFF. (The bootrom erases a
    4 KB sector the first time a block writes to it: what a region's sectors held besides it is then 0xFF.)"""
    pages: list[tuple[int, bytes]] = []
    for address, image in regions:
        if not image:
            raise UF2Error("the image is empty: nothing to write")
        if address % PAGE_SIZE or not FLASH_START <= address < FLASH_END:
            raise UF2Error(f"address 0x{address:08X}: an image starts on a {PAGE_SIZE}-byte page in flash "
                           f"(0x{FLASH_START:08X}-0x{FLASH_END - 1:08X})")
        count = -(-len(image) // PAGE_SIZE)
        if address + count * PAGE_SIZE > FLASH_END:
            raise UF2Error(f"an image of {len(image)} bytes at 0x{address:08X} runs past the end of flash "
                           f"(0x{FLASH_END:08X})")
        padded = bytes(image).ljust(count * PAGE_SIZE, b"\xff")
        pages += [(address + n * PAGE_SIZE, padded[n * PAGE_SIZE:(n + 1) * PAGE_SIZE]) for n in range(count)]
    if len({a for a, _ in pages}) != len(pages):
        raise UF2Error("two regions write the same page")
    out = bytearray()
    for n, (address, page) in enumerate(pages):
        out += _HEADER.pack(MAGIC_START0, MAGIC_START1, FLAG_FAMILY_ID, address, PAGE_SIZE, n, len(pages), family)
        out += page.ljust(DATA_SIZE, b"\0")
        out += _END.pack(MAGIC_END)
    return bytes(out)


def read(data: bytes, family: int = RP2040_FAMILY) -> tuple[int, bytes]:
    """The image a UF2 file writes: (its first address, its bytes), the pages in address order and contiguous
    (:func:`read_regions` for a file of several)."""
    regions = read_regions(data, family)
    if len(regions) > 1:
        raise UF2Error(f"the pages are not contiguous: none at 0x{regions[0][0] + len(regions[0][1]):08X}")
    return regions[0]


def read_regions(data: bytes, family: int = RP2040_FAMILY) -> list[tuple[int, bytes]]:
    """What a UF2 file writes, as ``(address, bytes)`` runs of contiguous pages in address order.
    Every block is checked (magics, the family flag and ``family``, a 256-byte payload on a page in flash, the block
    numbers 0 to n - 1 and the same count in each, the padding after the payload zero); :class:`UF2Error` names the
    first that is not."""
    if not data or len(data) % BLOCK_SIZE:
        raise UF2Error(f"a UF2 file is whole {BLOCK_SIZE}-byte blocks; this one is {len(data)} bytes")
    blocks = len(data) // BLOCK_SIZE
    pages: dict[int, bytes] = {}
    for i in range(blocks):
        at = i * BLOCK_SIZE
        m0, m1, flags, addr, size, number, count, fam = _HEADER.unpack_from(data, at)
        where = f"block {i}"
        if (m0, m1) != (MAGIC_START0, MAGIC_START1) or _END.unpack_from(data, at + BLOCK_SIZE - 4)[0] != MAGIC_END:
            raise UF2Error(f"{where}: its magic numbers are not UF2's (0x{MAGIC_START0:08X}, 0x{MAGIC_START1:08X}, "
                           f"0x{MAGIC_END:08X})")
        if not flags & FLAG_FAMILY_ID or fam != family:
            raise UF2Error(f"{where}: family 0x{fam:08X} (flags 0x{flags:08X}); the RP2040 takes family "
                           f"0x{family:08X} with flag 0x{FLAG_FAMILY_ID:04X}")
        if size != PAGE_SIZE:
            raise UF2Error(f"{where}: a payload of {size} bytes; the RP2040 takes {PAGE_SIZE}")
        if addr % PAGE_SIZE or not FLASH_START <= addr <= FLASH_END - PAGE_SIZE:
            raise UF2Error(f"{where}: address 0x{addr:08X} is not a {PAGE_SIZE}-byte page in flash "
                           f"(0x{FLASH_START:08X}-0x{FLASH_END - 1:08X})")
        if number != i or count != blocks:
            raise UF2Error(f"{where}: numbered {number} of {count}; a file of {blocks} blocks numbers them 0 to "
                           f"{blocks - 1}")
        if any(data[at + HEADER_SIZE + PAGE_SIZE:at + BLOCK_SIZE - 4]):
            raise UF2Error(f"{where}: the bytes after its payload are not zero")
        if addr in pages:
            raise UF2Error(f"{where}: address 0x{addr:08X} is written twice")
        pages[addr] = data[at + HEADER_SIZE:at + HEADER_SIZE + PAGE_SIZE]
    runs: list[list[int]] = []  # [first page, last page]
    for addr in sorted(pages):
        if runs and runs[-1][1] + PAGE_SIZE == addr:
            runs[-1][1] = addr
        else:
            runs.append([addr, addr])
    return [(a, b"".join(pages[p] for p in range(a, b + PAGE_SIZE, PAGE_SIZE))) for a, b in runs]


def main(argv: list[str] | None = None) -> int:
    """``python3 uf2.py OUT.uf2 BOOT2.bin IMAGE.bin RECORD.uf2``: boot2 (at most 252 bytes) sealed with its checksum,
    the image after it (from 0x10000100) and what RECORD.uf2 writes (a build's calibration.uf2: the record in the
    board's last flash sector), in one UF2 file written whole. Exit 2 with one line for a file that cannot be read
    or is not what it should be."""
    parser = argparse.ArgumentParser(prog="uf2.py", description=main.__doc__)
    for name in ("out", "boot2", "image", "record"):
        parser.add_argument(name)
    args = parser.parse_args(argv)
    try:
        flash = seal_boot2(Path(args.boot2).read_bytes()) + Path(args.image).read_bytes()
        data = write_regions([(FLASH_START, flash), *read_regions(Path(args.record).read_bytes())])
    except (OSError, UF2Error) as exc:
        print(f"uf2.py: {exc}", file=sys.stderr)
        return 2
    partial = Path(f"{args.out}.partial")
    partial.write_bytes(data)
    os.replace(partial, args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
