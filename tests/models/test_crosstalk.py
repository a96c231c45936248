"""The crosstalk budget: the neighbours' field against magpylib's superposition, the least pitch where the budget
crosses the tolerance, what polarity changes and what it does not, the skin's coupling against Boussinesq and under
mesh refinement, the magnets' force against dipoles far apart, and the findings."""

from __future__ import annotations

import json

import magpylib
import numpy as np
import pytest

from magfab import derive, parse_spec
from magfab.check import crosstalk_findings
from magfab.models import crosstalk as X
from magfab.models.mechanics.coupling import boussinesq_ratio, coupling
from magfab.models.taxels import field_at_chips
from magfab.units import UT_PER_GAUSS


@pytest.fixture(scope="module")
def strip(array_builds):
    b = array_builds["strip_1x5"]
    return b.design, b.prediction, json.loads((b.out_dir / "array" / "crosstalk.json").read_text())


@pytest.fixture(scope="module")
def strip_findings(array_builds):
    return json.loads((array_builds["strip_1x5"].out_dir / "findings.json").read_text())


def _layout(design):
    xy = np.array([[t.x_mm, t.y_mm] for t in design.taxels])
    return xy, np.array([float(t.polarity) for t in design.taxels])


@pytest.mark.parametrize("name", ["fingertip_2x2", "strip_1x5"])
def test_neighbours_field_is_magpylibs_superposition(array_builds, name):
    d = array_builds[name].design
    loads = X._Loads.of(d, array_builds[name].prediction)
    xy, signs = _layout(d)
    _, _, rest = X.layout_errors(loads, xy, signs)
    m = loads.magnet
    for i, (x, y) in enumerate(xy):
        mags = [magpylib.magnet.Cylinder(polarization=(0, 0, s * m.remanence_T),
                                         dimension=(2 * m.radius_mm, m.height_mm),
                                         position=(px, py, loads.z_centre)) for j, ((px, py), s) in
                enumerate(zip(xy, signs)) if j != i]
        B = magpylib.getB(mags, (x, y, loads.z_chip), sumup=True) * 1e4  # T -> G
        assert rest[i] == pytest.approx(B, abs=1e-3 * np.abs(B).max())
    # and the calibration's own superposition (models.taxels) agrees with the budget's
    table = field_at_chips(d) / UT_PER_GAUSS
    assert rest == pytest.approx(table.sum(axis=1) - np.einsum("iik->ik", table), abs=1e-9)


def test_the_least_pitch_is_where_the_budget_crosses_the_tolerance(strip, strip_findings):
    d, pred, doc = strip
    loads = X._Loads.of(d, pred)
    xy, signs = _layout(d)
    centre = xy.mean(axis=0)
    least, tol = doc["min_pitch_mm"]["same"], doc["tolerance_mN"]

    def worst(p):
        f, common, _ = X.layout_errors(loads, centre + (xy - centre) * p / d.array.pitch_mm, signs)
        return max(f.max(), common.max())

    assert worst(least * 1.002) <= tol < worst(least * 0.99)
    assert d.array.pitch_mm < least  # the example sits below it: hence the warning and the dynamic compensation
    assert doc["dynamic"] is True and doc["min_pitch_compensated_mm"]["same"] < least
    # with the compensation the strip is within tolerance wherever its tips fit: the parts set the least pitch, and
    # the info finding says so rather than give it as the crosstalk's figure
    assert doc["min_pitch_compensated_mm"]["same"] == doc["parts_min_pitch_mm"] == pytest.approx(d.array.min_pitch_mm)
    info = next(f["message"] for f in strip_findings if f["code"] == "array-crosstalk-budget")
    assert f"{d.array.min_pitch_mm:.1f} mm (the parts' minimum" in info
    assert f"without it: same polarity {least:.1f} mm" in info


def test_polarity_changes_every_neighbour_at_once_not_one_alone(array_builds):
    d = array_builds["fingertip_2x2"].design
    loads = X._Loads.of(d, array_builds["fingertip_2x2"].prediction)
    xy, _ = _layout(d)
    same, alternating = np.ones(4), np.array([1.0, -1.0, -1.0, 1.0])
    f_same, c_same, r_same = X.layout_errors(loads, xy, same)
    f_alt, c_alt, r_alt = X.layout_errors(loads, xy, alternating)
    assert f_alt == pytest.approx(f_same)  # one neighbour's misreading has the same size either way
    # in a checkerboard the two edge neighbours flip and the diagonal one does not: their lateral fields at rest
    # and their pressed changes partly cancel (about a third less at 10 mm), not halve
    assert np.all(np.hypot(r_alt[:, 0], r_alt[:, 1]) < 0.7 * np.hypot(r_same[:, 0], r_same[:, 1]))
    assert np.all(c_alt < 0.8 * c_same) and np.all(c_alt > 0.5 * c_same)
    # while the axial offset grows: an edge neighbour's Bz and the diagonal's have opposite signs at these distances
    assert np.all(np.abs(r_alt[:, 2]) > np.abs(r_same[:, 2]))
    # the least pitch is set by one neighbour sliding, so it is the same for both polarities
    doc = json.loads((array_builds["fingertip_2x2"].out_dir / "array" / "crosstalk.json").read_text())
    assert doc["min_pitch_mm"]["same"] == doc["min_pitch_mm"]["alternating"]


def test_the_magnets_push_the_strips_ends_out_or_pull_them_in(strip):
    d, pred, doc = strip
    loads = X._Loads.of(d, pred)
    xy, _same = _layout(d)
    net = np.array(doc["magnet_net_force_mN"])
    assert net[0, 0] < 0 < net[-1, 0] and net[0, 0] == pytest.approx(-net[-1, 0], rel=1e-3)
    assert abs(net[2, 0]) < 1e-3 and np.abs(net[:, 1]).max() < 1e-3  # the middle one is balanced; nothing across
    assert np.array(doc["predisplacement_mm"]) == pytest.approx(net / 1000 / loads.shear_stiffness_N_per_mm, abs=1e-5)
    alternating = X.magnet_forces(loads, xy, np.array([1.0, -1.0, 1.0, -1.0, 1.0]))
    assert alternating[0, 0] > 0 > alternating[-1, 0]  # unlike neighbours attract: the ends are pulled in


def test_the_host_compensation_removes_a_pressed_or_sliding_neighbour():
    d = derive(parse_spec('name = "pair"\n[array]\nrows = 1\ncols = 2\npitch_mm = 14'))
    from magfab.models.predict import predict

    loads = X._Loads.of(d, predict(d))
    xy, signs = _layout(d)
    from dataclasses import replace

    pressed = replace(loads, shear_travel_mm=1e-9)  # only the normal press
    raw = X.layout_errors(pressed, xy, signs)[0].max()
    left = X.compensated_errors(d, pressed, xy, signs)[0].max()
    assert left < raw / 100.0
    # slid through the whole shear travel (2.5 mm): the lateral tables and the spread moment keep up
    slid_raw, slid_left = X.layout_errors(loads, xy, signs)[0].max(), X.compensated_errors(d, loads, xy, signs)[0].max()
    assert slid_raw > 50.0 and slid_left < slid_raw / 100.0
    flipped = np.array([1.0, -1.0])  # and with the neighbour magnetised the other way
    assert X.compensated_errors(d, loads, xy, flipped)[0].max() < slid_raw / 100.0


def test_skin_coupling_against_boussinesq_and_under_refinement():
    r = np.array([2.0, 5.0, 10.0])
    thick = coupling(300.0, 2.6, 12.0)
    assert thick.at(r) == pytest.approx(boussinesq_ratio(r, 2.6), rel=0.06)
    coarse, fine = coupling(7.9, 2.6, 20.0, cell_mm=0.2), coupling(7.9, 2.6, 20.0, cell_mm=0.1)
    assert np.abs(coarse.at(r) - fine.at(r)).max() < 1e-3
    # bonded to the pad, a thin layer couples far less than a half-space, and rises between taxels (incompressible)
    assert abs(fine.at(10.0)) < boussinesq_ratio(np.array([10.0]), 2.6)[0] / 4 and fine.at(10.0) < 0


def test_magnet_force_tends_to_the_dipoles_far_apart(strip):
    d, pred, _ = strip
    loads = X._Loads.of(d, pred)
    near_dip, near_exact = X._magnet_force(loads, 10.0, True)
    far_dip, far_exact = X._magnet_force(loads, 40.0, True)
    assert far_exact == pytest.approx(far_dip, rel=0.02) and near_exact > near_dip > 0
    assert X._magnet_force(loads, 10.0, False)[1] == pytest.approx(-near_exact)


def test_findings_warn_below_the_least_pitch_only(array_builds):
    skin = {f.code: f for f in array_builds["fingertip_2x2"].findings}
    strip = {f.code: f for f in array_builds["strip_1x5"].findings}
    # the skin at 10 mm: a load on one taxel moves its neighbours' magnets (26 mN read), past the 3.7 mN tolerance
    assert skin["array-crosstalk"].key == "array.pitch_mm" and "array-crosstalk-budget" in skin
    # the strip of separate tips at 14 mm: the compensation leaves a fraction of a millinewton
    assert "array-crosstalk" not in strip and "array-crosstalk-budget" in strip


@pytest.fixture(scope="module")
def close_pair():
    from magfab.models.predict import predict

    d = derive(parse_spec('name = "close"\n[array]\nrows = 1\ncols = 2\npitch_mm = 7\nskin = "continuous"\n'
                          'polarity = "alternating"'))
    return d, X.crosstalk(d, predict(d))


def test_the_charts_are_the_same_bytes_twice(close_pair):
    from magfab.export.crosstalk_figures import figures

    first, second = figures(close_pair[1]), figures(close_pair[1])
    assert sorted(first) == sorted(f"{n}.{k}" for n in ("crosstalk_map", "crosstalk_pitch", "skin_coupling")
                                   for k in ("png", "svg"))
    assert first == second


def test_close_magnets_in_a_skin_warn_of_their_pull(close_pair):
    from magfab.models.predict import predict

    d, xt = close_pair
    found = {f.code: f for f in crosstalk_findings(d, xt)}
    assert xt.force_exact_mN < 0 and xt.predisplacement_mm[0, 0] > 0.1 * xt.shear_travel_mm  # pulled together
    assert found["array-magnet-force"].key == "array.pitch_mm" and "pull" in found["array-magnet-force"].message
    assert found["array-crosstalk"].key == "array.pitch_mm" and "array-saturation" not in found
    # four magnets of one polarity 5.5 mm apart (the least a skin allows) add 108 G to a chip whose own magnet at
    # d_min already reads 995 G: past the 1065 G full scale; at 10 mm they add 3 G
    loads = X._Loads.of(d, predict(d))
    own = X.fieldmod.exact(loads.magnet, np.array([[0.0, 0.0, -(d.spec.sensor.d_min_mm + loads.magnet.height_mm / 2)]]))
    square = np.array([[-1.0, 1.0], [1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]]) / 2
    for pitch, over in ((5.5, True), (10.0, False)):
        rest = X.layout_errors(loads, square * pitch, np.ones(4))[2]
        assert bool(own[0, 2] + rest[:, 2].max() > xt.full_scale_G) is over
    from dataclasses import replace

    hot = crosstalk_findings(d, replace(xt, saturation_G=own[0, 2] + rest[:, 2].max() + 110.0))
    assert [f.key for f in hot if f.code == "array-saturation"] == ["sensor.d_min_mm"]

