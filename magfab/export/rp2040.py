"""The RP2040 readout boards' firmware: one image per board, its calibration record in flash, and the .uf2 files a
build writes (docs/bundle.md section 4).

* :func:`readout_board` -- the spec's readout board, a recipe of ``recipes/boards.toml`` (the Uno without ``[board]``).
* :func:`defines` -- the compiler's ``-D`` flags that make the image a board's: its I2C controller and pins, and the
  record's flash sector (:func:`record_offset`: the last 4 KB sector of the board's flash; the sensor identity's is
  the sector below, so that a .uf2 holding a record leaves the identity alone).
* :func:`image_name`, :func:`build_uf2` -- ``magfab-rp2040-<board>.uf2``: the image magfab ships for the board
  (:func:`shipped_image`) and this build's record, in one file a board in BOOTSEL mode takes on its USB drive.
* :func:`calibration_uf2` -- ``calibration.uf2``: the record alone, for a board that already runs the image.

The image is the generic one (:func:`magfab.export.firmware.generic_sources` with ``rp2040/``): every setting comes
from the record, as the AVR image's come from its EEPROM. :mod:`magfab.export.toolchain` compiles it with
arm-none-eabi-gcc; ``python -m magfab.export.toolchain`` rewrites the shipped images.
"""

from __future__ import annotations

import json
from functools import cache
from importlib.resources import files
from typing import TYPE_CHECKING, Any

from ..formats.uf2 import FLASH_START, write_regions
from ..recipes import Recipe, catalogue, resolve
from ..spec_sections import readout_board_key

if TYPE_CHECKING:
    from ..spec import Spec

__all__ = ["RP2040_DIR", "RP2040_SOURCES", "ARM_CFLAGS", "ARM_LDFLAGS", "CALIBRATION_UF2", "TOOLCHAIN_JSON",
           "readout_board", "board_key", "short_name", "is_rp2040", "defines", "record_offset", "image_name",
           "binary_name", "shipped_image", "uf2_source", "build_uf2", "calibration_uf2", "rp2040_boards"]

#: The RP2040 sources of the firmware bundle (templates/firmware/rp2040), beside the portable core.
RP2040_DIR = "rp2040"
RP2040_SOURCES = ("start.c", "main.c", "clocks.c", "usb_cdc.c", "flash.c")
ARM_CFLAGS = ("-mcpu=cortex-m0plus", "-mthumb", "-Os", "-std=gnu99", "-Wall", "-Wextra", "-ffunction-sections",
              "-fdata-sections", "-nostartfiles", "--specs=nano.specs", "--specs=nosys.specs")
ARM_LDFLAGS = ("-Wl,--gc-sections", "-lm")
#: boot2 alone: position-independent, no library (boot2.c)
BOOT2_CFLAGS = ("-mcpu=cortex-m0plus", "-mthumb", "-Os", "-Wall", "-Wextra", "-ffreestanding", "-nostdlib", "-fPIC")
CALIBRATION_UF2 = "calibration.uf2"
#: The shipped images' record beside them (package data in generic_image/): toolchain versions, sizes, hashes.
TOOLCHAIN_JSON = "toolchain-rp2040.json"
SECTOR = 4096


def readout_board(spec: Spec) -> Recipe:
    """The spec's readout board: ``[board]``'s, or the Arduino Uno's when the spec has no such section."""
    return resolve.board(board_key(spec))


def board_key(spec: Spec) -> str:
    """The key of the spec's readout board in recipes/boards.toml."""
    return readout_board_key(spec.board)


def short_name(board: Recipe) -> str:
    """The board's name without its parenthesis ("Adafruit QT Py RP2040"), as the bench pages call it."""
    return board.name.split(" (")[0]


def is_rp2040(spec: Spec) -> bool:
    """Whether the spec's readout board is an RP2040 board."""
    return readout_board(spec).texts["mcu"] == "rp2040"


def rp2040_boards() -> list[str]:
    """The RP2040 boards' keys in recipes/boards.toml."""
    return [k for k, r in catalogue("boards").items() if r.texts["mcu"] == "rp2040"]


def record_offset(board: Recipe) -> int:
    """The record's flash offset on ``board``: its last 4 KB sector."""
    return int(board["flash_bytes"].nominal) - SECTOR


def defines(key: str) -> tuple[str, ...]:
    """The ``-D`` flags of board ``key``'s image (main.c, mf_calib.c and mf_nv.c read them): its I2C pins, a second
    bus on the other controller, the record's sector."""
    board = resolve.board(key)
    sda, scl = int(board["sda_gpio"].nominal), int(board["scl_gpio"].nominal)
    sda_b, scl_b = int(board["sda_b_gpio"].nominal), int(board["scl_b_gpio"].nominal)
    return (f"-DMF_RP_I2C={(sda >> 1) & 1}", f"-DMF_RP_SDA={sda}", f"-DMF_RP_SCL={scl}", "-DMF_BUSES=2",
            f"-DMF_RP_SDA_B={sda_b}", f"-DMF_RP_SCL_B={scl_b}", f"-DMF_NV_FLASH_OFFSET=0x{record_offset(board):X}UL")


def image_name(key: str) -> str:
    """The .uf2 a build writes for board ``key``."""
    return f"magfab-rp2040-{key}.uf2"


def binary_name(key: str) -> str:
    """The shipped flash contents (boot2, then the image) for board ``key``, in the package's generic_image/."""
    return f"magfab-rp2040-{key}.bin"


@cache
def _toolchain() -> dict[str, Any]:
    folder = files("magfab.export").joinpath("generic_image")
    return json.loads(folder.joinpath(TOOLCHAIN_JSON).read_text())


def shipped_image(key: str) -> tuple[bytes, dict[str, Any]]:
    """Board ``key``'s shipped flash contents (boot2 sealed, then the image from 0x10000100) and
    ``toolchain-rp2040.json``'s record of it (its sizes beside the toolchain's versions)."""
    folder = files("magfab.export").joinpath("generic_image")
    made = _toolchain()
    return folder.joinpath(binary_name(key)).read_bytes(), {**made, **made["boards"][key]}


def uf2_source() -> bytes:
    """magfab.formats.uf2's source: an RP2040 build's ``firmware/rp2040/uf2.py``, which its Makefile runs."""
    return files("magfab.formats").joinpath("uf2.py").read_bytes()


def build_uf2(key: str, record: bytes) -> bytes:
    """The .uf2 of board ``key``'s shipped image with ``record`` in its sector."""
    image, _ = shipped_image(key)
    return write_regions([(FLASH_START, image), (FLASH_START + record_offset(resolve.board(key)), record)])


def calibration_uf2(key: str, record: bytes) -> bytes:
    """The .uf2 of ``record`` alone in board ``key``'s record sector."""
    return write_regions([(FLASH_START + record_offset(resolve.board(key)), record)])
