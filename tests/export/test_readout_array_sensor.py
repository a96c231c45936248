"""``magfab-readout`` with the sensor record of an array board, on both array examples' packages
(strip_1x5: five separate tips, fingertip_2x2: one skin): ``upload --sensor ID`` writes the array's record carrying
the set hash of the sensor's taxel calibrations and the identity block, ``info`` and ``stream`` read every taxel with
the sensor's calibration of it, ``check --sensor ID`` puts the weight on each taxel in turn and appends one check
event per taxel with the crosstalk it measured on the others; the guards refuse with exit status 2, one line, and
nothing written to the board or the record. The check's judgement over the space of faults (a taxel softer than
the recipe, a neighbour coupled to it) runs in process on the simulated array, every taxel pressed in turn."""

from __future__ import annotations

import argparse
import hashlib
import importlib
import io
import json
from pathlib import Path

import pytest
from readout_support import assert_refused, imported
from readout_support import board_bytes as _board
from readout_support import readout_command as readout
from readout_support import snapshot as _snapshot

from magfab.formats import sensor_records as rec
from magfab.formats.calibration_json import calibration_sha256

EXAMPLES = ("strip_1x5", "fingertip_2x2")
FAST = ("--samples", "30", "--settle", "0.05", "--yes")
STEPS = ["polarity (sign of Bz)", "Bz at rest", "|Bxy| at rest", "rise of Bz under 50 g", "crosstalk on the others"]


def _package(build) -> Path:
    return build.out_dir / "readout" / "src" / "magfab_readout"


def _taxel_calibrations(build) -> list[dict]:
    layout = json.loads((_package(build) / "array.json").read_text())
    return [json.loads((_package(build) / t["calibration"]).read_text()) for t in layout["taxels"]]


def _calibrate(sensor: rec.Sensor, spec: str, cals, skip=()) -> None:
    """One calibration event per taxel (dated a day apart), each the package's with another tare."""
    for k, cal in enumerate(cals):
        if k not in skip:
            sensor.append("calibration", {"taxel": k, "spec_sha256": spec},
                          {"calibration.json": json.dumps(cal).encode()}, date=f"2026-11-{10 + k}T09:00:00Z")


@pytest.fixture(params=EXAMPLES)
def bench(request, array_builds, tmp_path):
    build = array_builds[request.param]
    spec = json.loads((_package(build) / "build.json").read_text())["spec_sha256"]
    cals = _taxel_calibrations(build)
    for cal in cals:
        cal["tare_N"]["Fz_N"] += 0.002
    root = tmp_path / "lab" / "sensors"
    sensor = rec.create(root, "arr-01", {"spec_sha256": spec, "taxels": len(cals)}, {})
    _calibrate(sensor, spec, cals)
    cwd = tmp_path / "bench"
    cwd.mkdir()
    return {"build": build, "root": root, "sensor": sensor, "cals": cals, "spec": spec, "n": len(cals),
            "eeprom": tmp_path / "board.eeprom", "cwd": cwd}


def _set_sha(cals) -> str:
    """docs/bundle.md section 4: SHA-256 of the taxel calibrations' SHA-256s in taxel order, joined by commas."""
    return hashlib.sha256(",".join(calibration_sha256(c) for c in cals).encode("ascii")).hexdigest()


def test_upload_info_stream_check_round_trip(bench):
    root, sensor, n = bench["root"], bench["sensor"], bench["n"]
    set16, newest = _set_sha(bench["cals"])[:16], f"2026-11-{9 + n}T09:00:00Z"
    proc = readout(bench, "info", "--sensors", root)
    assert proc.returncode == 0 and "sensor:  no sensor ID on this board" in proc.stdout, proc.stderr

    proc = readout(bench, "upload", "--sensor", "arr-01", "--sensors", root)
    assert proc.returncode == 0, proc.stderr
    assert f"carries sensor arr-01's ID, taxel calibrations {set16} (the newest of {newest})" in proc.stdout
    upload = sensor.events()[-1]
    assert upload["kind"] == "upload" and upload["taxel"] is None
    assert upload["calibration_sha256"] == _set_sha(bench["cals"])
    assert upload["taxel_calibrations"] == [calibration_sha256(c) for c in bench["cals"]]
    assert _board(bench)[8:24] == set16.encode()  # the array record's hash field: the set the board carries

    proc = readout(bench, "info", "--sensors", root)
    assert proc.returncode == 0, proc.stderr
    assert f"sensor:  arr-01, calibration of {newest} ({set16})" in proc.stdout
    assert "calibration: match (sensor arr-01's current taxel calibrations" in proc.stdout
    lines = [line for line in proc.stdout.splitlines() if line.startswith("  taxel ")]
    for k, (line, cal) in enumerate(zip(lines, bench["cals"])):
        assert line.endswith(f"calibration of 2026-11-{10 + k}T09:00:00Z {calibration_sha256(cal)[:16]}"), line

    proc = readout(bench, "stream", "--count", "3", "--sensors", root)
    assert proc.returncode == 0 and f"sensor arr-01's taxel calibrations {set16}" in proc.stdout, proc.stderr

    proc = readout(bench, "check", "--sensor", "arr-01", "--sensors", root, *FAST)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"verdict: PASS (all {n} taxels, {5 * n} steps)" in proc.stdout
    assert [p for p in proc.stderr.splitlines() if p.startswith("place the 50 g weight on taxel")] == [
        p for p in proc.stderr.splitlines() if "weight" in p and p.startswith("place")]
    checks = [e for e in sensor.events() if e["kind"] == "check"]
    assert [c["taxel"] for c in checks] == list(range(n))
    for k, c in enumerate(checks):
        assert c["verdict"] == "pass" and c["simulated"] is True
        assert c["calibration_sha256"] == calibration_sha256(bench["cals"][k])
        assert [s["name"] for s in c["steps"]] == STEPS
        others = {f"crosstalk_taxel_{i:02d}_mN" for i in range(n) if i != k}
        assert others <= set(c["figures"]) and f"crosstalk_taxel_{k:02d}_mN" not in c["figures"]
        assert c["figures"]["crosstalk_max_mN"] == max(c["figures"][f] for f in others)
        assert c["figures"]["Bz_rise_uT"] > 0 and c["figures"]["Bz_rest_uT"] > 0


def _uncalibrated_taxel(bench):
    other = rec.create(bench["root"], "arr-02", {"spec_sha256": bench["spec"]}, {})
    _calibrate(other, bench["spec"], bench["cals"], skip=(bench["n"] - 1,))
    return "arr-02", f"has no calibration for taxel {bench['n'] - 1} yet"


def _other_design(bench):
    bench["sensor"].append("calibration", {"taxel": 1, "spec_sha256": "ab" * 32},
                           {"calibration.json": json.dumps(bench["cals"][1]).encode()})
    return "arr-01", "was fitted to another design"


def _another_sensor_on_the_board(bench):
    other = rec.create(bench["root"], "arr-02", {"spec_sha256": bench["spec"]}, {})
    _calibrate(other, bench["spec"], _taxel_calibrations(bench["build"]))
    assert readout(bench, "upload", "--sensor", "arr-02", "--sensors", bench["root"]).returncode == 0
    return "arr-01", "reports sensor arr-02, not arr-01"


GUARDS = {
    "a taxel without a calibration": _uncalibrated_taxel,
    "another design": _other_design,
    "the board names another sensor": _another_sensor_on_the_board,
    "an unknown sensor": lambda bench: ("arr-09", "has no record in"),
}


@pytest.mark.parametrize("case", list(GUARDS))
def test_upload_guards_exit_2_with_one_line_and_write_nothing(bench, case):
    sid, message = GUARDS[case](bench)
    assert_refused(bench, message, "upload", "--sensor", sid, "--sensors", bench["root"])
    if case == "the board names another sensor":  # check too: refused before a reading, nothing appended
        assert_refused(bench, message, "check", "--sensor", sid, "--sensors", bench["root"], *FAST)
        proc = readout(bench, "upload", "--sensor", sid, "--sensors", bench["root"], "--force")
        assert proc.returncode == 0 and bench["sensor"].events()[-1]["replaced_sensor"] == "arr-02", proc.stderr


def test_a_plain_upload_onto_a_sensors_board_is_refused_without_force(bench, tmp_path):
    """The board carries arr-01's calibrations: the package's record would make the host read it with the package's
    provisional ones. Refused (exit 2, one line, nothing written) until --force; so is a calibration file."""
    assert readout(bench, "upload", "--sensor", "arr-01", "--sensors", bench["root"]).returncode == 0
    board, record = _board(bench), _snapshot(bench["root"])
    proc = readout(bench, "upload")
    assert proc.returncode == 2
    assert proc.stderr == "magfab-readout: error: this board is sensor arr-01: upload --sensor arr-01, or --force\n"
    path = tmp_path / "taxel.json"
    path.write_text(json.dumps(bench["cals"][0]))
    proc = readout(bench, "upload", path)
    assert proc.returncode == 2 and "an array's board holds no calibration" in proc.stderr
    assert _board(bench) == board and _snapshot(bench["root"]) == record
    proc = readout(bench, "upload", "--force")
    assert proc.returncode == 0, proc.stderr
    package = calibration_sha256(_taxel_calibrations(bench["build"])[0])[:16]
    assert _board(bench)[8:24] == package.encode()


# ---- the check's judgement, in process, over the faults ---------------------------------------------------------


@pytest.fixture(params=EXAMPLES, scope="module")
def pkg(request, array_builds, tmp_path_factory):
    """The example's package imported here, and its crosstalk budget."""
    folder = array_builds[request.param].out_dir
    rendered = {str(p.relative_to(folder)): p.read_bytes() for p in (folder / "readout").rglob("*") if p.is_file()}
    with imported(rendered, tmp_path_factory.mktemp(request.param)) as module:
        yield module


def _check(pkg, **faults):
    """``check --simulate`` in process on a simulated array (not paced in real time) whose rest tip has ``faults``
    (ArrayRestTip's softness, coupling): (exit status, output)."""
    array = pkg.ArrayCalibration.embedded()
    array_check = importlib.import_module("magfab_readout.array_check")
    cli = importlib.import_module("magfab_readout.cli")
    crosstalk = array_check.load_crosstalk()
    rest_tip = importlib.import_module("magfab_readout.array_sim").ArrayRestTip
    pattern = rest_tip.from_acceptance(array, importlib.import_module("magfab_readout.check").load_acceptance(),
                                       crosstalk, faults.get("softness"))
    if "extra_coupling" in faults:  # on top of the skin's own (crosstalk.json)
        pattern.coupling = [[c + e for c, e in zip(row, more)] for row, more in zip(pattern.coupling,
                                                                                     faults["extra_coupling"])]

    def open_device(args, text, _pattern):
        sim = pkg.SimulatedArray(array, realtime=False, chunk=8, pattern=pattern)
        return pkg.Device(transport=sim)
    args: argparse.Namespace = cli._parser().parse_args(["check", "--simulate", *FAST])
    out = io.StringIO()
    return array_check.run(args, array, out, open_device), out.getvalue()


def _failed(output: str) -> dict:
    """{taxel: [step names that failed]} from the check's lines."""
    failed: dict = {}
    for line in output.splitlines():
        if line.startswith("taxel ") and "  FAIL  " in line:
            k = int(line.split()[1])
            failed.setdefault(k, []).append(line.split("  FAIL  ")[0].split("  ", 2)[-1].strip())
    return failed


def test_every_taxel_of_a_nominal_array_passes(pkg):
    code, out = _check(pkg)
    assert code == 0 and _failed(out) == {}, out


def test_a_soft_taxel_fails_its_rise_alone(pkg):
    """Each taxel in turn three times softer than the recipe (its rise beyond the band): that taxel's rise fails and
    no other step; through the 2x2's continuous skin its larger travel drags its neighbours further, still within
    the budget's linear coupling bound (the skin stiffens: a neighbour moved by a fiftieth of the travel reads far
    less than a fiftieth of the load)."""
    n = pkg.ArrayCalibration.embedded().taxels
    for k in range(n):
        code, out = _check(pkg, softness=[3.0 if i == k else 1.0 for i in range(n)])
        assert code == 3 and _failed(out) == {k: ["rise of Bz under 50 g"]}, out


def test_a_neighbour_coupled_through_the_skin_fails_the_crosstalk(pkg):
    """Taxel k's neighbour k+1 dragged along by a tenth of k's travel (a skin glued across the lips): the crosstalk
    step of k fails naming k+1, and taxel k+1's own steps pass."""
    n = pkg.ArrayCalibration.embedded().taxels
    for k in range(n - 1):
        coupling = [[0.0] * n for _ in range(n)]
        coupling[k + 1][k] = 0.1
        code, out = _check(pkg, extra_coupling=coupling)
        assert code == 3 and _failed(out) == {k: ["crosstalk on the others"]}, out
        assert f"taxel(s) {k + 1} read more than the budget" in out
