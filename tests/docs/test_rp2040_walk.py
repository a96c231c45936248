"""The RP2040 board's pages, pasted as written on a simulated bench (tests/docs/rig_rp2040.py: the board's BOOTSEL
drive, and the emulated RP2040 behind a serial port running whatever .uf2 lands on the drive, with the build's
MLX90393 model). From a folder holding only the example spec: the README's build command, then the checklist's
"Flash and read" section, copying the .uf2 onto the drive, installing the reader, asking the board what it runs and
streaming calibrated forces, a press among them; then the firmware README's commands from firmware/ (the .uf2 copied
again, BOOTSEL held: the board's flash kept under it; the upload; the host build of the core against the simulated
chip); then the readout README's bench block: the .uf2 copied a third time, the scan recorded on the board's clock and
calibrated, the calibration and the sensor's ID uploaded into the board's flash, and the acceptance test."""

from __future__ import annotations

import contextlib
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import _missing, require_tool

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pages import blocks
from rig_rp2040 import Rp2040Rig
from walk import Bench, Scan

from magfab.export import rp2040

EXAMPLE = Path(__file__).resolve().parents[2] / "magfab" / "examples" / "magone_qtpy.toml"
PRESS_N = 1.0


def _flash_and_read(checklist: str) -> list:
    """The checklist's blocks in its "Flash and read" section."""
    start = re.search(r"^## \d+\. Flash and read$", checklist, re.M)
    end = re.search(r"^## ", checklist[start.end():], re.M)
    return blocks(checklist[start.start():start.end() + (end.start() if end else len(checklist))], "checklist.md")


def _bench_block(readme: str) -> list:
    """The readout README's bench block: the board flashed, the sensor streamed, its scan recorded and calibrated,
    the calibration and its ID uploaded, the acceptance test."""
    return [b for b in blocks(readme, "readout/README.md") if any(c.startswith("magfab-readout check") for c in
                                                                   b.commands) and b.lang == "sh"][:1]


@pytest.fixture(scope="module")
def rp2040_walked(tmp_path_factory):
    require_tool("cc")
    if not os.access("/media" if Path("/media").exists() else "/", os.W_OK):
        _missing("the walk makes the board's drive under /media (the pages' Linux path), not writable here")
    lab = tmp_path_factory.mktemp("rp2040-lab")
    venv = lab.parent / (lab.name + "-venv")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, capture_output=True, timeout=300)
    shutil.copyfile(EXAMPLE, lab / EXAMPLE.name)
    with contextlib.ExitStack() as stack:
        bench = Bench(cwd=lab, venv=venv, plug_in=None, home=lab)
        built = bench.paste(f"magfab build {EXAMPLE.name}")
        assert built.returncode == 0, built.stdout + built.stderr
        build = lab / "build" / "magone-qtpy"
        bench.cwd = build
        bench.rig = stack.enter_context(Rp2040Rig(build, tmp_path_factory.mktemp("rp2040-board")))
        bench.scan = Scan(build)
        bench.scan.at_rest(bench.rig)
        bench.press = [bench.scan.field_at(PRESS_N)]
        pages = [(_flash_and_read((build / "checklist.md").read_text()), build),
                 (blocks((build / "firmware" / "README.md").read_text(), "firmware/README.md"), build / "firmware"),
                 (_bench_block((build / "readout" / "README.md").read_text()), build)]
        for page, folder in pages:
            bench.cwd = folder
            for block in page:
                for line in block.commands:
                    if line.startswith("cp ") and "RPI-RP2" in line and bench.rig.flashed is not None:
                        bench.rig.bootsel()  # a board that runs an image: BOOTSEL held while it is plugged in
                    ran = bench.paste(line)
                    interrupted = "Ctrl-C ends it" in line and ran.returncode == 130
                    assert (ran.returncode == 0 or interrupted) and "Traceback" not in ran.stderr, (
                        f"{block}: `{line}` exited {ran.returncode}\n{ran.stdout[-3000:]}\n{ran.stderr[-3000:]}")
        bench.cwd = build
        yield bench


def test_the_bench_path_ends_in_a_passing_acceptance_test_on_the_rp2040(rp2040_walked):
    """The readout README's bench block on the RP2040 board: the scan recorded on the board's clock and calibrated
    against the reference log into the sensor's record, that calibration and the sensor's ID uploaded into the
    board's flash over USB (the board then names the sensor), and the acceptance test passes, turned over and warmed
    at its prompts."""
    fitted = next(r for r in rp2040_walked.ran if r.line.startswith("magfab calibrate")).stdout
    fit = next(line for line in fitted.splitlines() if line.startswith("calibrated sensor"))
    print(fit)  # with -s
    assert float(fit.split("held-out RMS Fz ")[1].split()[0]) < 50, fit  # the AVR walk's bound (test_pages.py)
    last = [r for r in rp2040_walked.ran if r.line.startswith("magfab-readout info")][-1].stdout
    assert "sensor:  magone-qtpy-01, calibration of " in last, last
    check = next(r for r in rp2040_walked.ran if r.line.startswith("magfab-readout check"))
    print("\n".join(line for line in check.stdout.splitlines() if line.startswith("step ")))  # with -s
    assert "FAIL" not in check.stdout and check.stdout.count("PASS") >= 6, check.stdout
    passed = [line.split()[2] for line in check.stdout.splitlines() if line.startswith("step ") and "PASS" in line]
    assert {"turned", "warm-up"} <= set(passed), check.stdout


def test_the_uf2_copied_onto_the_drive_runs_and_streams_forces(rp2040_walked):
    """The board ran exactly the build's .uf2 (the copy the page made), the reader found this build's calibration
    on it, and the stream zeroed at rest and read the press."""
    build = rp2040_walked.cwd
    key = rp2040_walked.rig.key
    assert rp2040_walked.rig.flashed.read_bytes() == (build / "firmware" / rp2040.image_name(key)).read_bytes()
    upload = next(r for r in rp2040_walked.ran if r.line.startswith("magfab-readout upload"))
    assert upload.returncode == 0, upload.stdout + upload.stderr
    infos = [r for r in rp2040_walked.ran if r.line.startswith("magfab-readout info")]
    assert len(infos) == 4 and all("calibration: match" in r.stdout for r in infos[:3]), [r.stdout for r in infos]
    assert rp2040_walked.rig.resets == 3  # flashed three times: the checklist's copy, the firmware and readout READMEs'

    stream = next(r for r in rp2040_walked.ran if r.line.startswith("magfab-readout stream"))
    rows = [line.split() for line in stream.stdout.splitlines() if line and not line.startswith("#")]
    fz = [float(r[4]) for r in rows if len(r) > 4 and re.fullmatch(r"[-+]?\d+\.\d+", r[4])]
    print(f"{len(fz)} samples, Fz up to {max(fz):.3f} N")
    assert "# zero:" in stream.stdout and max(fz) > 0.5 * PRESS_N, stream.stdout[:3000]
