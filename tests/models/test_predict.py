"""Predictions: the chain field x elastomer -> sensitivity, resolution, range; the checks on them; the
model choice; and what a build writes."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab import SpecError, derive, parse_spec
from magfab.check import predict_with_findings, prediction_findings
from magfab.errors import Severity
from magfab.export import firmware
from magfab.models import field as F
from magfab.models import mechanics as M
from magfab.models.chip import chip_setting, noise
from magfab.models.predict import predict


def _codes(found, severity=Severity.ERROR):
    return {f.code for f in found if f.severity is severity}


def axial_bz(d, radius, height, br_G):
    """docs/models.md, M6: Bz on the axis at distance d below the pole face, in the unit of ``br_G``."""
    d = np.asarray(d, dtype=float)
    return br_G / 2 * ((d + height) / np.hypot(d + height, radius) - d / np.hypot(d, radius))


def test_the_figures_follow_m10_and_m11_from_the_published_data(pred, design):
    """Recomputed from predictions.json alone (curves, travel, remanence band, noise) and M6 written here:
    S_F = (dBz/du) / (dF/du) (M10) over the range, every material and magnet band; R = N_B / S_F (M11)
    at its worst; the range is the softest curve's force at the binding travel."""
    d = json.loads(json.dumps(pred.as_json()))  # as written
    n, f, noise_G = d["normal"], d["field"], d["noise_G"]
    u = np.asarray(n["magnet_displacement_mm"])
    inside = u <= n["travel_mm"] + 1e-9
    m = F.Magnet.from_design(design)
    s_f = []
    for br_T in f["remanence_T"].values():
        s_b = np.gradient(axial_bz(design.d_rest_mm - u, m.radius_mm, m.height_mm, br_T * 1e4), u, edge_order=2)
        for curve in n["curve"].values():
            k_e = np.gradient([force for _, force in curve], u, edge_order=2)
            s_f.append((s_b / k_e)[inside])
    lo, hi = n["sensitivity_G_per_N"]
    assert lo == pytest.approx(float(np.min(s_f)), rel=1e-3) and hi == pytest.approx(float(np.max(s_f)), rel=1e-3)
    assert 0 < lo < hi
    assert n["resolution_mN"] == pytest.approx(1000 * noise_G["total_z_G"] / lo, rel=1e-9)  # M11, worst case
    assert noise_G["total_z_G"] == pytest.approx(math.sqrt(sum(noise_G[k] ** 2 for k in (
        "environment_G", "chip_z_G", "quantisation_z_G"))))
    soft = np.asarray([force for _, force in n["curve"]["soft"]])
    assert n["range_N"] == pytest.approx(float(np.interp(n["travel_mm"], u, soft)), rel=1e-12)
    assert n["range_N"] == min(n["range_by_material_N"].values())
    # shear: on the axis dBr/dr = dBz/dz / 2 (paraxial expansion of a curl- and divergence-free field); the chip
    # reads the magnet's shift (dBx/dshift = dBr/dr) and tilt (dBx/dtilt = Bz - gap dBr/dr, field.tilt), so at rest
    # S = dBr/dr / k_s + (Bz - d_rest dBr/dr) tilt_per_N; the worst resolution is the stiff material with the
    # weakest magnet at rest (the sensitivity rises with preload as the gap closes and the tilt falls)
    s = d["shear"]
    assert f["dBr_dr_rest_G_per_mm"] == pytest.approx(f["dBz_dz_rest_G_per_mm"] / 2, rel=2e-3)
    weak = f["remanence_T"]["low"] / f["remanence_T"]["nominal"]
    d_shift, d_tilt = f["dBr_dr_rest_G_per_mm"], f["Bz_rest_G"] - design.d_rest_mm * f["dBr_dr_rest_G_per_mm"]
    worst = weak * (d_shift / s["stiffness_N_per_mm"]["stiff"] + d_tilt * s["tilt_at_rest_rad_per_N"]["stiff"])
    assert s["resolution_mN"] == pytest.approx(1000 * noise_G["total_xy_G"] / worst, rel=2e-3)
    assert s["range_N"] == pytest.approx(s["stiffness_N_per_mm"]["soft"] * design.magnet_radius_mm)
    assert set(d["models"]) == {"field", "mechanics", "shear"}


def test_field_at_rest_is_m6_and_gradient_its_derivative(pred, design):
    """On the axis the prediction's field is docs/models.md, M6, with the nominal remanence."""
    m = F.Magnet.from_design(design)
    d, R, H, br = design.d_rest_mm, m.radius_mm, m.height_mm, m.remanence_T * 1e4
    assert pred.as_json()["field"]["Bz_rest_G"] == pytest.approx(float(axial_bz(d, R, H, br)), rel=1e-4)
    h = 1e-4
    slope = float(axial_bz(d + h, R, H, br) - axial_bz(d - h, R, H, br)) / (2 * h)
    assert pred.as_json()["field"]["dBz_dz_rest_G_per_mm"] == pytest.approx(-slope, rel=1e-5)


def test_band_orders_as_physics_says(pred):
    """Softer silicone: more sensitive and finer resolution, smaller force range; stiffness scales with mu."""
    n = pred.as_json()["normal"]
    at_rest = n["resolution_at_rest_mN"]
    assert at_rest["soft"] < at_rest["nominal"] < at_rest["stiff"]
    r = n["range_by_material_N"]
    assert r["soft"] < r["nominal"] < r["stiff"]
    mus = pred.as_json()["material_mu_kPa"]
    k = n["stiffness_at_rest_N_per_mm"]
    assert k["stiff"] / k["soft"] == pytest.approx(mus["stiff"] / mus["soft"], rel=1e-9)
    # the worst case is the stiff material with the weakest magnet, over the range (docs/models.md, M10): at rest
    # under the neo-Hookean law; the Yeoh law's stiffening makes it coarser deeper in
    a = pred.arrays
    assert n["resolution_mN"] == pytest.approx(float(np.max(a["res_stiff_low"][a["in_range"]])), rel=1e-9)
    assert n["resolution_mN"] >= at_rest["stiff"]


def test_sensitivity_is_field_gradient_over_stiffness(pred, design):
    """S_F = S_B / K_e (M10) and R = N_B / S_F (M11), recomputed from the arrays."""
    a = pred.arrays
    u = a["u"]
    s_b = np.gradient(a["bz_low"], u, edge_order=2)
    k_e = np.gradient(pred.curves["stiff"].force_N, u, edge_order=2)
    s_f = s_b / k_e
    assert np.allclose(a["sf_stiff_low"], s_f)
    n_b = pred.as_json()["noise_G"]["total_z_G"]
    assert pred.as_json()["normal"]["resolution_at_rest_mN"]["stiff"] == pytest.approx(1000 * n_b / s_f[0])


def test_noise_combines_environment_chip_and_quantisation(design):
    chip = chip_setting(design)
    nz = noise(design, chip)
    assert nz["total_z_G"] == pytest.approx(math.sqrt(0.1**2 + chip.noise_z_G**2 + (chip.lsb_z_uT / 100) ** 2 / 12))
    assert chip.lsb_z_uT == pytest.approx(1.210 * 4)  # GAIN_SEL 0, RES 2 (datasheet Table 17)
    assert chip.full_scale_z_G == pytest.approx(22000 * 4.84 / 100)
    # T+X+Y+Z at OSR 0, DIG_FILT 2 takes ~1.84 ms (MLX90393 datasheet Table 19); ours omits the wake-up
    assert chip.conversion_ms == pytest.approx(1.84, abs=0.15)
    quiet = derive(parse_spec("[sensor]\nosr = 3\ndig_filt = 7\n"))
    assert chip_setting(quiet).noise_z_G < chip.noise_z_G / 5  # longer averaging, less noise


def test_range_limits_are_reported_and_consistent(pred, design):
    n = pred.as_json()["normal"]
    limits = n["range_limits_travel_mm"]
    assert set(limits) <= {"d_min", "chip full scale", "invertibility", "stretch", "material data", "scan depth",
                           "model"}
    assert limits["d_min"] == pytest.approx(design.d_rest_mm - design.spec.sensor.d_min_mm)
    assert n["travel_mm"] == pytest.approx(min(limits.values()))
    assert n["range_limit"] == min(limits, key=limits.get)
    u, f = pred.arrays["u"], pred.curves["soft"].force_N
    assert n["range_N"] == pytest.approx(float(np.interp(n["travel_mm"], u, f)))
    # MagOne's FE reaches the 3 mm scan depth: the curve ends there, named so, not as a model failure; with the
    # default law (Ecoflex 00-30's Yeoh fit) the stretch stays within its data (4), so the scan depth ends the range:
    # the sensor's range, not a model's reach (the neo-Hookean law's is, tests/test_check_range.py)
    nominal = pred.curves["nominal"]
    assert nominal.indentation_mm[-1] == pytest.approx(design.spec.calibration.scan_z_mm)
    assert "model" not in limits and limits["scan depth"] == pytest.approx(nominal.magnet_displacement_mm[-1])
    assert "calibration.scan_z_mm" in n["model_limit"]
    assert n["range_limit"] == "scan depth" and not n["range_is_model_reach"]
    text = pred.normal.range_text()
    assert text == f"{n['range_N']:.3f} N (ends at: scan depth)"
    stretch = np.interp(n["travel_mm"], u, nominal.max_stretch)
    assert 2.0 < stretch < design.material.yeoh.stretch_max  # past the neo-Hookean data, within the Yeoh fit's


def test_a_curve_is_named_by_what_ends_it():
    """"scan depth" when the FE was solved to the depth the design is used over, "model" when it stopped before."""
    from magfab.models.predict import MODEL, SCAN_DEPTH, _curve_end

    d = np.linspace(0.0, 3.0, 4)
    body = M.Body(6.0, 8.0, 2.0, magnet_radius_mm=2.5, magnet_height_mm=2.0, magnet_z_mm=4.0)
    curve = M.fe(body, 23.0, d[:2], mesh_mm=2.0)
    assert _curve_end(curve, d[:2]) == ("", "")
    stopped = replace(curve, info={**curve.info, "failure": "element inversion at indentation 2 mm"})
    assert _curve_end(stopped, d) == (MODEL, "element inversion at indentation 2 mm")
    solved = replace(curve, info={**curve.info, "failure": "solved to 1 mm", "ends_at": SCAN_DEPTH})
    assert _curve_end(solved, d) == (SCAN_DEPTH, "solved to 1 mm")
    # the whole grid solved, the magnet short of the travel to d_min (it lags the surface): the model's reach
    moved = float(curve.magnet_displacement_mm[-1])
    assert _curve_end(curve, d[:2], travel_mm=moved) == ("", "")
    label, note = _curve_end(curve, d[:2], travel_mm=moved + 0.5)
    assert label == MODEL and f"{moved:.3g} mm of its {moved + 0.5:.3g} mm" in note


def test_sensitivity_at_rest_is_m10_per_material_with_the_nominal_magnet(pred, design):
    """predictions.json's at-rest sensitivities, recomputed from its own numbers and M6 written here: normal
    S_F = (dBz/du) / (dF/du) at u = 0, shear dBr/dr / k_s + (Bz - d_rest dBr/dr) tilt (the magnet's shift and
    tilt per N), each for the nominal grade and every material."""
    d = json.loads(json.dumps(pred.as_json()))
    n, s, f = d["normal"], d["shear"], d["field"]
    u = np.asarray(n["magnet_displacement_mm"])
    m = F.Magnet.from_design(design)
    br_G = f["remanence_T"]["nominal"] * 1e4
    s_b = np.gradient(axial_bz(design.d_rest_mm - u, m.radius_mm, m.height_mm, br_G), u, edge_order=2)[0]
    for k in ("soft", "nominal", "stiff"):
        k_e = np.gradient([force for _, force in n["curve"][k]], u, edge_order=2)[0]
        assert n["sensitivity_at_rest_G_per_N"][k] == pytest.approx(s_b / k_e, rel=1e-3)
        d_shift, d_tilt = f["dBr_dr_rest_G_per_mm"], f["Bz_rest_G"] - design.d_rest_mm * f["dBr_dr_rest_G_per_mm"]
        assert s["sensitivity_at_rest_G_per_N"][k] == pytest.approx(
            d_shift / s["stiffness_N_per_mm"][k] + d_tilt * s["tilt_at_rest_rad_per_N"][k], rel=2e-3)
        assert s["sensitivity_at_rest_G_per_N"][k] < d_shift / s["stiffness_N_per_mm"][k]  # the tilt cancels some
    for key in ("normal", "shear"):
        at_rest = d[key]["sensitivity_at_rest_G_per_N"]
        assert at_rest["soft"] > at_rest["nominal"] > at_rest["stiff"] > 0  # softer silicone, more G per N
        lo, hi = d[key]["sensitivity_G_per_N"]
        assert lo <= at_rest["stiff"] and at_rest["soft"] <= hi  # inside the band over the range, both bands


def test_shear_uses_the_fe_and_its_range_is_the_magnet_radius(pred, design):
    """At rest the magnet's lateral stiffness under a load through the surface is today's load-on-the-magnet FE
    within 2 % (MagOne); along the scan it falls with preload (compressive prestress), and the sensitivity the
    chip sees rises (the gap closes, the tilt falls)."""
    s = pred.as_json()["shear"]
    body = M.Body.from_design(design)
    k = M.shear_stiffness(body, pred.as_json()["material_mu_kPa"]["soft"], "fe")
    assert s["stiffness_N_per_mm"]["soft"] == pytest.approx(k, rel=0.02)
    assert s["range_N"] == pytest.approx(s["stiffness_N_per_mm"]["soft"] * design.magnet_radius_mm)
    along = s["along_scan"]
    assert along["indentation_mm"][0] == 0.0 and along["indentation_mm"][-1] == design.spec.calibration.scan_z_mm
    assert np.all(np.diff(along["magnet_stiffness_N_per_mm"]["nominal"]) < 0)
    assert np.all(np.diff(along["sensitivity_G_per_N"]["nominal"]) > 0)
    assert along["magnet_stiffness_N_per_mm"]["soft"][0] == s["stiffness_N_per_mm"]["soft"]


def test_saturating_design_is_refused_with_the_distance_to_use():
    """A design constraint (docs/models.md, M9): B(d_min) <= the chip's full scale. The paper's 2 mm (to the package
    top) is 1.5 mm too close when measured to the sensing point."""
    d = derive(parse_spec("[sensor]\nd_min_mm = 2.0\n"))
    found = prediction_findings(d, predict(d))
    err = [f for f in found if f.code == "chip-saturates"]
    assert err and err[0].severity is Severity.ERROR and err[0].key == "sensor.d_min_mm"
    assert "at least 2.43 mm" in err[0].message


def test_required_resolution_is_checked():
    d = derive(parse_spec("[predict]\nrequired_resolution_mN = 1.0\n"))
    assert "resolution-short" in _codes(prediction_findings(d, predict(d)))
    d = derive(parse_spec("[predict]\nrequired_resolution_mN = 10.0\n"))
    assert "resolution-short" not in _codes(prediction_findings(d, predict(d)))


def test_default_design_passes_its_checks(design, pred):
    """No error; one warning: with the range to the 3 mm scan depth, the strongest grade's field at its end just
    reaches the chip's 50 mT saturation onset (MLX90393 datasheet, BSAT), which the calibration scan covers."""
    found = prediction_findings(design, pred)
    assert not _codes(found), found
    assert _codes(found, Severity.WARNING) == {"imc-saturation"}, found
    assert 500.0 < pred.field.Bz_range_end_strongest_G < 505.0
    assert any(f.code == "prediction" for f in found)


def test_guidelines_warn(design):
    d = derive(parse_spec("[magnet]\nheight_mm = 4.0\n[sensor]\nd_max_mm = 10.5\nd_min_mm = 6\n"
                          "[elastomer]\nheight_mm = 14.0\n", "tall"))
    warned = _codes(prediction_findings(d, predict(d)), Severity.WARNING)
    assert {"magnet-aspect", "rest-distance"} <= warned


def test_auto_picks_the_cheapest_field_model_within_tolerance(design):
    """The working volume runs to r = R_m: the axial form (M6) and the dipole fail there, the surrogate fits 1 %; a
    tolerance tighter than the surrogate's own error takes the exact field."""
    assert predict(design).as_json()["models"]["field"]["model"] == "surrogate"
    tight = derive(parse_spec("[predict]\ntolerance_pct = 0.0001\nmechanics_model = \"column\"\n"))
    assert predict(tight).as_json()["models"]["field"]["model"] == "exact"


def test_a_chosen_model_outside_tolerance_is_a_warning():
    d = derive(parse_spec('[predict]\nfield_model = "dipole"\nmechanics_model = "column"\n'))
    p = predict(d)
    assert p.as_json()["models"]["field"]["model"] == "dipole" and p.as_json()["models"]["field"]["chosen_by"] == "spec"
    assert "model-error" in _codes(prediction_findings(d, p), Severity.WARNING)


def test_fe_mesh_choice_meets_the_tolerance_by_its_estimate(pred):
    m = pred.as_json()["models"]["mechanics"]
    assert m["model"] == "fe" and m["relative_error"] <= 0.01


def test_bad_register_pairs_are_refused():
    with pytest.raises(SpecError) as e:
        derive(parse_spec("[sensor]\nosr = 1\ndig_filt = 0\n"))
    assert e.value.key == "sensor.dig_filt" and "0/0, 0/1, 1/0" in str(e.value)


def test_prediction_is_deterministic(design, pred, monkeypatch):
    """The same numbers again, and with the reference mesh solved in-process instead of in a forked worker (the
    ``pred`` fixture ran it forked where two cores allow; the build's physics worker runs it in-process)."""
    from magfab.fork import parallel_available

    monkeypatch.setenv("MAGFAB_JOBS", "1")
    assert not parallel_available()
    again = predict(design)
    assert json.dumps(again.as_json(), sort_keys=True) == json.dumps(pred.as_json(), sort_keys=True)


def test_build_writes_predictions_plots_and_records_models(default_build, pred):
    out = default_build.out_dir
    data = json.loads((out / "predictions.json").read_text())
    measured = data.pop("readout_measured")  # beside it, the readout's rate as the shipped image measured it
    assert measured == firmware.measured_rate()
    assert data == json.loads(json.dumps(pred.as_json()))  # the build writes the prediction of its design, whole
    for stem in ("field_axis", "field_contours", "force", "sensitivity", "speed_accuracy"):
        svg = (out / "plots" / f"{stem}.svg").read_text()
        assert svg.lstrip().startswith("<?xml") and "<svg" in svg
        assert (out / "plots" / f"{stem}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["models"]["field_model"]["model"] == data["models"]["field"]["model"]
    assert manifest["models"]["mechanics_model"]["model"] == "fe"


def test_a_model_that_cannot_answer_is_a_finding_not_a_traceback(design, monkeypatch):
    from magfab.models import predict as P

    def broken(*args, **kwargs):
        raise M.MechanicsError("fe (mesh 0.75 mm): element inversion at indentation 0.01 mm")

    monkeypatch.setattr(P.mech, "fe", broken)
    pred, found = predict_with_findings(design)
    assert pred is None
    assert [(f.code, f.severity, f.key) for f in found] == [
        ("prediction-failed", Severity.ERROR, "predict.mechanics_model")]
    assert "element inversion" in found[0].message


def test_the_predicted_rate_is_the_firmwares_pace(default_build):
    """One conversion time for the prediction (noise, scan sample times) and the firmware's pacing: the datasheet's
    table (chips.toml tconv_osr<o>_dig_filt<d>_ms), which the simulated bus delivers 100 % of (test_simbus)."""
    pred = json.loads((default_build.out_dir / "predictions.json").read_text())
    build = json.loads((default_build.out_dir / "readout/src/magfab_readout/build.json").read_text())
    assert pred["chip"]["conversion_ms"] == pytest.approx(1.84)  # OSR 0, DIG_FILT 2, with T (MagOne)
    assert build["sample_rate_Hz"] == pytest.approx(pred["chip"]["rate_Hz"], rel=1e-6)


@settings(max_examples=12, deadline=None)
@given(peak=st.floats(0.15, 0.85), drop=st.floats(0.0, 0.3))
def test_the_range_ends_where_two_forces_give_one_field(magone_design, magone_prediction, peak, drop):
    """A curve whose force stops rising with the magnet's travel at a drawn point (the silicone buckling: it then
    stays level or falls by a drawn fraction) is not one-to-one past it, so the range ends there as "invertibility",
    a limit of the sensor (not "at least"), even before the material law's data end. Drawn to the model's reach or
    past it, it is still found, and the earlier limit ends the range."""
    from magfab.models.predict import FLAT, INVERTIBILITY, _derivative, _normal
    from magfab.models.shear_figures import _crossing

    real = magone_prediction.curves["nominal"]
    u = real.magnet_displacement_mm
    u_peak = peak * float(u[-1])
    force = np.where(u <= u_peak, real.force_N, np.interp(u_peak, u, real.force_N) * (1.0 - drop * (u - u_peak)))
    curves = {k: replace(real, force_N=force).scaled(mu) for k, mu in magone_prediction.material_mu_kPa.items()}
    chip, nz = chip_setting(magone_design), noise(magone_design, chip_setting(magone_design))
    magnets = {b: F.Magnet.from_design(magone_design, b) for b in ("low", "nominal", "high")}
    n, _ = _normal(magone_design, chip, nz, magnets, "exact", curves, ("", ""))
    k_e = _derivative(u, force)
    level = FLAT * np.max(np.abs(k_e))
    flat = int(np.nonzero(k_e[1:] <= level)[0][0]) + 1
    expected = _crossing(u, k_e, level, flat)
    assert n.range_limits_travel_mm[INVERTIBILITY] == pytest.approx(expected)
    if expected < n.range_limits_travel_mm.get("material data", math.inf):
        assert n.range_limit == INVERTIBILITY and not n.range_is_model_reach
        # within the curve's grid step of the peak: the slope is a three-point derivative on the FE's own grid
        assert u_peak - 1e-9 <= n.travel_mm <= u[min(np.searchsorted(u, u_peak) + 1, u.size - 1)] + 1e-9
