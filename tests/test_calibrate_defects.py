"""The measured defects of the sensor-records work, each a test that failed on the main before the fix (run this file
with PYTHONPATH at that main to see them fail): another sensor's scan calibrated a build; calibrating from the build's
own simulated scan removed it; a rebuild silently replaced a measured calibration."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from calibrate_support import add, tree

from magfab.formats.scan_csv import read_scan_csv, scan_csv
from magfab.pipeline import _scan

# ---- B1: a scan whose rest field is outside the design's band ------------------------------------------------------

def test_another_designs_scan_is_refused_and_nothing_is_written(bench, n52):
    """Measured: another sensor's scan calibrated this build, exit 0. Now exit 2, one line, the build untouched."""
    project, out, calls, run = bench
    (project / "other.csv").write_text(scan_csv(n52))
    before = tree(out)
    result = run("calibrate", "other.csv", "--out", str(out))
    assert result.exit_code == 2, result.output
    line = result.output.strip()
    assert "\n" not in line and "acceptance band" in line and "the wrong sensor, the wrong build, or a misassembled" \
        in line and "stronger than" in line
    assert calls == [] and tree(out) == before


def test_this_builds_own_scans_pass(bench):
    """The build's simulated scan and a recording's shape (rest first, then presses) pass the guard."""
    _project, out, _calls, run = bench
    result = run("calibrate", str(out / "calibration" / "scan_simulated.csv"), "--out", str(out))
    assert result.exit_code == 0, result.output
    assert "calibration (provisional, simulated scan)" in result.output  # the session build is the plan here


# ---- B4: the build's own simulated scan, calibrated on, stays ------------------------------------------------------

def test_a_measured_scan_still_ships_the_simulated_scan(magone_design, magone_prediction, default_build):
    """Measured: `magfab calibrate calibration/scan_simulated.csv` removed the file (the build wrote it only when
    no scan was given). The stage now ships it, the same bytes, whatever the scan."""
    simulated = (default_build.out_dir / "calibration" / "scan_simulated.csv").read_bytes()
    given = replace(read_scan_csv(simulated), source="scan_simulated.csv")
    stage = _scan(magone_design, magone_prediction, given, lambda _stage: None)
    shipped = {a.path: a.data for a in stage.artifacts}
    assert shipped["calibration/scan_simulated.csv"] == simulated
    assert stage.scan is given


# ---- B5: a rebuild over a measured calibration -------------------------------------------------------------------

def _measured(out: Path) -> None:
    """The build folder as `magfab calibrate scan.csv --reference reference.csv` leaves it (its calibration
    fitted to a measured scan)."""
    path = out / "calibration" / "calibration.json"
    cal = json.loads(path.read_text())
    cal["scan"]["source"] = "scan.csv + reference.csv"
    path.write_text(json.dumps(cal, indent=2, sort_keys=True) + "\n")


def test_a_rebuild_refuses_to_discard_a_measured_calibration(bench):
    """Measured: `magfab build` after a measured calibration replaced it with the simulated fit, silently. Now it
    refuses (exit 2, one line, nothing written) until a record keeps it or --discard-calibration is given."""
    project, out, calls, run = bench
    _measured(out)
    before = tree(out)
    result = run("build", "--out", str(out))
    assert result.exit_code == 2, result.output
    line = result.output.strip()
    assert "\n" not in line and "measured calibration (calibration/calibration.json)" in line
    assert "magfab sensor add ID --build" in line and "--discard-calibration" in line
    assert calls == [] and tree(out) == before
    sensor = add(project, out, "finger-01")  # kept: a calibration event holding it, as sensor add would
    sensor.append("calibration", {"calibration_sha256": "0" * 64},
                  {"calibration.json": (out / "calibration" / "calibration.json").read_bytes()})
    assert run("build", "--out", str(out)).exit_code == 0 and len(calls) == 1


def test_discard_calibration_rebuilds_anyway(bench):
    _project, out, calls, run = bench
    _measured(out)
    result = run("build", "--out", str(out), "--discard-calibration")
    assert result.exit_code == 0, result.output
    assert len(calls) == 1


