"""calibration.json: the validator bounds what the formula computes, not only each number: the thermal
denominator over the chip's rated range, the scaled inputs and the polynomial over the valid region, the MLS
model's inputs. The examples of the issue, then generated documents: every refused one in one line naming the
key path, every accepted one finite (and within float32) wherever it is sampled in its region and over the
temperature range. The firmware's record check refusing the same records is tests/export/test_firmware_bounds.py."""

from __future__ import annotations

import copy
import math

import pytest
from calibration_strategies import calibration, region_points
from hypothesis import HealthCheck, event, given, settings
from test_calibration_json import good

from magfab.readout.src.magfab_readout.calibration import Calibration
from magfab.readout.src.magfab_readout.calibration_json import AXES, THERMAL_REFERENCE_C, CalibrationError, validate

SETTINGS = {"deadline": None, "derandomize": True, "suppress_health_check": [HealthCheck.too_slow]}
FLOAT32_MAX = 3.4028234663852886e38
THERMAL_MIN_DENOMINATOR = 0.5  # calibration_json's, as docs/bundle.md section 2 states it (not imported: the test
# shows the defect on code without it)


def _one_line(exc: CalibrationError, key: str) -> None:
    text = str(exc)
    assert "\n" not in text and text.startswith(f"calibration.json: {key} = ") and exc.allowed in text


def test_thermal_denominator_zero_at_room_temperature_is_refused():
    """T0 125 C and a +0.01/C are each within bounds, but 1 + a (T - T0) is 0 at 25 C: the board divided by zero."""
    doc = good()
    doc["thermal"] = {"reference_C": 125.0, "source": "recipe",
                      "coefficient_per_C": {"Bx_uT": 0.01, "By_uT": -0.0012, "Bz_uT": -0.0012}}
    with pytest.raises(CalibrationError) as caught:
        validate(doc)
    _one_line(caught.value, "thermal.coefficient_per_C.Bx_uT")
    assert "falls to -0.65 at -40 degC" in str(caught.value) and "at least 0.5" in str(caught.value)


@pytest.mark.parametrize("path, value", [("scaling.Bz_uT.scale", 1e-300), ("scaling.Br_uT.scale", 1e-300),
                                         ("scaling.Bz_uT.center", 1e308), ("scaling.Br_uT.center", -1e308)])
def test_tiny_scale_or_huge_centre_is_refused(path, value):
    """Evaluation gave -inf + inf (math.fsum's ValueError) for these; now the file is refused naming the input."""
    doc = good()
    _, name, key = path.split(".")
    doc["scaling"][name][key] = value
    with pytest.raises(CalibrationError) as caught:
        validate(doc)
    _one_line(caught.value, f"scaling.{name}")
    assert "into +/-1000" in str(caught.value)


def test_coefficients_beyond_float32_over_the_region_are_refused():
    doc = good()
    doc["coefficients"]["Fz_N"][3] = 1e35  # u^2: finite in float64, beyond float32's 3.4e38 nowhere, but > 1e30
    with pytest.raises(CalibrationError) as caught:
        validate(doc)
    _one_line(caught.value, "coefficients.Fz_N[3]")


def test_mls_tiny_bandwidth_and_far_points_are_refused():
    doc = good()
    doc["method"] = "mls"
    doc["mls"] = {"order": 1, "bandwidth": 1e-300,
                  "points": {"Bz_uT": [12000.0, 20000.0, 28000.0], "Br_uT": [0.0, 6000.0, 0.0],
                             "Fz_N": [0.0, 1.0, 2.0], "Fr_N": [0.0, 0.5, 1.0]}}
    with pytest.raises(CalibrationError) as caught:
        validate(copy.deepcopy(doc))
    _one_line(caught.value, "mls.bandwidth")
    doc["mls"]["bandwidth"] = 0.3
    doc["mls"]["points"]["Bz_uT"][1] = 1e300
    with pytest.raises(CalibrationError) as caught:
        validate(doc)
    _one_line(caught.value, "mls.points.Bz_uT[1]")


def test_the_host_never_divides_by_zero_at_a_temperature_outside_the_range():
    """A valid file (the denominator at least 0.5 from -40 to 125 C) read at a temperature no chip reports (a
    corrupted word): the host leaves the field uncorrected, as the firmware does (and flags it there)."""
    doc = good()
    doc["thermal"] = {"reference_C": 25.0, "source": "recipe",
                      "coefficient_per_C": {"Bx_uT": -0.005, "By_uT": -0.005, "Bz_uT": -0.005}}
    cal = Calibration(doc)
    assert cal.evaluate(1000.0, 0.0, 20000.0, temperature_C=225.0) == cal.evaluate(1000.0, 0.0, 20000.0)


def _check_finite(cal: Calibration, doc: dict) -> None:
    methods = ["poly"] + (["mls"] if "mls" in doc else [])
    temps = [None] if "thermal" not in doc else [THERMAL_REFERENCE_C[0], 25.0, THERMAL_REFERENCE_C[1]]
    points = region_points(doc)
    assert points, "the region holds the hull's vertices"
    for bz, br in points:
        for t in temps:
            a = [0.0] * 3 if t is None else [doc["thermal"]["coefficient_per_C"][k] for k in AXES]
            t0 = 0.0 if t is None else doc["thermal"]["reference_C"]
            d = [1.0 + ak * ((t or 0.0) - t0) for ak in a]
            assert min(d) >= THERMAL_MIN_DENOMINATOR
            bx, by = br * 0.6, br * 0.8  # the field read at T: the region's field times the denominators
            for method in methods:
                f = cal.evaluate(bx * d[0], by * d[1], bz * d[2], method=method, temperature_C=t)
                assert all(math.isfinite(x) and abs(x) <= FLOAT32_MAX for x in f), (bz, br, t, method, f)


def _refusal(doc: dict) -> CalibrationError | None:
    try:
        validate(copy.deepcopy(doc))
    except CalibrationError as exc:
        return exc
    return None


@settings(max_examples=250, **SETTINGS)
@given(doc=calibration())
def test_generated_documents_are_refused_in_one_line_or_evaluate_finite(doc):
    exc = _refusal(doc)
    if exc is not None:
        node = doc
        for part in exc.key.split("[")[0].split("."):  # the key path names a key of the document
            assert part in node, (exc.key, str(exc))
            node = node[part]
        _one_line(exc, exc.key)
        event("refused: " + exc.key.split("[")[0])
        return
    event("accepted " + doc["method"] + (" thermal" if "thermal" in doc else ""))
    _check_finite(Calibration(doc), doc)
