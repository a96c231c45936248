"""``magfab calibrate --sensor ID``: the record gets the calibration event, the build folder is left
byte for byte; a scan belongs to one sensor; a record made from another spec is refused; a wrong scan writes no
record. And the rest-band guard over a space of wrong and right scans (Hypothesis, the grades, the distance)."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pytest
from calibrate_support import add, tree
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from magfab import derive, load_spec
from magfab.errors import ScanError
from magfab.formats.scan_csv import read_scan_csv, scan_csv
from magfab.models import rest_guard as R
from magfab.models.scan import simulate_scan

# ---- A, B2, B3: --sensor ------------------------------------------------------------------------------------------

def test_calibrate_a_sensor_writes_its_record_and_leaves_the_build(bench):
    project, out, calls, run = bench
    sensor = add(project, out, "finger-01")
    shutil.copy(out / "calibration" / "scan_simulated.csv", project / "scan.csv")
    before = tree(out)
    result = run("calibrate", "scan.csv", "--sensor", "finger-01", "--out", str(out), "--date", "2026-11-28")
    assert result.exit_code == 0, result.output
    assert calls == [] and tree(out) == before  # the build keeps its provisional calibration
    assert "next: magfab-readout upload --sensor finger-01" in result.output
    event, cal = sensor.current_calibration()
    assert event["date"] == "2026-11-28T00:00:00Z" and event["provisional"] is False and event["taxel"] is None
    assert event["spec_sha256"] == load_spec(None).sha256() and event["source"] == "scan.csv"
    assert sensor.file(event["files"]["scan.csv"]) == (project / "scan.csv").read_bytes()
    from magfab.formats.calibration_json import calibration_sha256

    assert event["calibration_sha256"] == calibration_sha256(cal)
    assert cal["coefficients"] == json.loads((out / "calibration" / "calibration.json").read_text())["coefficients"]
    # the rest field and the slopes: in the predicted bands (predictions.json, G/N -> uT/N)
    pred = json.loads((out / "predictions.json").read_text())
    bands = json.loads((out / "calibration" / "acceptance.json").read_text())["rest"]["Bz_uT"]
    assert bands["min"] <= event["rest_field_uT"][2] <= bands["max"]
    for key, axis in (("sensitivity_normal_uT_per_N", "normal"), ("sensitivity_shear_uT_per_N", "shear")):
        low, high = pred[axis]["sensitivity_G_per_N"]
        assert 100 * low <= event[key] <= 100 * high, key
    assert event["range_shear_N"] > 0 and event["range_normal_N"] > 0


def test_a_scan_of_another_sensor_is_refused(bench):
    project, out, _calls, run = bench
    add(project, out, "finger-01")
    other = add(project, out, "finger-02")
    shutil.copy(out / "calibration" / "scan_simulated.csv", project / "scan.csv")
    assert run("calibrate", "scan.csv", "--sensor", "finger-01").exit_code == 0
    result = run("calibrate", "scan.csv", "--sensor", "finger-02")
    assert result.exit_code == 2 and "calibrated sensor finger-01 already" in result.output
    assert [e["kind"] for e in other.events()] == ["added"]


def test_a_sensor_of_another_design_is_refused(bench):
    project, out, _calls, run = bench
    sensor = add(project, out, "finger-01", spec_sha256="f" * 64)
    scan = str(out / "calibration" / "scan_simulated.csv")
    result = run("calibrate", scan, "--sensor", "finger-01", "--out", str(out))
    assert result.exit_code == 2 and "was made from another spec" in result.output
    assert "\n" not in result.output.strip() and [e["kind"] for e in sensor.events()] == ["added"]


def test_a_wrong_scan_writes_no_record(bench, n52):
    project, out, _calls, run = bench
    sensor = add(project, out, "finger-01")
    (project / "other.csv").write_text(scan_csv(n52))
    result = run("calibrate", "other.csv", "--sensor", "finger-01")
    assert result.exit_code == 2 and "acceptance band" in result.output
    assert [e["kind"] for e in sensor.events()] == ["added"]


# ---- D: the rest-band guard over the space of scans ---------------------------------------------------------------

@pytest.fixture(scope="module")
def bands(default_build):
    return json.loads((default_build.out_dir / "calibration" / "acceptance.json").read_text())


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(scale=st.floats(0.5, 1.6), shift=st.floats(-3000.0, 3000.0), temperature=st.sampled_from([None, 22.0, 40.0]))
def test_the_rest_guard_refuses_exactly_the_scans_outside_the_band(default_build, bands, scale, shift, temperature):
    """This design's scan, its field scaled (another grade or distance) and shifted (a stray magnet), at a bench
    temperature or a warm one: refused exactly when its rest Bz, brought back to the bench's range, is outside the
    band (a margin of the allowance either side is left to the noise)."""
    scan = read_scan_csv(default_build.out_dir / "calibration" / "scan_simulated.csv")
    b = scan.B_uT * scale + [0.0, 0.0, shift]
    t = None if temperature is None else np.full(scan.rows, temperature)
    moved = replace(scan, B_uT=b, temperature_C=t)
    rest = R.rest_field(moved)
    low, high = R.rest_band(bands, rest, remanence_per_C=-0.0012)
    margin = 0.01 * (high - low)
    bz = float(rest.B_uT[2])
    try:
        R.check_rest_band(moved, bands, remanence_per_C=-0.0012)
        refused = ""
    except ScanError as exc:
        refused = str(exc)
    assert "\n" not in refused
    if low + margin < bz < high - margin:
        assert not refused
    elif bz < low - margin or bz > high + margin:
        assert refused


@pytest.mark.parametrize("grade, inside", [("N35", True), ("N42", True), ("N45", False), ("N52", False)])
def test_the_rest_guard_tells_the_grades_as_acceptance_json_does(magone_design, magone_prediction, bands, grade,
                                                                  inside):
    """Another magnet grade in the same fingertip: passed or refused as acceptance.json's grade table says."""
    spec = magone_design.spec
    design = derive(spec.model_copy(update={"magnet": spec.magnet.model_copy(update={"grade": grade})}))
    scan = simulate_scan(design, magone_prediction)
    assert bands["grades"][grade]["inside_rest_band"] is inside
    if inside:
        R.check_rest_band(scan, bands)
    else:
        with pytest.raises(ScanError, match="stronger than"):
            R.check_rest_band(scan, bands)


@pytest.mark.parametrize("d_mm, inside", [(5.0, False), (6.0, True), (7.0, False)])
def test_the_rest_guard_tells_another_distance(magone_design, magone_prediction, bands, d_mm, inside):
    """The same magnet at another rest distance (another design's stack-up, or a magnet not pushed home)."""
    scan = simulate_scan(replace(magone_design, d_rest_mm=d_mm), magone_prediction)
    if inside:
        R.check_rest_band(scan, bands)
    else:
        with pytest.raises(ScanError, match="acceptance band"):
            R.check_rest_band(scan, bands)
    flipped = simulate_scan(replace(magone_design, d_rest_mm=d_mm), magone_prediction, polarity=-1)
    with pytest.raises(ScanError, match="upside down" if inside else "acceptance band"):
        R.check_rest_band(flipped, bands)
