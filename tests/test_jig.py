"""The weight jig (magfab/jig.py) over the design space: the cap's face covers the tip wherever it travels, its tray
clears the board under the deepest load the plan may put on it, the coins keep the load on the axis, the stand keeps
the load inside its base, and the plan in coins stays inside the ranges and the pockets."""

from __future__ import annotations

import math

import numpy as np
import pytest
from design_box import box_designs, plan_or_refusal
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab import derive, load_spec
from magfab.jig import ANGLES_DEG, BASE_CLEARANCE_MM, REACH, coin_layout, jig_of, platform
from magfab.models import predict as predict_module
from magfab.models import weighing
from magfab.recipes import catalogue
from magfab.units import G0


def test_the_jigs_constants_are_the_models():
    assert REACH == predict_module.GRID_REACH
    assert ANGLES_DEG == weighing.ANGLES_DEG


@settings(max_examples=60, deadline=None)
@given(pairs=st.integers(0, 60), pockets=st.sampled_from([2, 4, 6, 8]))
def test_any_even_stack_keeps_the_load_on_the_axis(pairs, pockets):
    layout = coin_layout(2 * pairs, pockets)
    assert sum(layout) == 2 * pairs and max(layout) - min(layout) <= 1
    angles = 2 * math.pi * np.arange(pockets) / pockets
    centre = np.array([np.dot(layout, np.cos(angles)), np.dot(layout, np.sin(angles))])
    assert np.allclose(centre, 0.0, atol=1e-9)


def test_an_odd_stack_is_refused():
    with pytest.raises(ValueError, match="odd"):
        coin_layout(7, 6)


def _holds(design, prediction=None) -> None:
    """The jig's geometry for ``design`` (and its plan, given the prediction)."""
    j = jig_of(design)
    # the flat face covers the tip, with half its radius of lateral travel
    assert j.face_radius_mm >= 1.5 * design.elastomer_radius_mm
    # the tray clears the pad's lip and the connector by the clearance with the cap sunk to the curve's end
    connector = catalogue("parts")["jst-sh-4"]["height_mm"].nominal
    tallest = max(design.z_pad_top_mm + design.lip_height_mm, connector)
    assert j.z_under_mm - j.sink_mm >= tallest + 0.999
    assert j.sink_mm == pytest.approx(min(REACH * predict_module.travel_to_d_min(design),
                                          design.spec.calibration.scan_z_mm))
    # the pockets stand clear of the skirt and of each other
    assert j.pocket_ring_mm - j.pocket_radius_mm - j.wall_mm > j.face_radius_mm + j.wall_mm
    gap = 2 * j.pocket_ring_mm * math.sin(math.pi / j.pockets)
    assert gap > 2 * (j.pocket_radius_mm + j.wall_mm)
    # the stand: the loaded cap clears its base plate, and its load falls well inside the base
    for angle in ANGLES_DEG:
        p = platform(design, angle)
        assert p.cap_clearance_mm >= BASE_CLEARANCE_MM - 1e-9 and p.low_mm > p.depth_mm, p
        a = math.radians(angle)
        lever = j.board_thickness_mm - p.depth_mm + j.z_face_mm + j.rim_mm
        assert lever * math.sin(a) <= p.base_mm[1] / 2.0 - 10.0, p
    if prediction is None:
        return
    plan, refusal = plan_or_refusal(j, prediction)
    if plan is None:  # a range the cap and two coins already pass, a shear range the cap alone, or ranges that
        cap_N = j.cap_mass_bound_g() * G0 / 1000.0  # leave too few weighings: refused, and only then
        assert (j.cap_mass_bound_g() + 2 * j.coin_g > 900 * prediction.normal.range_N / G0
                or cap_N * math.sin(math.radians(20.0)) > 0.9 * prediction.shear.range_N
                or f"fewer than the {weighing.MIN_FIRST}" in refusal), refusal
        return
    loads = weighing.load_of([m for m, _, _ in plan], [a for _, a, _ in plan])
    assert np.all(loads[:, 2] <= 0.9 * prediction.normal.range_N + 1e-9)
    assert np.all(loads[:, 1] <= 0.9 * prediction.shear.range_N + 1e-9)
    for _, angle, coins in plan:
        assert coins % 2 == 0
        assert j.moment_arm_mm(coins) <= j.steady_arm_mm  # the loaded cap stays steady on a rounded tip
        if angle > 0:  # a tilted stack stays below the pockets' rim
            assert max(coin_layout(coins, j.pockets)) * j.coin_mm <= j.rim_mm


def test_the_jig_holds_for_magone(magone_design, magone_prediction):
    _holds(magone_design, magone_prediction)


def test_a_flat_tip_carries_only_what_its_contact_keeps_steady():
    """A flat tip has no rolling geometry to right the cap: its flat-stand loads stop where the load's tipping moment
    per radian, W h, passes the contact's rotational stiffness (k_n a^2 / 4, the softest skin), and that bound falls
    as stacks grow. On MagOne's flat tip the rule allows 84 coins of the 144 the pockets' four-rim stacks hold (at
    144, W h is 3x its k_theta, the stiffness held at the soft curve's end past it)."""
    from magfab.spec import parse_spec

    design = derive(parse_spec('[elastomer]\ntip = "flat"'))
    prediction = predict_module.predict(design)
    j = jig_of(design)
    most = round(max(j.loads_g()) / j.coin_g)
    steady = [j.contact_steady(coins, prediction) for coins in range(0, most + 1, 2)]
    assert steady == sorted(steady, reverse=True)  # once unsteady, heavier stays so
    assert round(max(j.plan_loads(prediction)["loads_g"]) / j.coin_g) == 84 and most == 144
    curve = prediction.curves["soft"]
    weight = (j.cap_mass_bound_g() + most * j.coin_g) * G0 / 1000.0
    k_theta = np.interp(weight, curve.force_N, curve.stiffness_N_per_mm) * j.tip_radius_mm**2 / 4.0
    assert weight * j.moment_arm_mm(most) / k_theta == pytest.approx(3.0, abs=0.1)
    _holds(design, prediction)


def test_the_jig_holds_across_the_design_box():
    """Designs drawn from the inverse search's default box, without their predictions (the plan is held over the box
    by tests/models/test_weighing.py); the slow test draws more, with."""
    for design in box_designs(12, 11):
        _holds(design)


@pytest.mark.slow
def test_the_jig_and_its_plan_hold_across_the_design_box_densely():
    for design in box_designs(12, 23):
        _holds(design, predict_module.predict(design))


def test_the_caps_volume_is_its_solids(monkeypatch):
    """The cap's mass bound (the plan's range check, made without the CAD kernel) is its solid's volume: MagOne's,
    and a short tip's whose tray must sit above its top (its tray raised past the face), both on the bed."""
    import dataclasses

    from magfab import jig as jig_module

    design = derive(load_spec(None))
    nominal = jig_of(design)
    short = dataclasses.replace(nominal, z_under_mm=nominal.z_face_mm + 0.7)
    for j in (nominal, short):
        monkeypatch.setattr(jig_module, "jig_of", lambda _design, j=j: j)
        solid = jig_module.cap_solid(design).val()
        assert solid.isValid() and solid.BoundingBox().zmin == pytest.approx(0.0, abs=1e-9)
        assert solid.Volume() == pytest.approx(j.cap_volume_mm3(), rel=1e-6)


def _cap_clears_its_stands(design) -> None:
    """The cap in its use pose on each stand, sunk to the normal curve's end, and the stand share no volume (the
    cap's tray overhangs the platform and hangs over the base plate on the downhill side)."""
    from magfab.jig import cap_solid, stand_solid

    j = jig_of(design)
    for angle in ANGLES_DEG:
        p = platform(design, angle)
        lo, _ = j.skirt_span_mm
        # the cap from its print pose to its use pose on the board, sunk, then onto the platform's tilted face
        on_board = lo - j.sink_mm + j.board_thickness_mm - p.depth_mm
        cap = (cap_solid(design).translate((0, 0, on_board)).rotate((0, 0, 0), (1, 0, 0), -angle)
               .translate((0, 0, p.centre_z_mm)))
        common = cap.intersect(stand_solid(design, angle))
        volume = sum(s.Volume() for s in common.solids().vals()) if common.solids().size() else 0.0
        assert volume == pytest.approx(0.0, abs=1e-6), (design.spec.name, angle, volume)
        assert cap.val().BoundingBox().zmin >= 0.0, (design.spec.name, angle)


def test_the_loaded_cap_clears_its_stand(magone_design):
    _cap_clears_its_stands(magone_design)


def test_the_loaded_cap_clears_its_stand_across_the_design_box():
    """The same over designs drawn from the inverse search's default box (every silicone, tip and stock magnet; tips
    and boards of every size the search makes)."""
    for design in box_designs(12, 11):
        _cap_clears_its_stands(design)


def test_an_array_has_no_jig(array_builds):
    design = array_builds["strip_1x5"].design
    with pytest.raises(ValueError, match="single taxel"):
        jig_of(design)
    assert not any(a.path.startswith("weigh_") for a in array_builds["strip_1x5"].artifacts)
    assert not any(a.path.endswith("weigh_plan.json") for a in array_builds["strip_1x5"].artifacts)


def test_a_stand_the_cap_alone_overloads_has_no_weighings(magone_design, magone_prediction, monkeypatch):
    """A shear range the cap alone passes at 40 degrees but not at 20: the plan weighs on two stands and the build's
    plan file tabulates only those (it once failed on the empty stand); a shear range the cap alone passes on every
    tilted stand: no plan, and the build's findings say why."""
    import dataclasses

    from magfab import pipeline
    from magfab.errors import Severity
    from magfab.export.weigh_plan import weigh_plan

    j = jig_of(magone_design)
    cap_N = j.cap_mass_bound_g() * G0 / 1000.0
    between = cap_N * (math.sin(math.radians(20.0)) + math.sin(math.radians(40.0))) / 2.0 / 0.9
    narrow = dataclasses.replace(magone_prediction,
                                 shear=dataclasses.replace(magone_prediction.shear, range_N=between))
    plan = weigh_plan(magone_design, narrow)
    assert {s["angle_deg"] for s in plan["steps"]} == {0.0, 20.0} == {t["angle_deg"] for t in plan["nominal"]}
    assert len(plan["steps"]) >= weighing.MIN_FIRST
    none = dataclasses.replace(magone_prediction, shear=dataclasses.replace(
        magone_prediction.shear, range_N=0.9 * cap_N * math.sin(math.radians(20.0))))
    with pytest.raises(weighing.ScanError, match="on every tilted stand: no weight plan tells its shear"):
        weigh_plan(magone_design, none)
    monkeypatch.setattr(pipeline, "weigh_plan", lambda design, prediction: weigh_plan(design, none))
    found = pipeline.bundle_stage(magone_design, magone_prediction, None, None, lambda *a, **k: None, {}).findings
    said = [f for f in found if f.code == "weigh-plan"]
    assert len(said) == 1 and said[0].severity is Severity.INFO and "calibrate from a scan" in said[0].message
