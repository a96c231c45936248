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
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import _missing, require_tool

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pages import blocks, install_command
from rig import Rig, build_library
from simbus import HarnessUnavailable
from walk import Bench, Skin

from magfab.units import G0

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

        bench = Bench(cwd=lab, venv=venv, plug_in=plug_in, home=lab)
        skip = install_command(README)
        for block in blocks(README, "README.md"):
            weights = any(c.startswith("magfab-readout weigh") for c in block.commands)
            if weights:  # a new sensor on its own board, not the nominal one: finger-01's board off the bench
                board, bench.skin = bench.swap(None), Skin(bench.cwd)
                bench.weighed = {"skin": bench.skin, "first": len(bench.ran)}
            for line in block.commands:
                if line == skip:
                    continue
                ran = bench.paste(line) if block.lang == "sh" else bench.python(block.text)
                _assert_ok(ran, block)
                if block.lang == "python":
                    break
            if weights:
                bench.skin = None
                bench.weighed["rig"] = bench.swap(board)
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
    """Add the sensor's record, flash (avrdude over the bootloader), install, upload the provisional calibration,
    stream, record during the scan, calibrate into the sensor's record against the reference log, upload it with the
    sensor's ID, and the acceptance test passes on the board and is kept in the record."""
    build = walked.cwd
    assert build.name == "finger" and (build / "manifest.json").is_file() and not (build / "build").exists()
    flashed = _data(walked.rig.flashed.read_text())  # what avrdude wrote, in whole pages
    image = _data((build / "firmware" / "magfab-atmega328p.hex").read_text())
    assert flashed[:len(image)] == image and set(flashed[len(image):]) <= {0xFF}
    infos = [r.stdout for r in walked.ran if r.line.startswith("magfab-readout info")]
    assert len(infos) == 2 and all("calibration: match" in i for i in infos), infos
    assert "no sensor ID on this board" in infos[0] and "sensor:  finger-01, calibration of " in infos[1], infos
    check = _ran(walked, "magfab-readout check")
    assert "FAIL" not in check.stdout and check.stdout.count("PASS") >= 6, check.stdout
    passed = [line.split()[2] for line in check.stdout.splitlines() if line.startswith("step ") and "PASS" in line]
    assert {"turned", "warm-up"} <= set(passed), check.stdout  # the board turned over and warmed at the prompts
    print("\n".join(line for line in check.stdout.splitlines() if line.startswith("step ")))  # with -s
    built = json.loads((build / "calibration" / "calibration.json").read_text())
    assert built["scan"]["source"] == "simulated"  # the build keeps its provisional calibration
    sensor = _record(walked, "finger-01")
    kinds = [e["kind"] for e in sensor.events()]
    assert kinds == ["added", "calibration", "upload", "check", "reskin"], kinds
    event = next(e for e in sensor.events() if e["kind"] == "calibration")
    cal = json.loads(sensor.file(event["files"]["calibration.json"]))
    assert cal["scan"]["source"] == event["source"] == "scan.csv + reference.csv" and not event["provisional"]
    fitted = _ran(walked, "magfab calibrate").stdout
    fit = next(line for line in fitted.splitlines() if line.startswith("calibrated sensor"))
    print(fit)  # with -s
    # The bench's scan is coarse (every 5th point, 30 ms apart, the stage's field held for 2 ms slices), so the fit
    # misses the build's simulated one (about 5 mN) by a few mN; a recording misaligned with its reference (a board
    # clock the log was not stamped on) gives hundreds.
    assert float(fit.split("held-out RMS Fz ")[1].split()[0]) < 50, fit
    merged = sensor.file(event["files"]["scan_merged.csv"])  # what was fitted, by its hash
    from magfab.formats.scan_csv import read_scan_csv

    assert read_scan_csv(merged).rows == cal["scan"]["rows"]
    data = b"".join(line for line in merged.splitlines(keepends=True) if not line.startswith(b"#"))
    assert hashlib.sha256(data).hexdigest() == cal["scan"]["sha256"]  # the file without its comment
    assert _ran(walked, "magfab-readout record").returncode == 0  # Ctrl-C ends a recording as a success
    uploads = [r for r in walked.ran if r.line.startswith("magfab-readout upload")]
    assert [u.line.split("#")[0].split()[2:] for u in uploads] == [
        [], ["--sensor", "finger-01"], [], ["--sensor", "finger-03"], ["--sensor", "finger-03"]]
    assert uploads[1].stdout != uploads[0].stdout
    # The board names finger-01 and runs its calibration; the new skin changes the record, not the board.
    assert _board_says(walked.rig) == ("finger-01", event["calibration_sha256"][:16], event["calibration_sha256"][:16])
    with open(build / "scan.csv", newline="") as f:
        header = next(csv.reader(line for line in f if not line.startswith("#")))
    assert "Fz_sensor_N" in header and "Fz_N" not in header  # the recording keeps the sensor's own forces apart
    assert (walked.cwd / "finger-01.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"  # sensor show's chart


def test_the_live_view_of_the_board(walked):
    """The README's `magfab-readout view`, on the rig (the shipped image on the simulated board and bus): the page
    the walk opened drew the frames and its latency reached the summary, with the rate the board delivered."""
    view = _ran(walked, "magfab-readout view")
    m = re.search(r"view: (\d+) samples.*?; ([\d.]+) samples/s .*?the page drew (\d+) updates.*?from read to drawn "
                  r"median ([\d.]+) ms, p95 ([\d.]+) ms", view.stderr)
    assert m, view.stderr
    samples, rate, drawn, median, p95 = map(float, m.groups())
    assert samples > 100 and rate > 0 and drawn > 10 and 0 < median <= p95 < 2000, view.stderr
    print(view.stderr.strip().splitlines()[-1])  # with -s


def test_a_sensor_calibrated_with_weights_passes_its_check(walked):
    """The README's weights path on its own board, whose chip reads a sensor drawn across the bands (not the nominal
    one: another hyperelastic law, its magnet tilted and offset, the Earth's field turning with the stand): the first
    two weighings, the plan they give for its skin, its weighings, the model's calibration into the record, its
    upload, and the acceptance check passes. The calibration
    reads the drawn sensor's flat loads within twice the error it states; the re-skin's three weighings keep the
    magnet's parameters."""
    from magfab.models.weighing import RESKIN_KEPT
    from magfab.readout.src.magfab_readout.calibration import Calibration

    weighed = walked.weighed
    ran = walked.ran[weighed["first"]:]
    weighs = [r for r in ran if r.line.startswith("magfab-readout weigh")]
    planned = json.loads((walked.cwd / "plan.json").read_text())  # the plan weigh-plan made for the drawn skin
    steps = len(planned["steps"])
    assert [r.stdout.count("step ") for r in weighs] == [2, steps, 3], [r.stdout for r in weighs]
    assert planned["stiffness"] >= 1.0 and planned["adapted"]["weighings"] == "first.csv"
    check = next(r for r in ran if r.line.startswith("magfab-readout check"))
    assert "FAIL" not in check.stdout and "verdict: PASS" in check.stdout, check.stdout
    print("\n".join(line for line in check.stdout.splitlines() if line.startswith("step ")))  # with -s
    sensor = _record(walked, "finger-03")
    fits = [e for e in sensor.events() if e["kind"] == "calibration"]
    first, skin = (json.loads(sensor.file(e["files"]["calibration.json"])) for e in fits)
    model = first["scan"]["model"]
    assert model["weighings"] == steps and skin["scan"]["model"]["kept"] == sorted(RESKIN_KEPT)
    # the first calibration against the drawn sensor it was made on (the skin before its re-skin): flat loads
    truth = weighed["skin"].first
    cal = Calibration(first)
    grams = np.linspace(20.0, 250.0, 12)
    fz = np.array([cal.evaluate(*truth.reading(m, 0.0))[2] for m in grams])
    rms_mN = 1000 * float(np.sqrt(np.mean((fz - grams * 1e-3 * G0) ** 2)))
    stated = model["predicted_error_mN"]["Fz_rms"]["p90"]
    print(f"weights calibration on the drawn sensor: flat loads 20-250 g, Fz RMS {rms_mN:.1f} mN, stated {stated} mN")
    assert rms_mN <= 2.0 * stated, (rms_mN, stated)
    assert _board_says(weighed["rig"])[0] == "finger-03"


def _record(bench, sensor_id: str):
    """The record of ``sensor_id`` in the walk's sensors/ (beside the spec, where the README adds it)."""
    from magfab.formats import sensor_records

    return sensor_records.open_sensor(bench.home / "sensors", sensor_id)


def _board_says(rig) -> tuple:
    """What the board's EEPROM holds: (the sensor ID its identity block names, the calibration hash that block names,
    the hash of the calibration record the image runs), each None when it holds none."""
    from magfab.export.firmware import _eeprom_module
    from magfab.readout.src.magfab_readout import identity

    data = rig.eeprom(1024)
    found = identity.unpack(data[identity.ADDRESS:])
    running = _eeprom_module().unpack_header(data)["sha16"]
    return (None, None, running) if found is None else (found.sensor_id, found.calibration_sha16, running)


def test_the_rest_of_the_pages_run_as_written(walked):
    """The checklist's and the bundle READMEs' commands, each page from its own folder, after the README's walk
    (a line the walk already ran in the same folder is not run twice: the same text, the same state)."""
    for tool in ("avr-gcc", "simavr", "make"):  # the firmware README builds the image and its benchmark
        require_tool(tool)
    build = walked.cwd
    done = {(_command(r.line), r.cwd) for r in walked.ran}
    pages = [("checklist.md", build), ("readout/README.md", build)]
    board = None
    try:
        ran = _paste_pages(walked, build, pages, done)
        # The firmware README is a board's first flash: a new board, which names no sensor yet (finger-01's, flashed
        # again, would keep its calibration and ID, and a plain upload over them is refused).
        board = walked.swap(walked.plug_in(build))
        ran += _paste_pages(walked, build, [("firmware/README.md", build / "firmware")], done)
    finally:
        walked.cwd = build
        if board is not None:
            walked.swap(board)
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
# Two sensors of one design. The README's walk made and calibrated finger-01 on the first board and gave it a new
# skin; the same README lines then run for finger-02 on a second board (the ID is the only text changed), the design
# is rebuilt, finger-02 is calibrated again, and finger-01's board comes back for its new skin's calibration.

def _readme_lines(first: str, last: str) -> list[str]:
    """The README's commands from the block holding a line that starts with ``first`` to the one with ``last``."""
    found = [b for b in blocks(README, "README.md") if b.lang == "sh"]
    start = next(i for i, b in enumerate(found) if any(c.startswith(first) for c in b.commands))
    end = next(i for i, b in enumerate(found) if any(c.startswith(last) for c in b.commands))
    return [c for b in found[start:end + 1] for c in b.commands]


def _paste(bench, lines, swap: tuple[str, str] = ("finger-01", "finger-01")) -> None:
    """Paste ``lines`` with the sensor ID ``swap[0]`` changed to ``swap[1]``. ``pip install ./readout`` is not run
    again: the reader it installs, this build's, is installed already (the same text in the same folder, as
    _paste_pages leaves out)."""
    for line in lines:
        if line.startswith("pip install ./readout"):
            continue
        ran = bench.paste(line.replace(*swap))
        _assert_ok(ran, "README.md")


def _tree(folder: Path) -> dict:
    """{relative path: sha256} of every file under ``folder``."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def two_sensors(walked, tmp_path_factory):
    """The bench after the two-sensor lifecycle (the ran lines before it: the README walk's), with the records'
    folder and the build's readout just before and just after the rebuild, and both boards."""
    bench, home, build = walked, walked.home, walked.cwd
    first = len(bench.ran)
    for_one = _readme_lines("magfab sensor add finger-01", "magfab sensor show")  # one sensor's bench lines
    scan_again = _readme_lines("magfab-readout record", "magfab-readout record")[:4]  # record, calibrate, upload, info
    listing = next(c for c in _readme_lines("magfab sensor list", "magfab sensor list")
                   if c.startswith("magfab sensor list"))
    rebuild = next(c for c in _readme_lines("magfab init finger.toml", "magfab init finger.toml")
                   if c.startswith("magfab build finger.toml"))
    plug_in = bench.plug_in
    with contextlib.ExitStack() as stack:
        board_1 = bench.swap(None)  # finger-01's board off the bench
        bench.plug_in = lambda d: stack.enter_context(Rig(d, board_1.lib, tmp_path_factory.mktemp("board-2")))
        try:
            bench.cwd = home
            _paste(bench, for_one, ("finger-01", "finger-02"))  # the same lines with finger-02's ID, on the new board
            board_2 = bench.rig
            bench.cwd = home
            before = _tree(home / "sensors"), _tree(build / "readout")
            _assert_ok(bench.paste(rebuild), "README.md")
            after = _tree(home / "sensors"), _tree(build / "readout")
            bench.cwd = build
            _paste(bench, scan_again, ("finger-01", "finger-02"))  # finger-02 calibrated again, same skin
            bench.swap(board_1)  # finger-01's board back, a new skin on it since the README's walk
            back = _board_says(board_1)  # what it runs: the old skin's, or the file the readout README forced on it
            _paste(bench, [*scan_again, for_one[-1], listing])  # and its history compares the two skins
        finally:
            bench.plug_in = plug_in
            for ran in bench.ran[first:]:  # with -s: what the two-sensor lifecycle adds to the walk
                print(f"{ran.seconds:6.1f} s  {ran.line}")
            print(f"{sum(r.seconds for r in bench.ran[first:]):6.1f} s  in all")
        yield {"boards": {"finger-01": board_1, "finger-02": board_2}, "before": before, "after": after,
               "first": first, "back": back}


def test_two_sensors_of_one_design_keep_every_measurement(walked, two_sensors):
    """Through two sensors' calibrations, uploads and checks, a rebuild of the design, a second calibration and a
    new skin's: every recording, reference log, calibration and check the walk made is in its sensor's record, each
    kept file is the bytes its name promises, and each history holds its events in order."""
    from magfab.formats import sensor_records
    from magfab.readout.src.magfab_readout.calibration_json import calibration_sha256

    for index, path, sha in walked.produced:  # each recording and its reference log, as the walk made them
        calibrate = next(r for r in walked.ran[index:] if r.line.startswith("magfab calibrate"))
        sensor = _record(walked, calibrate.line.split("--sensor ")[1].split()[0])
        kept = [e["files"] for e in sensor.events() if e["kind"] == "calibration"]
        assert any(sha == files.get(path.name) for files in kept), (path.name, calibrate.line, kept)
    histories = {}
    for sensor in sensor_records.list_sensors(walked.home / "sensors"):
        events = sensor.events()
        histories[sensor.id] = [e["kind"] for e in events]
        assert [e["number"] for e in events] == list(range(1, len(events) + 1))
        assert [e["date"] for e in events] == sorted(e["date"] for e in events)
        for event in events:  # every kept file holds the bytes its name promises
            for role, sha in event["files"].items():
                assert hashlib.sha256(sensor.file(sha)).hexdigest() == sha, (sensor.id, role)
        calibrations = [e for e in events if e["kind"] == "calibration"]
        ran = [r for r in walked.ran if r.line.startswith("magfab calibrate") and f"--sensor {sensor.id}" in r.line]
        assert len(calibrations) == len(ran) == 2  # one per calibrate line the walk ran
        for event, line in zip(calibrations, ran):
            cal = json.loads(sensor.file(event["files"]["calibration.json"]))
            assert event["number"] == int(line.stdout.split("events/")[1][:6]) and not event["provisional"]
            assert calibration_sha256(cal) == event["calibration_sha256"]
        checks = [r for r in walked.ran if r.line.startswith("magfab-readout check") and sensor.id in r.line]
        kept = [e for e in events if e["kind"] == "check"]
        assert len(kept) == len(checks) == 1 and kept[0]["verdict"] == "pass"
        assert f"record: check {kept[0]['number']} of sensor {sensor.id}" in checks[0].stdout
    assert histories == {
        "finger-01": ["added", "calibration", "upload", "check", "reskin", "calibration", "upload"],
        "finger-02": ["added", "calibration", "upload", "check", "calibration", "upload"],
        "finger-03": ["added", "calibration", "upload", "check", "reskin", "calibration", "upload"]}, histories


def test_each_board_reports_its_own_sensor(walked, two_sensors):
    """Each board's EEPROM names its own sensor and that sensor's newest calibration, and `info` says so; the ID
    is the only thing the pages changed between the two boards."""
    for sensor_id, rig in two_sensors["boards"].items():
        current, _ = _record(walked, sensor_id).current_calibration()
        assert _board_says(rig) == (sensor_id, *[current["calibration_sha256"][:16]] * 2)
    infos = [r.stdout for r in walked.ran[two_sensors["first"]:] if r.line.startswith("magfab-readout info")]
    said = [next(line for line in i.splitlines() if line.startswith("sensor:")) for i in infos]
    assert [s.split()[1].rstrip(",") for s in said] == ["no", "finger-02", "finger-02", "finger-01"], said
    assert all("calibration: match" in i for i in infos)


def test_a_rebuild_leaves_the_records_and_a_new_skin_is_compared(walked, two_sensors):
    """`magfab build finger.toml` over a build whose sensors were calibrated into their records: it succeeds, every
    record is as it was, and the build's readout (the installed reader's) is the same; `record` reads the re-skinned
    board, which runs the old skin's calibration or (after the readout README's forced upload) the package's, and
    says which; `sensor show` compares the
    new skin's calibration with the old one's; `sensor list` names both sensors."""
    rebuilt = [r for r in walked.ran if r.line.startswith("magfab build finger.toml")][-1]
    assert rebuilt.returncode == 0 and "discard" not in rebuilt.stderr
    assert two_sensors["after"] == two_sensors["before"]
    recorded = [r for r in walked.ran[two_sensors["first"]:]
                if r.line.startswith("magfab-readout record") and r.cwd.name == "finger"][-1]  # finger-01's new skin
    named, running = two_sensors["back"][1:]
    if named == running:  # the README's walk left it so: the old skin's calibration, which the record keeps
        assert "(skin 0), not one of the skin in use (skin 1)" in recorded.stderr, recorded.stderr
    else:  # the readout README's `upload calibration/calibration.json --force` ran on it since (its page's test)
        assert f"but runs calibration {running}" in recorded.stderr.lower(), recorded.stderr
    show = [r for r in walked.ran if r.line.startswith("magfab sensor show finger-01")][-1].stdout
    assert "new skin against the previous one" in show and "rest Bz" in show, show
    listed = [r for r in walked.ran if r.line.startswith("magfab sensor list")][-1].stdout
    rows = {line.split()[0]: line.split() for line in listed.splitlines()[1:]}
    assert set(rows) == {"finger-01", "finger-02", "finger-03"} and rows["finger-01"][2:4] == ["1", "2"], listed


# ---------------------------------------------------------------------------------------------------------------
# The array's pages: the 1x5 strip the README's "Arrays" section built in the same walk, on a board of
# five chips. These run last: the strip's readout replaces the finger's in the walk's environment.

PRESSED, PRESS_N = 2, 0.5  # a press of 0.5 N straight down on the middle taxel while `stream` runs
AT_REST = 20  # cycles at rest the stream must print after the press


def _cycles(stream_out: str, unread: list | None = None) -> list[dict[int, list[float]]]:
    """`stream`'s cycles in the order printed, each {taxel: [Fx, Fy, Fz]}: a cycle's lines are consecutive and share
    its sequence number (the second column; one byte, it wraps every 256 cycles, so it only tells cycles apart).
    ``unread`` collects (cycle index, flags) of each line whose taxel was not read: its frame missing ('M', dropped
    on the line) or its chip's error ('E')."""
    cycles: list[dict[int, list[float]]] = []
    seq = None
    for line in stream_out.splitlines():
        r = line.split()
        if len(r) < 11 or line.startswith("#") or not r[1].isdigit():
            continue
        if r[1] != seq:
            cycles.append({})
            seq = r[1]
        cycles[-1][int(r[2])] = [float(x) for x in r[3:6]]
        if unread is not None and ("M" in r[10] or "E" in r[10] or any(math.isnan(f) for f in cycles[-1][int(r[2])])):
            unread.append((len(cycles) - 1, r[10]))
    return cycles


def _rest_after_press(stream_out: str) -> bool:
    """The stream has printed the press and then AT_REST whole cycles with the pressed taxel back at rest."""
    cycles = _cycles(stream_out)  # parsed once: the walk asks this of the whole output every 0.1 s
    on = [k for k, c in enumerate(cycles) if c.get(PRESSED, [0.0] * 3)[2] > PRESS_N / 2]
    return bool(on) and sum(len(c) == 5 for c in cycles[on[-1] + 2:]) >= AT_REST


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

        bench = Bench(cwd=strip, venv=walked.venv, plug_in=plug_in, press=_press_fields(strip, PRESSED, PRESS_N),
                      after_press=_rest_after_press)
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
    unread: list[tuple[int, str]] = []
    cycles = _cycles(ran.stdout, unread)
    # A frame the port dropped (nobody read it in time on a loaded machine, as a USB serial line drops) reads NaN,
    # flagged 'M'; such cycles are left out, and must be rare.
    dropped = {i for i, _ in unread}
    assert all(f[4] == "M" for _, f in unread) and len(dropped) <= len(cycles) // 20, (unread, ran.stderr)
    whole = [c for i, c in enumerate(cycles) if len(c) == 5 and i not in dropped]
    assert len(whole) >= 100 and len(whole) >= len(cycles) - 2 - len(dropped), ran.stderr  # a cycle cut by Ctrl-C
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
    assert len(at_rest) >= AT_REST  # zeroed before the press and after it
