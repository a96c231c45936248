"""What an RP2040 build gives the bench: the .uf2 (the board's shipped image and the build's record in the board's last
flash sector), calibration.uf2, the RP2040 sources and no AVR files; a BOM and a wiring table with no level shifter,
the board's own pins from recipes/boards.toml; flash instructions that copy the .uf2 onto the RPI-RP2 drive. Every
RP2040 board of the recipe, and a [board] that names another microcontroller's board refused in one line."""

from __future__ import annotations

import csv
import io
import json
import shutil
import subprocess
import sys

import pytest
from click.testing import CliRunner
from conftest import require_tool
from readout_support import make_calibration

from magfab import derive, load_spec
from magfab.cli import main
from magfab.errors import SpecError
from magfab.export import bom, checklist_rp2040, firmware, rp2040, toolchain
from magfab.formats.uf2 import FLASH_START, boot2_sealed, read_regions
from magfab.recipes import catalogue, resolve
from magfab.spec import parse_spec


def _record(build) -> bytes:
    """The build's record, as its readout package packs it (the bytes ``magfab-readout upload`` writes)."""
    cal = json.loads((build.out_dir / "calibration" / "calibration.json").read_text())
    return firmware.eeprom_record(derive(build.spec), cal)


def test_the_build_writes_the_uf2_of_the_shipped_image_and_its_record(rp2040_build):
    fw = rp2040_build.out_dir / "firmware"
    key = rp2040.board_key(rp2040_build.spec)
    image, record = read_regions((fw / rp2040.image_name(key)).read_bytes())
    assert image == (FLASH_START, rp2040.shipped_image(key)[0].ljust(len(image[1]), b"\xff"))
    offset = rp2040.record_offset(resolve.board(key))
    assert record[0] == FLASH_START + offset and record[1].rstrip(b"\xff") == _record(rp2040_build).rstrip(b"\xff")
    assert read_regions((fw / rp2040.CALIBRATION_UF2).read_bytes()) == [record]
    assert rp2040_build.calibration["image"] == f"firmware/{rp2040.image_name(key)}"  # what the build says it wrote
    names = {p.relative_to(fw).as_posix() for p in fw.rglob("*") if p.is_file()}
    assert {f"rp2040/{s}" for s in rp2040.RP2040_SOURCES} <= names
    assert not [n for n in names if n.startswith("avr/") or n.endswith((".hex", ".eep", ".ino")) or n in (
        "flash.sh", "flash.bat", "platformio.ini")]


def test_the_bench_pages_have_no_level_shifter_and_copy_the_uf2(rp2040_build):
    out = rp2040_build.out_dir
    key = rp2040.board_key(rp2040_build.spec)
    rows = list(csv.DictReader(io.StringIO((out / "bom.csv").read_text())))
    items = {r["item"]: r for r in rows}
    assert "Level shifter" not in items and "Jumper wires" not in items
    assert rp2040.image_name(key) in items["Microcontroller"]["description"]
    assert items["Cable"]["part"] == catalogue("bench")["qwiic-cable"].name  # the QT Py's STEMMA QT socket
    page = (out / "checklist.md").read_text()
    assert "level shifter, low side" not in page and "flash.sh" not in page
    for command in checklist_rp2040.flash_commands(derive(rp2040_build.spec)):
        assert command in page
    readme = (out / "readout" / "README.md").read_text()
    assert "flash.sh" not in readme and f"cp firmware/{rp2040.image_name(key)}" in readme
    assert "cp " + rp2040.image_name(key) in (out / "firmware" / "README.md").read_text()


@pytest.mark.parametrize("key", rp2040.rp2040_boards())
def test_every_rp2040_board_gets_its_pins_its_sector_and_its_cable(key):
    """Each board of recipes/boards.toml: the image's -D flags name its controller and pins (an SDA pin and an SCL pin
    of one controller, as the datasheet's function table pairs them), the record's sector is its flash's last, the
    wiring table its pins, and the BOM the cable that fits its socket (or its header)."""
    board = resolve.board(key)
    design = derive(load_spec(None).model_copy(update={"board": parse_spec(f'[board]\nboard = "{key}"\n').board}))
    sda, scl = int(board["sda_gpio"].nominal), int(board["scl_gpio"].nominal)
    assert rp2040.defines(key)[:3] == (f"-DMF_RP_I2C={(sda >> 1) & 1}", f"-DMF_RP_SDA={sda}", f"-DMF_RP_SCL={scl}")
    assert sda % 2 == 0 and scl == sda + 1
    sda_b, scl_b = int(board["sda_b_gpio"].nominal), int(board["scl_b_gpio"].nominal)  # the second bus: the other
    assert sda_b % 2 == 0 and scl_b == sda_b + 1 and (sda_b >> 1) & 1 != (sda >> 1) & 1  # controller's pair
    assert rp2040.defines(key)[3:6] == ("-DMF_BUSES=2", f"-DMF_RP_SDA_B={sda_b}", f"-DMF_RP_SCL_B={scl_b}")
    assert rp2040.record_offset(board) == board["flash_bytes"].nominal - 4096
    assert [pin for _, pin in checklist_rp2040.wiring_rows(design)] == [board.texts[k] for k in (
        "gnd_pin", "v3_pin", "sda_pin", "scl_pin")]
    cable = next(r for r in bom.bom_rows(design) if r["item"] == "Cable")
    socket = board.texts["connector"] == "stemma-qt"
    assert cable["part"] == catalogue("bench")["qwiic-cable" if socket else "qwiic-jumper"].name
    assert not [r for r in bom.bom_rows(design) if r["item"] == "Level shifter"]
    name, data, _ = firmware.ready_image(design, make_calibration())
    assert name == f"firmware/{rp2040.image_name(key)}"
    assert read_regions(data)[-1][0] == FLASH_START + rp2040.record_offset(board)


@pytest.mark.parametrize(("board", "allowed"), [
    ('mcu = "atmega328p"\nboard = "pico"', "the atmega328p boards: uno, nano"),
    ('mcu = "rp2040"\nboard = "nano"', "the rp2040 boards: pico"),
    ('board = "pi-pico"', "must be 'uno', 'nano', 'pico'")])
def test_a_board_of_another_microcontroller_is_refused_in_one_line(board, allowed, tmp_path):
    """``magfab check`` refuses it, exit 2, one line naming what is allowed, nothing written."""
    spec = tmp_path / "spec.toml"
    spec.write_text(f"[board]\n{board}\n")
    with pytest.raises(SpecError, match=allowed.replace("(", r"\(")):
        load_spec(spec)
    run = CliRunner().invoke(main, ["check", str(spec)])
    assert run.exit_code == 2 and allowed in run.output and len(run.output.strip().splitlines()) == 1, run.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["spec.toml"]


@pytest.mark.parametrize("key", rp2040.rp2040_boards())
def test_an_array_on_two_buses_wires_j2_to_the_boards_second_controller(key):
    """``array.buses = 2`` on each RP2040 board: the wiring table adds J2's SDA and SCL to the board's second bus's
    pins (its ground and supply wires taped off), the BOM a second Qwiic-to-pins cable, a second connector and four
    pull-ups, the solder step J2 and R1-R4; and the record's mask names the odd taxels."""
    board = resolve.board(key)
    spec = parse_spec(f'[array]\nrows = 1\ncols = 3\npitch_mm = 14\nbuses = 2\n[board]\nboard = "{key}"\n')
    design = derive(spec)
    rows = checklist_rp2040.wiring_rows(design)
    assert ("J2 SDA (pin 3)", board.texts["sda_b_pin"]) in rows and ("J2 SCL (pin 4)", board.texts["scl_b_pin"]) in rows
    assert [pin for _, pin in rows[:4]] == [board.texts[k] for k in ("gnd_pin", "v3_pin", "sda_pin", "scl_pin")]
    text = " ".join(checklist_rp2040.wiring_text(design))
    assert board.texts["sda_b_pin"] in text and "J2" in text and "tape off" in text
    items = bom.bom_rows(design)
    cables = [r for r in items if r["item"] == "Cable"]
    assert len(cables) == 2 and cables[1]["part"] == catalogue("bench")["qwiic-jumper"].name
    assert "J2" in cables[1]["description"]
    assert next(r for r in items if r["item"] == "Connector")["quantity"] == 2
    assert next(r for r in items if r["item"] == "Resistor")["quantity"] == 4
    settings = firmware.image_settings(design)
    assert settings["taxel_buses"] == 0b010
    record = firmware.eeprom_record(design, make_calibration())
    assert int.from_bytes(record[6:8], "little") == 0b010


def test_make_rebuilds_the_builds_uf2_from_its_sources_byte_for_byte(rp2040_build, tmp_path):
    """The firmware README's ``make -C rp2040`` in a copy of the build's firmware folder: boot2 and the image compiled
    from the bundle's own sources with the flags magfab uses, and the bundle's ``rp2040/uf2.py`` (magfab's UF2 writer,
    verbatim) putting them and ``calibration.uf2``'s record in one file: the build's own .uf2, byte for byte, with the
    arm-none-eabi-gcc that toolchain-rp2040.json names (another compiler: a sealed boot2, the record in its sector).
    uf2.py refuses a record that is not a UF2 file in one line, exit 2, nothing written."""
    make = require_tool("make")
    require_tool("arm-none-eabi-gcc")
    fw = tmp_path / "firmware"
    shutil.copytree(rp2040_build.out_dir / "firmware", fw)
    key = rp2040.board_key(rp2040_build.spec)
    built = (fw / rp2040.image_name(key)).read_bytes()
    assert (fw / "rp2040" / "uf2.py").read_bytes() == rp2040.uf2_source()
    (fw / rp2040.image_name(key)).unlink()
    ran = subprocess.run([make, "-C", "rp2040"], cwd=fw, capture_output=True, text=True, timeout=300)
    assert ran.returncode == 0, ran.stdout + ran.stderr
    made = (fw / rp2040.image_name(key)).read_bytes()
    regions = read_regions(made)
    assert boot2_sealed(regions[0][1]) and regions[-1][0] == FLASH_START + rp2040.record_offset(rp2040.readout_board(
        rp2040_build.spec))
    if toolchain.arm_versions() == rp2040.shipped_image(key)[1]["toolchain"]:
        assert made == built
    bad = subprocess.run([sys.executable, "uf2.py", str(tmp_path / "out.uf2"), "build/boot2.bin", f"build/{key}.bin",
                          "Makefile"], cwd=fw / "rp2040", capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and bad.stderr.startswith("uf2.py: ") and len(bad.stderr.strip().splitlines()) == 1
    assert not list(tmp_path.glob("out.uf2*"))
