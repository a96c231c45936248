"""The reference chip's site and rejection (magfab/models/reference.py), checked against magpylib's own objects."""

from __future__ import annotations

import magpylib as magpy
import numpy as np
import pytest

from magfab.check import reference_findings
from magfab.models import reference as ref
from magfab.models.chip import chip_setting, noise
from magfab.models.crosstalk import _Loads
from magfab.reference_chip import reference_chip


def test_the_dipole_is_magpylibs():
    from magfab.models.drift import dipole_field_G

    rng = np.random.default_rng(3)
    for _ in range(5):
        m, at, p = rng.normal(size=3), rng.normal(size=3) * 40, rng.normal(size=3) * 40
        mine = dipole_field_G(m, at, p)
        theirs = magpy.misc.Dipole(moment=m, position=at / 1000).getB(p / 1000) * 1e4  # T -> G
        assert np.allclose(mine, theirs, rtol=1e-9, atol=1e-12)


def _changes_magpylib(design, pred, xy):
    """The largest change (xy, z) at the point as the magnet is pressed or slid, by magpylib's Cylinder."""
    loads = _Loads.of(design, pred)
    travel = ref.Travel.predicted(design, pred)
    assert travel.normal_mm == loads.normal_travel_mm and travel.shear_mm == loads.shear_travel_mm
    m = loads.magnet
    cyl = magpy.magnet.Cylinder(polarization=(0, 0, m.remanence_T),
                                dimension=(2 * m.radius_mm / 1000, m.height_mm / 1000))
    point = np.array([xy[0], xy[1], design.z_sense_mm]) / 1000
    centre = np.array([0.0, 0.0, loads.z_centre])
    moves = [(0, 0, -loads.normal_travel_mm)] + [(sx * loads.shear_travel_mm, sy * loads.shear_travel_mm, 0)
                                                  for sx, sy in ((1, 0), (-1, 0), (0, 1), (0, -1))]
    cyl.position = centre / 1000
    rest = cyl.getB(point) * 1e4
    worst = np.zeros(2)
    for mv in moves:
        cyl.position = (centre + mv) / 1000
        d = cyl.getB(point) * 1e4 - rest
        worst = np.maximum(worst, [np.hypot(d[0], d[1]), abs(d[2])])
    return worst


def test_the_site_is_the_nearest_point_where_the_magnet_moves_under_the_noise(design, pred):
    site = ref.site(design, ref.Travel.predicted(design, pred), span_C=20.0)
    n = noise(design, chip_setting(design))
    limit = np.array([n["total_xy_G"], n["total_z_G"]])
    assert np.all(_changes_magpylib(design, pred, site.xy_mm) <= limit * (1 + 1e-6))
    closer = (site.xy_mm[0], site.xy_mm[1] - 1.0)
    assert np.any(_changes_magpylib(design, pred, closer) > limit)
    assert site.xy_mm[0] == 0.0 and site.separation_mm == pytest.approx(site.xy_mm[1])
    assert np.all(np.array(site.thermal_G) < limit)
    bound = ref.site(design, ref.Travel.bound(design), span_C=20.0)  # what the board places by: never nearer
    assert bound.separation_mm >= site.separation_mm and ref.Travel.bound(design).shear_mm >= travel_shear(design, pred)


def travel_shear(design, pred):
    return ref.Travel.predicted(design, pred).shear_mm


def test_a_fixed_distance_reports_how_loud_the_magnet_is_there(design, pred):
    near = ref.site(design, ref.Travel.predicted(design, pred), span_C=20.0, distance_mm=15.0)
    n = noise(design, chip_setting(design))
    assert near.separation_mm == 15.0 and max(near.motion_G) > 10 * n["total_z_G"]


def test_rejection_uniform_from_the_datasheet_bounds_and_a_dipole_by_its_gradient(design, pred):
    site = ref.site(design, ref.Travel.bound(design), span_C=20.0)
    rej = ref.rejection(design, site, distances_mm=(30.0, 3000.0, 10000.0))
    assert rej.uniform == pytest.approx(1 / (0.06 + 0.01))
    near, far, farther = rej.dipole
    assert near < 1.0  # a motor about as far as the reference: subtracting it can make things worse
    s = site.separation_mm
    # far away: the gradient, D / (3 s) on the axis, a bit less off it
    for d, r in zip((3000.0, 10000.0), (far, farther)):
        assert 0.6 * d / (3 * s) < r < 1.1 * d / (3 * s)
    assert farther > far > near and all(m >= w for m, w in zip(rej.dipole_median, rej.dipole))
    assert rej.noise_growth == pytest.approx(np.sqrt(1 + 1 / 15))


def test_the_prediction_carries_the_reference_budget(pred):
    """predictions.json's reference section and its findings; the session's MagOne prediction stands for the same
    spec with [reference] (the reference chip changes no part of the prediction); predict() wiring it is
    tests/export/test_simbus_reference.py's setup."""
    from magfab import derive, parse_spec
    from magfab.models import drift

    design = derive(parse_spec("[reference]\n[environment]\nstray_moment_Am2 = 0.5\nstray_distance_mm = 300\n"))
    section = ref.budget(design, pred, drift.drift(design, pred), reference_chip(design))
    assert section["quiet"] and section["chip"]["designator"] == "U2"
    rot = section["rotation"]
    ratio = section["rejection"]["uniform"]
    assert abs(rot["with"]["normal_rest_mN"]) == pytest.approx(abs(rot["without"]["normal_rest_mN"]) / ratio, rel=0.05)
    stray = section["stray"]
    assert abs(stray["with_median"]["normal_rest_mN"]) < abs(stray["without"]["normal_rest_mN"])
    info = reference_findings(design, section)
    assert [f.code for f in info] == ["reference"] and "14x" in info[0].message
    loud = derive(parse_spec("[reference]\ndistance_mm = 12\n"))
    found = reference_findings(loud, ref.budget(loud, pred, drift.drift(loud, pred), reference_chip(loud)))
    assert [(f.code, f.key) for f in found] == [("reference-loud", "reference.distance_mm")]
