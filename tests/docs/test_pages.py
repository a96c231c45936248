"""The pages a person follows, pasted as written: the README from `magfab init` to the acceptance test, then
the build's checklist and bundle READMEs, in a fresh folder, on a simulated bench (tests/docs/rig.py: the
real avrdude flashing a simulated Uno's bootloader, the shipped image in simavr on a serial port, the
build's own MLX90393 model; walk.py: a shell, the scan and the weight). A command that drifts from the code
fails here."""

from __future__ import annotations

import contextlib
import csv
import hashlib
import json
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import _missing, require_tool

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pages import blocks, install_command  # noqa: E402
from rig import Rig, build_library  # noqa: E402
from simbus import HarnessUnavailable  # noqa: E402
from walk import Bench  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
README = (ROOT / "README.md").read_text(encoding="utf-8")


@pytest.fixture(scope="module")
def walked(tmp_path_factory):
    """The README's commands, in order, in an empty folder: the bench, after the walk."""
    require_tool("avrdude")
    require_tool("cc")
    lab = tmp_path_factory.mktemp("lab")
    venv = lab.parent / (lab.name + "-venv")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, capture_output=True, timeout=300)
    with contextlib.ExitStack() as stack:

        def plug_in(build_dir: Path) -> Rig:
            try:
                lib = build_library(build_dir, tmp_path_factory.mktemp("harness"))
            except HarnessUnavailable as exc:
                _missing(str(exc))
            return stack.enter_context(Rig(build_dir, lib, tmp_path_factory.mktemp("board")))

        bench = Bench(cwd=lab, venv=venv, plug_in=plug_in)
        skip = install_command(README)
        for block in blocks(README, "README.md"):
            for line in block.commands:
                if line == skip:
                    continue
                ran = bench.paste(line) if block.lang == "sh" else bench.python(block.text)
                _assert_ok(ran, block)
                if block.lang == "python":
                    break
        yield bench


def _assert_ok(ran, block) -> None:
    interrupted = "Ctrl-C ends it" in ran.line
    ok = ran.returncode == 0 or interrupted and ran.returncode == 130
    assert ok and "Traceback" not in ran.stderr, (
        f"{block}: `{ran.line}` in {ran.cwd} exited {ran.returncode}\n{ran.stdout[-3000:]}\n{ran.stderr[-3000:]}")


def _ran(bench, start: str):
    return next(r for r in bench.ran if r.line.startswith(start))


def test_the_readme_walk_reaches_a_passing_acceptance_test(walked):
    """Flash (avrdude over the bootloader), install, upload, stream, record during the scan, calibrate in place
    against the reference log, reinstall, upload, and the acceptance test passes on the board."""
    build = walked.cwd
    assert build.name == "finger" and (build / "manifest.json").is_file() and not (build / "build").exists()
    flashed = _data(walked.rig.flashed.read_text())  # what avrdude wrote, in whole pages
    image = _data((build / "firmware" / "magfab-atmega328p.hex").read_text())
    assert flashed[:len(image)] == image and set(flashed[len(image):]) <= {0xFF}
    assert "calibration: match" in _ran(walked, "magfab-readout info").stdout
    check = _ran(walked, "magfab-readout check")
    assert "FAIL" not in check.stdout and check.stdout.count("PASS") >= 4, check.stdout
    cal = json.loads((build / "calibration" / "calibration.json").read_text())
    assert cal["scan"]["source"] == "scan.csv + reference.csv" and not (build / "calibration" / "scan_simulated.csv").exists()
    fitted = _ran(walked, "magfab calibrate").stdout
    print(next(line for line in fitted.splitlines() if "calibration (" in line))  # the bench scan's fit, with -s
    merged = (build / "calibration" / "scan_merged.csv").read_bytes()  # what was fitted, by its hash
    from magfab.formats.scan_csv import read_scan_csv

    assert read_scan_csv(merged).rows == cal["scan"]["rows"]
    data = b"".join(line for line in merged.splitlines(keepends=True) if not line.startswith(b"#"))
    assert hashlib.sha256(data).hexdigest() == cal["scan"]["sha256"]  # the file without its comment
    assert _ran(walked, "magfab-readout record").returncode == 0  # Ctrl-C ends a recording as a success
    uploads = [r for r in walked.ran if r.line.startswith("magfab-readout upload")]
    assert len(uploads) == 2 and cal["scan"]["sha256"] and uploads[-1].stdout != uploads[0].stdout
    with open(build / "scan.csv", newline="") as f:
        header = next(csv.reader(line for line in f if not line.startswith("#")))
    assert "Fz_sensor_N" in header and "Fz_N" not in header  # the recording keeps the sensor's own forces apart


def test_the_rest_of_the_pages_run_as_written(walked):
    """The checklist's and the bundle READMEs' commands, each page from its own folder, after the README's walk
    (a line the walk already ran in the same folder is not run twice: the same text, the same state)."""
    for tool in ("avr-gcc", "simavr", "make"):  # the firmware README builds the image and its benchmark
        require_tool(tool)
    build = walked.cwd
    done = {(_command(r.line), r.cwd) for r in walked.ran}
    pages = [("checklist.md", build), ("readout/README.md", build), ("firmware/README.md", build / "firmware")]
    try:
        ran = _paste_pages(walked, build, pages, done)
    finally:
        walked.cwd = build
    assert ran >= 3


def _paste_pages(walked, build, pages, done) -> int:
    ran = 0
    for page, folder in pages:
        walked.cwd = folder
        for block in blocks((build / page).read_text(encoding="utf-8"), page):
            if block.lang == "python":
                _assert_ok(walked.python(block.text), block)
                ran += 1
                continue
            for line in block.commands:
                if (_command(line.replace("/dev/ttyACM0", walked.rig.port)), walked.cwd) in done:
                    continue
                ran_line = walked.paste(line)
                _assert_ok(ran_line, block)
                done.add((_command(ran_line.line), ran_line.cwd))
                ran += 1
    return ran


def _command(line: str) -> str:
    """A command without its comment and spacing: the same command on two pages is run once."""
    return " ".join(line.split("#")[0].split())


def _data(hex_text: str) -> bytes:
    """The program bytes of an Intel HEX file, in address order."""
    from simbus import read_intel_hex

    records = sorted(read_intel_hex(hex_text))
    end = max(a + len(d) for a, d in records)
    image = bytearray(b"\xff" * end)
    for address, data in records:
        image[address:address + len(data)] = data
    return bytes(image)


def test_every_runnable_block_is_tagged(walked):
    """A command block without the `sh` tag would never be run: every fence on the pages names its language."""
    for page, text in [("README.md", README)] + [(p, (walked.cwd / p).read_text(encoding="utf-8"))
                                                 for p in ("checklist.md", "readout/README.md", "firmware/README.md")]:
        untagged = [b for b in blocks(text, page, every=True) if not b.lang]
        assert not untagged, f"untagged code blocks (tag them sh, python, text...): {untagged}"


def test_a_recording_is_not_calibrated_against_itself(walked):
    """`magfab calibrate scan.csv` without the reference's log: one line naming the sensor's own force columns,
    exit 2, the build untouched."""
    build = walked.cwd
    before = (build / "manifest.json").read_bytes()
    ran = walked.paste("magfab calibrate scan.csv")
    walked.ran.pop()
    assert ran.returncode == 2 and "Traceback" not in ran.stderr
    assert ran.stderr.count("\n") == 1 and "Fz_sensor_N" in ran.stderr and "--reference" in ran.stderr
    assert (build / "manifest.json").read_bytes() == before
