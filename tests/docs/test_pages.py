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
from pages import blocks, install_command
from rig import Rig, build_library
from simbus import HarnessUnavailable
from walk import Bench

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
        for ran in bench.ran:  # with -s: where the README's walk spends its time
            print(f"{ran.seconds:6.1f} s  {ran.line}")
        yield bench


def _assert_ok(ran, block) -> None:
    interrupted = "Ctrl-C ends it" in ran.line
    ok = ran.returncode == 0 or (interrupted and ran.returncode == 130)
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
    assert "FAIL" not in check.stdout and check.stdout.count("PASS") >= 6, check.stdout
    passed = [line.split()[2] for line in check.stdout.splitlines() if line.startswith("step ") and "PASS" in line]
    assert {"turned", "warm-up"} <= set(passed), check.stdout  # the board turned over and warmed at the prompts
    print("\n".join(line for line in check.stdout.splitlines() if line.startswith("step ")))  # with -s
    cal = json.loads((build / "calibration" / "calibration.json").read_text())
    assert cal["scan"]["source"] == "scan.csv + reference.csv" and \
        (build / "calibration" / "scan_simulated.csv").exists()  # kept: it may be a calibration's input
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
                port = walked.rig.port if walked.rig is not None else "/dev/ttyACM0"
                if (_command(line.replace("/dev/ttyACM0", port)), walked.cwd) in done:
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


# ---------------------------------------------------------------------------------------------------------------
# The array's pages: the 1x5 strip the README's "Arrays" section built in the same walk, on a board of
# five chips. These run last: the strip's readout replaces the finger's in the walk's environment.

PRESSED, PRESS_N = 2, 0.5  # a press of 0.5 N straight down on the middle taxel while `stream` runs


def _press_fields(build: Path, taxel: int, force_N: float) -> list:
    """Every chip's field (uT, taxel order) with magnet ``taxel`` pressed by ``force_N`` on its axis: its travel from
    the build's predicted nominal curve (predictions.json), the fields from magfab's exact model of every magnet."""
    import numpy as np

    from magfab.design import derive
    from magfab.models import taxels
    from magfab.spec import load_build_spec

    normal = json.loads((build / "predictions.json").read_text())["normal"]
    force = [f for _, f in normal["curve"]["nominal"]]
    travel = float(np.interp(force_N, force, normal["magnet_displacement_mm"]))
    design = derive(load_build_spec(build))
    centres = taxels._magnet_centres(design).copy()
    centres[taxel] += (0.0, 0.0, -travel)  # towards its chip
    return taxels.field_at_chips(design, centres).sum(axis=1).tolist()


@pytest.fixture(scope="module")
def strip_walked(walked, tmp_path_factory):
    """The strip's readout/README.md and checklist.md pasted from its build folder (the README walk's build/strip),
    on a new board with the strip's five chips at their addresses, in the walk's environment; a press on taxel 2
    while `stream` runs. The bench, after the pages."""
    strip = walked.cwd.parent / "strip"
    assert (strip / "calibration" / "array.json").is_file(), "the README's Arrays section builds build/strip"
    with contextlib.ExitStack() as stack:

        def plug_in(build_dir: Path) -> Rig:
            lib = build_library(build_dir, tmp_path_factory.mktemp("strip-harness"))
            return stack.enter_context(Rig(build_dir, lib, tmp_path_factory.mktemp("strip-board")))

        bench = Bench(cwd=strip, venv=walked.venv, plug_in=plug_in, press=_press_fields(strip, PRESSED, PRESS_N))
        _paste_pages(bench, strip, [("readout/README.md", strip), ("checklist.md", strip)], set())
        bench.cwd = strip
        for ran in bench.ran:  # with -s: where the array's pages spend their time
            print(f"{ran.seconds:6.1f} s  {ran.line}")
        yield bench


def test_the_array_pages_run_as_written(strip_walked):
    """Flash, install, upload (the version-3 record: every chip's address), info (every taxel), stream, record
    (the taxel column), calibrate --taxel 0 and upload again, as the strip's pages write them."""
    bench, build = strip_walked, strip_walked.cwd
    assert len(bench.ran) >= 9 and bench.rig.resets == 0
    flashed = _data(bench.rig.flashed.read_text())
    image = _data((build / "firmware" / "magfab-atmega328p.hex").read_text())
    assert flashed[:len(image)] == image
    taxels = json.loads((build / "design.json").read_text())["array"]["taxels"]
    addresses = [t["i2c_address"] for t in taxels]
    assert len(addresses) == 5 and bench.rig.addresses == addresses
    from magfab.export.firmware import _eeprom_module

    ee = _eeprom_module()
    record = bench.rig.eeprom(1024)
    assert ee.unpack_header(record)["version"] == ee.VERSION_ARRAY == 3 and ee.addresses(record) == addresses
    upload = _ran(bench, "magfab-readout upload").stdout
    assert "read back equal; the board reads 5 chips" in upload, upload
    info = _ran(bench, "magfab-readout info").stdout
    listed = [line for line in info.splitlines() if line.lstrip().startswith("taxel ")]
    assert [int(line.split("address 0x")[1][:2], 16) for line in listed] == addresses, info
    assert info.rstrip().endswith("calibration: match")
    with open(build / "scan.csv", newline="") as f:
        reader = csv.DictReader(line for line in f if not line.startswith("#"))
        rows = list(reader)
    assert reader.fieldnames[:3] == ["time_s", "host_time_s", "taxel"] and "Fz_sensor_N" in reader.fieldnames
    assert {int(r["taxel"]) for r in rows} == set(range(5))  # every chip's reading recorded
    cal = json.loads((build / "calibration" / "taxel_00.json").read_text())
    assert cal["scan"]["source"] == "scan.csv + reference.csv" and \
        (build / "calibration" / "scan_taxel_00.csv").is_file()
    assert "--taxel 0" in _ran(bench, "magfab calibrate").line


def test_a_press_on_one_taxel_streams_on_that_taxel_only(strip_walked):
    """`stream --zero 200` prints every taxel of every cycle; pressed by 0.5 N, taxel 2 reads the press (within its
    calibration's held-out error) and its neighbours, whose chips see its magnet move, read less than the
    predicted resolution (the host removes the magnet's field from theirs)."""
    bench, build = strip_walked, strip_walked.cwd
    ran = _ran(bench, "magfab-readout stream --zero 200")
    rows = [line.split() for line in ran.stdout.splitlines() if line.strip() and not line.startswith("#")]
    cycles: dict[int, dict[int, list]] = {}
    for r in rows:
        cycles.setdefault(int(r[1]), {})[int(r[2])] = [float(x) for x in r[3:6]]
    whole = [c for c in cycles.values() if len(c) == 5]
    assert len(whole) >= 100 and len(whole) >= len(cycles) - 2, ran.stderr  # a cycle cut by Ctrl-C at most
    pred = json.loads((build / "predictions.json").read_text())
    resolution = [pred["shear"]["resolution_mN"] / 1e3] * 2 + [pred["normal"]["resolution_mN"] / 1e3]
    cal = json.loads((build / "calibration" / f"taxel_{PRESSED:02d}.json").read_text())
    tolerance = cal["errors"]["Fz_N"]["max_holdout"] + 3 * resolution[2]
    on = [c[PRESSED][2] > PRESS_N / 2 for c in whole]
    # The rig's press is a step between two of the board's chip reads: a cycle on either side of the step can hold
    # chips read before it and chips read after it (a finger's press is continuous), so the edges are left out.
    pressed = [c for i, c in enumerate(whole) if all(on[max(i - 1, 0):i + 2])]
    assert len(pressed) >= 20, [c[PRESSED] for c in whole[::20]]
    for c in pressed:
        assert abs(c[PRESSED][2] - PRESS_N) < tolerance, (c[PRESSED], PRESS_N, tolerance)
        for k in set(range(5)) - {PRESSED}:
            assert all(abs(f) < r for f, r in zip(c[k], resolution)), (k, c[k], resolution)
    at_rest = [c for c in whole if abs(c[PRESSED][2]) < resolution[2]]
    assert len(at_rest) >= 20  # zeroed before the press and after it
