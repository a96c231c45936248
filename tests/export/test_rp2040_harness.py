"""The RP2040 emulator harness (tests/firmware_sim/rp2040): arm-none-eabi-gcc builds its smoke images, magfab writes
them as UF2 files behind a sealed boot2 (magfab.formats.uf2), and rp2040js runs them from the vector table after
boot2: the line one sends on UART0 arrives, and the other enumerates as a USB CDC device and its lines arrive. The
harness checks each block and boot2's checksum in its own implementation and refuses a file whose boot2 or family
is wrong."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest
from conftest import require_node_package, require_tool

from magfab.formats.uf2 import boot2_sealed, read, seal_boot2, write

HARNESS = Path(__file__).resolve().parent.parent / "firmware_sim" / "rp2040"


def _run(node: str, uf2: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([node, str(HARNESS / "run.mjs"), str(uf2), *args], capture_output=True, text=True,
                          timeout=60, cwd=HARNESS)


def _build(out: Path, *sources: str) -> bytes:
    """The flash contents of one harness image: a sealed empty boot2, then ``sources`` built for the Cortex-M0+."""
    gcc = require_tool("arm-none-eabi-gcc")
    objcopy = require_tool("arm-none-eabi-objcopy")
    elf, binary = out / f"{sources[0]}.elf", out / f"{sources[0]}.bin"
    subprocess.run([gcc, "-mcpu=cortex-m0plus", "-mthumb", "-Os", "-ffreestanding", "-nostdlib", "-Wall", "-Wextra",
                    "-Werror", "-T", str(HARNESS / "smoke.ld"), "-o", str(elf), *(str(HARNESS / s) for s in sources)],
                   check=True)
    subprocess.run([objcopy, "-O", "binary", str(elf), str(binary)], check=True)
    return seal_boot2(b"") + binary.read_bytes()


@pytest.fixture(scope="module")
def smoke(tmp_path_factory):
    """The UART smoke image: (node, its flash contents, the .uf2's path)."""
    node = require_node_package(HARNESS, "rp2040js")
    out = tmp_path_factory.mktemp("rp2040")
    flash = _build(out, "smoke.c")
    uf2 = out / "smoke.uf2"
    uf2.write_bytes(write(flash))
    return node, flash, uf2


def test_the_smoke_image_runs_on_the_emulated_rp2040(smoke):
    node, flash, uf2 = smoke
    start, image = read(uf2.read_bytes())
    assert start == 0x10000000 and image[:len(flash)] == flash and boot2_sealed(image)
    run = _run(node, uf2, "--until", "\n")
    assert run.returncode == 0, run.stdout + run.stderr
    report = json.loads(run.stdout)
    assert report["boot2_crc_ok"] and report["blocks"] == -(-len(flash) // 256)
    assert report["uart"] == "magfab rp2040 smoke\n"


def test_a_cdc_device_enumerates_and_echoes_on_the_emulated_usb(smoke, tmp_path):
    """usb_smoke.c on usb_cdc.c, a CDC-ACM device from the datasheet: rp2040js's host sets its address, reads its
    configuration (67 bytes, in two packets), configures it and sets the control lines; its greeting arrives, and a
    line sent to it, longer than a packet, comes back in capitals, whole and in order."""
    node = smoke[0]
    uf2 = tmp_path / "usb.uf2"
    uf2.write_bytes(write(_build(tmp_path, "usb_smoke.c", "usb_cdc.c")))
    line = "ping " + "abcdefghij" * 10 + "\n"
    run = _run(node, uf2, "--send", line, "--until", line.upper())
    assert run.returncode == 0, run.stdout + run.stderr
    report = json.loads(run.stdout)
    assert report["usb_connected"] and report["usb"] == "magfab rp2040 usb\n" + line.upper()


@pytest.mark.parametrize(("change", "refusal"), [("boot2", "boot2 checksum"), ("family", "block 0: family")])
def test_the_harness_refuses_what_the_bootrom_would(smoke, tmp_path, change, refusal):
    node, flash, _ = smoke
    data = write(bytes([flash[0] ^ 1]) + flash[1:]) if change == "boot2" else write(flash, family=0x68ED2B88)
    bad = tmp_path / "bad.uf2"
    bad.write_bytes(data)
    run = _run(node, bad)
    assert run.returncode == 2 and json.loads(run.stdout) == {"refused": refusal}
