"""The drift budget (magfab.models.drift): each figure against an independent computation, and the spec keys."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from magfab import SpecError, derive, parse_spec
from magfab.check import drift_findings
from magfab.errors import Severity
from magfab.models import drift as D
from magfab.models import field as F


def _calibration_inverse(pred, b_G):
    """The stiff material's force at the field ``b_G`` on the weakest magnet's curve, N, written out again: linear
    interpolation within the curve, the first segment's slope below rest."""
    bz, f = np.asarray(pred.arrays["bz_low"]), np.asarray(pred.curves["stiff"].force_N)
    if b_G < bz[0]:
        return f[0] + (b_G - bz[0]) * (f[1] - f[0]) / (bz[1] - bz[0])
    return float(np.interp(b_G, bz, f))


def test_the_magnets_error_per_degree_is_the_field_recomputed_with_a_warmer_magnet(design, pred):
    """Br scaled by (1 + alpha) for +1 C, the field recomputed with magpylib (not the prediction's field model) at the
    rest point, and read through the calibration's inverse."""
    alpha = D.coefficients(design).magnet_pct_per_C / 100.0
    cold = F.Magnet.from_design(design, "low")
    warm = F.Magnet(cold.radius_mm, cold.height_mm, cold.remanence_T * (1.0 + alpha))
    point = np.array([[0.0, 0.0, -(cold.height_mm / 2.0 + design.d_rest_mm)]])
    shift = F.magpylib_cylinder(warm, point)[0, 2] - F.magpylib_cylinder(cold, point)[0, 2]
    assert shift == pytest.approx(alpha * F.magpylib_cylinder(cold, point)[0, 2], rel=1e-9)  # B is linear in Br
    b_rest = pred.arrays["bz_low"][0]
    expected_mN = 1000.0 * _calibration_inverse(pred, b_rest + shift)
    got = pred.drift.temperature.per_C_parts["magnet"]
    assert got == pytest.approx(expected_mN, rel=0.01)  # the prediction's field model is within 1 % of exact
    assert got < 0  # a warmer magnet reads as a pull


def test_the_error_is_read_through_the_curve_not_its_tangent(design, pred):
    """At the end of the range the curve bends: a large field change read through the curve differs from the
    tangent's estimate, and the curve's answer is the one reported (a negative control for the inverse)."""
    ch = D.normal_channel(pred)
    b_end = ch.field_at(ch.end_N)
    big = 0.2 * b_end
    through_curve = float(D.force_error_mN(ch, ch.end_N, b_end - big))
    slope = (ch.force[-1] - ch.force[-2]) / (ch.field_G[-1] - ch.field_G[-2])
    tangent = -1000.0 * big * slope
    assert abs(through_curve - tangent) > 0.05 * abs(tangent)
    assert through_curve == pytest.approx(1000.0 * (float(np.interp(b_end - big, ch.field_G, ch.force)) - ch.end_N))


def test_compensation_with_exact_coefficients_and_no_other_error_leaves_nothing():
    b = np.array([150.0, 250.0])
    read = D.temperature_read_G(b, 10.0, alpha_pct=-0.12, compensation=(-0.12, 10.0))
    assert read == pytest.approx(b, rel=1e-12)
    read = D.temperature_read_G(b, 10.0, alpha_pct=-0.12)
    assert read == pytest.approx(b * (1 - 0.012), rel=1e-12)


def test_the_temperature_budget_orders_its_cases_and_grows_with_the_span(design, pred):
    t = pred.drift.temperature
    for point in ("normal_rest", "normal_end"):
        w = t.worst[point]
        assert w["without"] > w["with"] > w["fitted"] > 0
    assert t.worst["normal_rest"]["without"] == pytest.approx(5 * abs(t.per_C["normal_rest"]["without"]), rel=0.05)
    wide = derive(parse_spec("[environment]\ntemperature_min_C = 10.0\ntemperature_max_C = 40.0\n"))
    assert D.temperature_budget(wide, pred).worst["normal_rest"]["without"] == pytest.approx(
        3 * t.worst["normal_rest"]["without"], rel=0.05)
    assert t.calibration_C == 25.0 and t.span["normal_rest"]["without"][t.temperatures_C.index(25.0)] == 0.0


def test_the_earth_fields_error_scales_with_the_band_and_the_turn(design, pred):
    low = D.rotation_error(design, pred, field_G=0.25)
    high = D.rotation_error(design, pred, field_G=0.65)
    assert abs(high.normal_rest_mN) / abs(low.normal_rest_mN) == pytest.approx(0.65 / 0.25, rel=0.02)
    assert high.shear_mN / low.shear_mN == pytest.approx(0.65 / 0.25, rel=1e-9)  # the shear channel is linear
    assert high.field_G == pytest.approx(1.3)  # turned over: twice the field on an axis
    sixty = D.rotation_error(design, pred, field_G=0.65, rotation_deg=60.0)
    assert sixty.field_G == pytest.approx(0.65)  # 2 |B| sin(30 deg)
    assert D.rotation_error(design, pred, rotation_deg=0.0).normal_rest_mN == 0.0
    assert abs(high.shear_mN) == pytest.approx(1000 * 1.3 / pred.shear.sensitivity_G_per_N[0], rel=1e-9)


def test_the_dipole_is_magpylibs():
    import magpylib

    rng = np.random.default_rng(18)
    for _ in range(5):
        m, src, obs = rng.normal(size=3), rng.normal(size=3) * 50, rng.normal(size=3) * 50
        ref = magpylib.misc.Dipole(moment=m, position=src * 1e-3).getB(obs * 1e-3) * 1e4  # T -> G
        assert D.dipole_field_G(m, src, obs) == pytest.approx(ref, rel=1e-9, abs=1e-15)


def test_the_worst_orientation_of_a_dipole_is_found(design):
    """Over moment directions and positions on a sphere of 30 mm, no field on z exceeds the worst case, and some come
    within 1 % of it."""
    rng = np.random.default_rng(1)
    dirs = rng.normal(size=(600, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    dirs = np.vstack([dirs, [[0, 0, 1]]])
    b = D.dipole_field_G(dirs[:, None, :] * 0.5, dirs[None, :, :] * 30.0, np.zeros(3))
    worst = D.dipole_worst_G(0.5, 30.0)
    assert np.max(np.abs(b[..., 2])) <= worst * (1 + 1e-12)
    assert np.max(np.abs(b[..., 2])) >= 0.99 * worst
    assert worst == pytest.approx(4e-7 * math.pi * 0.5 / (2 * math.pi * 0.03**3) * 1e4)


def test_a_stated_stray_source_is_in_the_budget_and_none_is_not(design, pred):
    assert pred.drift.stray is None and "stray" in pred.as_json()["drift"]
    stated = derive(parse_spec("[environment]\nstray_moment_Am2 = 0.1\nstray_distance_mm = 30.0\n"))
    s = D.stray_error(stated, pred)
    assert s is not None and s.field_G == pytest.approx(D.dipole_worst_G(0.1, 30.0))
    nearer = D.stray_error(stated, pred, distance_mm=15.0)
    assert abs(nearer.shear_mN) == pytest.approx(8 * abs(s.shear_mN), rel=1e-9)  # 1/r^3
    codes = {f.code: f for f in drift_findings(stated, D.drift(stated, pred))}
    assert codes["drift-stray"].key == "environment.stray_distance_mm"


def test_findings_warn_only_where_an_error_exceeds_the_resolution(design, pred):
    found = {f.code: f for f in drift_findings(design, pred.drift)}
    assert found["drift-rotation"].severity is Severity.WARNING  # 1.3 G against ~0.1 G of noise
    still = derive(parse_spec("[environment]\nrotation_deg = 0.0\n"))
    found = {f.code: f for f in drift_findings(still, D.drift(still, pred))}
    assert found["drift-rotation"].severity is Severity.INFO


def test_the_drift_section_is_plain_and_deterministic(design, pred):
    doc = pred.as_json()["drift"]
    text = json.dumps(doc, sort_keys=True)
    assert text == json.dumps(D.drift(design, pred).as_json(), sort_keys=True)
    assert set(doc["temperature"]["per_C_mN"]["normal_rest"]) == set(D.CASES)
    assert doc["conditions"]["stated"] is False and doc["conditions"]["earth_field_G"] == 0.65
    assert doc["resolution_mN"]["normal"] == pred.normal.resolution_mN


@pytest.mark.parametrize("text, message", [
    ("temperature_min_C = 30.0\ntemperature_max_C = 20.0", "must be above temperature_min_C"),
    ("calibration_temperature_C = 40.0", "must lie within the span 20..30 C"),
    ("temperature_max_C = 130.0", "environment.temperature_max_C = 130.0: must be at most 125 C"),
    ("stray_distance_mm = 5.0", "environment.stray_distance_mm = 5.0: must be at least 10 mm"),
    ("stray_moment_Am2 = -1.0", "must be at least 0 A m^2"),
    ("earth_field_G = 2.0", "environment.earth_field_G = 2.0: must be at most 1 G"),
    ("rotation_deg = 270.0", "must be at most 180 deg"),
    ("temperature_lag = 1.0", "did you mean 'temperature_lag_C'?"),
])
def test_environment_spec_errors_are_one_line(text, message):
    with pytest.raises(SpecError) as info:
        parse_spec(f"[environment]\n{text}\n")
    assert message in str(info.value) and "\n" not in str(info.value)


def test_an_omitted_environment_leaves_the_spec_as_it_was():
    spec = parse_spec("")
    assert spec.environment is None and "environment" not in spec.dump()
    stated = parse_spec("[environment]\nrotation_deg = 90\n")
    assert stated.dump()["environment"]["rotation_deg"] == 90.0 and stated.sha256() != spec.sha256()


def test_the_build_ships_the_chart_deterministically(pred):
    from magfab.pipeline import _drift_charts

    first, again = _drift_charts(pred), _drift_charts(pred)
    assert [a.path for a in first] == ["drift/drift.png", "drift/drift.svg"]
    assert [a.data for a in first] == [a.data for a in again]
    assert first[1].data.lstrip().startswith(b"<?xml") and first[1].description.endswith(", SVG")


def test_the_reports_section_lists_every_source_against_the_resolution(design, pred):
    from magfab.export.report.drift import HEADER, drift_context

    stated = derive(parse_spec("[environment]\nstray_moment_Am2 = 0.1\nstray_distance_mm = 30.0\nrotation_deg = 0.0\n"))
    p = replace(pred, drift=D.drift(stated, pred))
    ctx = drift_context(p, lambda folder: [folder])
    labels = [row[0] for row in ctx["rows"]]
    assert ctx["figures"] == ["drift/"] and all(len(row) == len(HEADER) for row in ctx["rows"])
    assert labels[0] == "temperature, per C, uncompensated" and labels[-1].startswith("stray source: a 0.1 A m^2")
    turn = next(row for row in ctx["rows"] if row[0].startswith("this place"))
    assert turn[-1] == "within the resolution" and "spec's [environment]" in ctx["summary"]
    assert drift_context(replace(pred, drift=None), lambda folder: []) is None


def test_given_coefficients_give_the_simulated_runs_error(pred):
    """What a simulated ramp with known coefficients should show: the magnet alone, compensated exactly, is zero; a
    wrong alpha leaves the difference, which the budget's recipe case bounds."""
    ch = D.normal_channel(pred)
    dT = np.array([-5.0, 0.0, 5.0])
    exact = D.temperature_error_mN(ch, 0.0, dT, alpha_pct=-0.12, compensation=(-0.12, dT))
    assert np.allclose(exact, 0.0, atol=1e-9)
    off = D.temperature_error_mN(ch, 0.0, dT, alpha_pct=-0.09, compensation=(-0.12, dT))
    assert off[1] == 0.0 and off[2] > 0 > off[0]
    bound = np.abs(pred.drift.temperature.span["normal_rest"]["with"])
    t = np.asarray(pred.drift.temperature.temperatures_C)
    assert np.all(np.abs(off[[0, 2]]) <= bound[np.isin(t, [20.0, 30.0])])
    doc = pred.as_json()["drift"]
    assert doc["rotation"]["field_over_noise_z"] == pytest.approx(1.3 / pred.noise.total_z_G)


def test_the_worst_case_bounds_every_draw_within_the_bands(design, pred):
    """Coefficients drawn anywhere in their bands (magnet alpha, chip sensitivity and offset, lag, temperature
    reading error) never exceed the budget's compensated bound at any temperature of the span, and come close."""
    c = D.coefficients(design)
    t = pred.drift.temperature
    temps = np.asarray(t.temperatures_C)
    dT = temps - t.calibration_C
    ch = D.normal_channel(pred)
    rng = np.random.default_rng(7)
    n = 400
    alpha = rng.uniform(*c.magnet_spread_pct_per_C, size=(n, 1))
    sens = rng.uniform(-1, 1, size=(n, 1)) * c.chip_sensitivity_pct_per_C
    offset = rng.uniform(-1, 1, size=(n, 1)) * c.chip_offset_z_G_per_C
    lag = rng.uniform(-1, 1, size=(n, 1)) * D.environment(design).temperature_lag_C
    lo, hi = c.operating_C
    x, x0 = (temps - (lo + hi) / 2) / ((hi - lo) / 2), (t.calibration_C - (lo + hi) / 2) / ((hi - lo) / 2)
    reading = rng.uniform(-1, 1, size=(n, 1)) * (2 * c.sensor_linearity_C * np.abs(x**2 - x0**2)
                                                 + 0.5 * c.sensor_step_C)
    err = D.temperature_error_mN(ch, 0.0, dT, alpha_pct=alpha, sensitivity_pct=sens, offset_G_per_C=offset,
                                 magnet_dT_C=dT + lag, compensation=(c.magnet_pct_per_C, dT + reading))
    bound = np.abs(np.asarray(t.span["normal_rest"]["with"]))
    assert np.all(np.abs(err) <= bound * (1 + 1e-9))
    assert np.max(np.abs(err)) > 0.6 * np.max(bound)


def test_the_key_figures_carry_the_drift(design, pred):
    from magfab.export.report.tables import key_figures

    row = next(r for r in key_figures(design, pred, None, []) if r[0] == "drift")
    assert row[1] == f"{abs(pred.drift.temperature.per_C['normal_rest']['without']):.1f} mN/C"
    assert "180 deg" in row[2]
    assert not [r for r in key_figures(design, replace(pred, drift=None), None, []) if r[0] == "drift"]
