"""Calibration from known weights (magfab.models.weighing): the fit recovers the sensors its model describes, over
drawn sensors; against a truth made by the other hyperelastic law it stays within twice a full scan's error and its
stated bound covers the actual error; the plan stays inside the ranges of every skin it is made for."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from design_box import box_designs, plan_or_refusal
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab.errors import ScanError
from magfab.jig import jig_of, jig_plans
from magfab.models import acceptance
from magfab.models.weighing import (
    MIN_FIRST,
    PARAMS,
    RESKIN_KEPT,
    SensorModel,
    calibration_scan,
    first_weighings,
    fit_weights,
    load_of,
    noise_uT,
    reskin_plan,
    weight_plan,
)
from magfab.models.weighing_study import draw_sensor, trial, truth_model, weighings
from magfab.units import G0


@pytest.fixture(scope="module")
def model(magone_design, magone_prediction):
    return SensorModel.of(magone_design, magone_prediction)


@pytest.fixture(scope="module")
def truth(magone_design, magone_prediction, model, magone_neo_hookean):
    return truth_model(magone_design, magone_prediction, model, magone_neo_hookean[1])


@pytest.mark.parametrize("seed", range(8))
def test_a_sensor_the_model_describes_is_recovered_within_its_stated_spread(seed, model, magone_design,
                                                                             magone_prediction):
    """The fit's own model as the truth (shape and shear terms drawn too): every parameter within 4 of its
    posterior standard deviations of the truth, across the bands."""
    rng = np.random.default_rng(seed)
    sensor = draw_sensor(model, model, rng)
    sensor.theta[[7, 8, 9]] = model.prior.sigma[[7, 8, 9]] * rng.uniform(-2.0, 2.0, 3)
    plan = weight_plan(magone_prediction, 5.0)
    fit = fit_weights(model, weighings(sensor, plan, noise_uT(magone_design), rng))
    sd = np.sqrt(np.diag(fit.covariance))[:len(PARAMS)]
    off = np.abs(fit.theta[:len(PARAMS)] - sensor.theta) / sd
    assert np.all(off < 4.0), dict(zip(PARAMS, off.round(2)))
    assert fit.chi2 < 4.0


def test_the_weight_calibration_holds_against_a_full_scan_on_sensors_of_the_other_law(magone_design,
                                                                                      magone_prediction, model,
                                                                                      truth):
    """Eight drawn sensors (the other law, a tilted and offset magnet, the Earth's field, the chip's noise): the
    weight calibration's Fz RMS within twice the full scan's at the median, the re-skin's too, and the stated bound
    over the actual error in at least six of eight (bench/weights.py runs fifty)."""
    rng = np.random.default_rng(2026)
    shipped = _shipped(magone_design, magone_prediction)
    rows = [trial(magone_design, magone_prediction, model, truth, rng, **shipped) for _ in range(8)]
    ratio = [r.weights["fz_rms_N"] / r.full["fz_rms_N"] for r in rows]
    reskin = [r.reskin["fz_rms_N"] / r.reskin_full["fz_rms_N"] for r in rows]
    assert np.median(ratio) <= 2.0 and np.median(reskin) <= 2.0, (ratio, reskin)
    assert sum(r.weights["fz_rms_N"] <= r.bound_fz_rms_N for r in rows) >= 6
    assert sum(r.weights["shear_rms_N"] <= r.bound_shear_rms_N for r in rows) >= 6


def _shipped(design, prediction) -> dict:
    """The plan as the README's two-stage bench walks it (:meth:`magfab.jig.Jig.plan`): the jig's coins on its
    heaviest cap, for the stiffness the softest skin's first two weighings give."""
    return {"plan_of": jig_plans(design, prediction), "adaptive": True}


@pytest.mark.slow
def test_fifty_sensors_meet_the_goals_at_the_median_and_p90(magone_design, magone_prediction, model, truth):
    """The goals over fifty drawn sensors of MagOne: the ratio to the full scan's Fz RMS at most 2 at the median and
    the 90th percentile (the worst is bench/weights.py's to report), the re-skin's too, coverage at least 0.9."""
    rng = np.random.default_rng(50)
    shipped = _shipped(magone_design, magone_prediction)
    rows = [trial(magone_design, magone_prediction, model, truth, rng, **shipped) for _ in range(50)]
    for a, b in (("weights", "full"), ("reskin", "reskin_full")):
        ratio = [getattr(r, a)["fz_rms_N"] / getattr(r, b)["fz_rms_N"] for r in rows]
        assert np.quantile(ratio, 0.9) <= 2.0, (a, sorted(ratio))
    assert np.mean([r.weights["fz_rms_N"] <= r.bound_fz_rms_N for r in rows]) >= 0.9
    assert np.mean([r.weights["shear_rms_N"] <= r.bound_shear_rms_N for r in rows]) >= 0.9


@settings(max_examples=25, deadline=None)
@given(stiffness=st.floats(1.0, 4.0), cap=st.floats(0.0, 20.0))
def test_the_plan_stays_inside_the_ranges_of_the_skin_it_is_for(magone_prediction, stiffness, cap):
    """Twelve weighings on three angles, four to an angle, the cap alone first; every load's normal part within 90 %
    of the skin's normal range and its shear part within 90 % of its shear range (the softest skin's, times its
    stiffness); the first two weighings are the plan's for the softest skin, and a re-skin's three come from it."""
    plan = weight_plan(magone_prediction, cap, stiffness)
    angles = sorted({a for _, a in plan})
    assert len(angles) == 3 and all(sum(a == b for _, b in plan) == 4 for a in angles)
    f = load_of([m for m, _ in plan], [a for _, a in plan])
    assert np.all(f[:, 2] <= 0.9 * stiffness * magone_prediction.normal.range_N + 1e-9)
    assert np.all(f[:, 1] <= 0.9 * stiffness * magone_prediction.shear.range_N + 1e-9)
    assert all(min(m for m, b in plan if b == a) == cap for a in angles)
    first = first_weighings(weight_plan(magone_prediction, cap))
    assert first == [p for p in weight_plan(magone_prediction, cap) if p[1] == 0.0][::3]
    assert set(reskin_plan(plan)) <= set(plan) and len(reskin_plan(plan)) == 3
    assert math.isclose(load_of(1000.0, 0.0)[0, 2], G0)


def test_the_priors_are_the_acceptance_tests_bands(magone_design, magone_prediction, model):
    """The rest distance's prior spans no more than the acceptance test's worst-case distance band; the remanence's
    is the grade's band; each sigma is positive."""
    bands = acceptance.tolerance_bands(magone_design, magone_prediction)
    doc = acceptance.acceptance(magone_design, magone_prediction)
    d = doc["rest"]["distance_mm"]
    mid, half = bands["rest_distance_mm"]
    assert d["min"] - 1e-9 <= d["nominal"] + mid - half and d["nominal"] + mid + half <= d["max"] + 1e-9
    lo, hi, _ = bands["remanence_T"]
    assert math.isclose(4 * model.prior.sigma[PARAMS.index("log_br")], math.log(hi / lo))
    assert np.all(model.prior.sigma > 0) and set(model.prior.sources) == set(PARAMS)
    assert set(RESKIN_KEPT) < set(PARAMS) and {"log_mu", "d_mm"}.isdisjoint(RESKIN_KEPT)


def test_weighings_no_skin_of_the_design_explains_are_refused(magone_design, magone_prediction, model):
    """A magnet seated 1 mm high (fitted as a rest distance far outside its band), a mass no skin of the design
    carries, and weighings of another sensor's field: each refused in one line before any calibration is fitted."""
    rng = np.random.default_rng(3)
    sensor = draw_sensor(model, model, rng, centred=True)
    sensor.theta[2] = model.prior.mean[2] + 1.0
    plan = weight_plan(magone_prediction, 5.0)
    noise = noise_uT(magone_design)
    with pytest.raises(ScanError, match=r"the weighings fit d_mm = .* sigma from its band"):
        calibration_scan(magone_design, magone_prediction, weighings(sensor, plan, noise, rng))
    heavy = weighings(draw_sensor(model, model, rng), plan, noise, rng)
    heavy[3] = replace(heavy[3], mass_g=5005.0)
    with pytest.raises(ScanError, match=r"weighing 4, 5005 g at 0 deg, pushes 49\.1 N"):
        calibration_scan(magone_design, magone_prediction, heavy)
    mixed = weighings(draw_sensor(model, model, rng), plan, noise, rng)
    mixed[5] = replace(mixed[5], field_uT=(0.0, 0.0, 0.5 * mixed[5].field_uT[2]))
    with pytest.raises(ScanError, match="do not fit this design's model"):
        calibration_scan(magone_design, magone_prediction, mixed)


def _weighed_across_the_box(n: int, seed: int) -> None:
    """Each drawn design: its plan inside its ranges, its model's own sensors recovered (4 posterior sigma), and the
    command's path (guards, model scan, calibration, bound) run to a finite predicted error."""
    from magfab.models.predict import predict

    weighed = 0
    for design in box_designs(n, seed):
        prediction = predict(design)
        model = SensorModel.of(design, prediction)
        rng = np.random.default_rng(seed)
        sensor = draw_sensor(model, model, rng)
        jig = jig_of(design)  # the plan the build ships: the jig's coins on its heaviest cap
        cap_N = jig.cap_mass_bound_g() * G0 / 1000.0
        tilted = [a for a in (20.0, 40.0) if cap_N <= 0.9 * min(prediction.normal.range_N / math.cos(math.radians(a)),
                                                                prediction.shear.range_N / math.sin(math.radians(a)))]
        if 900 * prediction.normal.range_N < (jig.cap_mass_bound_g() + 2 * jig.coin_g) * G0 or not tilted:
            with pytest.raises(ScanError, match="calibrate it from a scan"):  # told, no plan
                jig.plan(prediction)
            continue
        steps, refusal = plan_or_refusal(jig, prediction)
        if steps is None:  # ranges that leave too few weighings: told, and only then
            assert f"fewer than the {MIN_FIRST} a first weight calibration needs" in refusal
            continue
        plan = [(m, a) for m, a, _ in steps]
        assert len(plan) >= MIN_FIRST and {a for _, a in plan} == {0.0, *tilted}  # an overloaded stand: no weighings
        weighed += 1
        loads = load_of([m for m, _ in plan], [a for _, a in plan])
        assert np.all(loads[:, 2] <= 0.9 * prediction.normal.range_N + 1e-9), design.spec.name
        assert np.all(loads[:, 1] <= 0.9 * prediction.shear.range_N + 1e-9), design.spec.name
        data = weighings(sensor, plan, noise_uT(design), rng)
        fit = fit_weights(model, data)
        sd = np.sqrt(np.diag(fit.covariance))[:len(PARAMS)]
        off = np.abs(fit.theta[:len(PARAMS)] - sensor.theta) / sd
        assert np.all(off < 4.0), (design.spec.elastomer, dict(zip(PARAMS, off.round(2))))
        scan, _, bound = calibration_scan(design, prediction, data)
        assert scan.rows > 50 and 0 < bound.fz_rms_N[0] <= bound.fz_rms_N[1] < math.inf
    assert weighed >= n // 2


def test_the_weight_path_holds_across_the_design_box():
    """Three designs drawn from the search's default box (other silicones, tips and magnets than the fixtures'); the
    slow test draws sixteen."""
    _weighed_across_the_box(3, 2026)


@pytest.mark.slow
def test_the_weight_path_holds_across_the_design_box_densely():
    _weighed_across_the_box(16, 7)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), high=st.floats(0.75, 2.0), row=st.integers(0, 11), excess=st.floats(1.01, 20.0))
def test_generated_mistakes_are_refused_by_their_guard(magone_design, magone_prediction, model, seed, high, row,
                                                       excess):
    """The guards against generated variants of their mistakes, on a sensor drawn across the bands: a magnet seated
    0.75-2 mm high is fitted outside the rest distance's band; any weighing made 1-20x heavier than the stiffest skin
    carries is refused by its number. The seat's lower end: the rest distance's prior sigma is 0.111 mm, so a sensor
    at its band's edge (-2 sigma) seated 0.67 mm high lands on the guard's 4 sigma exactly; the fit's own spread
    needs about 0.7 sigma more (0.7 mm high: 12 of 300 draws fitted inside, one of them a CI run's Hypothesis draw;
    0.75 mm: none of 300)."""
    rng = np.random.default_rng(seed)
    sensor = draw_sensor(model, model, rng)
    sensor.theta[2] += high
    plan = weight_plan(magone_prediction, 5.0)
    noise = noise_uT(magone_design)
    with pytest.raises(ScanError, match=r"the weighings fit d_mm = .* sigma from its band"):
        calibration_scan(magone_design, magone_prediction, weighings(sensor, plan, noise, rng))
    data = weighings(draw_sensor(model, model, rng), plan, noise, rng)
    stiffest = model.force_N[-1] * math.exp(model.prior.mean[0] + 2.0 * model.prior.sigma[0])
    angle = data[row].angle_deg
    data[row] = replace(data[row], mass_g=excess * stiffest * 1000.0 / G0 / math.cos(math.radians(angle)))
    with pytest.raises(ScanError, match=rf"weighing {row + 1}, .* g at {angle:g} deg, pushes"):
        calibration_scan(magone_design, magone_prediction, data)
