"""Physics of magfab.models.field: closed forms, limits and their rates, invariants, and the edges where each
model is known to fail (each must raise FieldModelError, not return a number).

References: a direct quadrature of the cylinder's surface charges (scipy, written here) for the exact field,
which is then the reference of the others; magpylib's Cylinder class as a second one. MagOne magnet D = 5 mm,
H = 2 mm, N35 (Br 1.195 T), working volume d = 2..6 mm below the lower face, r = 0..R.
"""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from magfab import load_spec
from magfab.models import field as F
from magfab.models.field.surrogate import _build_table

MAGONE = F.Magnet.from_spec(load_spec(None))
D_MIN, D_MAX = 2.0, 6.0


def rel(a, b):
    """Pointwise relative vector error |a - b| / |b|."""
    a, b = np.atleast_2d(a), np.atleast_2d(b)
    return np.linalg.norm(a - b, axis=1) / np.linalg.norm(b, axis=1)


def along(direction, distances):
    """Points at the given distances (mm) from the centre along a direction."""
    u = np.asarray(direction, float) / np.linalg.norm(direction)
    return np.outer(distances, u)


def test_magone_from_spec():
    assert (MAGONE.radius_mm, MAGONE.height_mm, MAGONE.remanence_T) == (2.5, 2.0, 1.195)
    assert MAGONE.aspect == pytest.approx(0.8)
    assert MAGONE.moment_A_m2 == pytest.approx(1.195 * math.pi * 2.5**2 * 2e-9 / (4e-7 * math.pi))


@pytest.mark.parametrize("bad", [0.0, -1.0, math.nan, math.inf, True, "2"])
def test_magnet_rejects_bad_numbers(bad):
    with pytest.raises(ValueError, match="radius_mm must be a positive finite number"):
        F.Magnet(bad, 2.0, 1.2)


# ---- closed forms ---------------------------------------------------------------------------------


def test_m6_matches_magpylib_on_the_axis():
    z = np.concatenate([-(1.0 + np.geomspace(0.01, 50.0, 60)), 1.0 + np.geomspace(0.01, 50.0, 60)])
    pts = np.column_stack([np.zeros_like(z), np.zeros_like(z), z])
    b = F.on_axis(MAGONE, pts)
    ref = F.magpylib_cylinder(MAGONE, pts)
    assert np.all(b[:, :2] == 0)
    assert np.max(rel(b, ref)) < 1e-9


def test_m6_as_printed_in_docs_models():
    """docs/models.md, M6, with z measured from the pole face, below the magnet, is what axis_bz returns."""
    R, H, br = 2.5, 2.0, 1.195e4
    for zf in (0.1, 2.0, 6.0, 20.0):
        printed = br / 2 * ((zf + H) / math.hypot(zf + H, R) - zf / math.hypot(zf, R))
        assert F.axis_bz(MAGONE, -(H / 2 + zf)) == pytest.approx(printed, rel=1e-12)


def charge_sheets(magnet, point):
    """B in G at ``point`` (mm) by direct quadrature of the equivalent surface charges: an axially magnetised
    cylinder is a disc of charge +Br/mu0 on its upper face and -Br/mu0 on its lower one, so outside it
    B = Br/(4 pi) [integral over the upper disc - over the lower] of (x - x') / |x - x'|^3 dA'. Independent of
    the elliptic-integral form (and of magpylib): only scipy's adaptive quadrature."""
    from scipy import integrate

    R, h, br = magnet.radius_mm, magnet.height_mm / 2.0, magnet.remanence_T * 1e4
    x, y, z = point
    r = math.hypot(x, y)
    radial = lambda rp, ph, dz: r - rp * math.cos(ph)
    axial = lambda rp, ph, dz: dz
    b = np.zeros(2)
    for z_face, sign in ((h, 1.0), (-h, -1.0)):
        dz = z - z_face
        for k, comp in enumerate((radial, axial)):
            def f(ph, rp, comp=comp, dz=dz):  # bound: dblquad calls it in this iteration
                return rp * comp(rp, ph, dz) / (r * r + rp * rp - 2.0 * r * rp * math.cos(ph) + dz * dz) ** 1.5
            val, _ = integrate.dblquad(f, 0.0, R, 0.0, math.pi, epsabs=1e-13, epsrel=1e-10)
            b[k] += sign * 2.0 * val  # the half-disc 0..pi, mirrored
    brho, bz = b * br / (4.0 * math.pi)
    q = brho / r if r > 0 else 0.0
    return np.array([q * x, q * y, bz])


@pytest.mark.parametrize("point", [
    (0.0, 0.0, -3.0),  # on the axis, 2 mm below the face
    (1.0, 0.5, -4.0),  # the working volume, off the axis
    (2.0, -1.0, -7.0),  # its far corner, r = 0.9 R
    (2.5, 0.0, -1.5),  # straight below the rim
    (3.5, 0.0, 0.0),  # beside the magnet, in the mid-plane (Bz < 0 there)
    (3.0, 1.0, 2.0),  # above and outside
    (0.3, 0.2, 1.6),  # above, near the axis
])
def test_exact_matches_a_direct_quadrature_of_the_charge_sheets(point):
    want = charge_sheets(MAGONE, point)
    assert rel(F.exact(MAGONE, point), want)[0] < 1e-9
    assert rel(F.magpylib_cylinder(MAGONE, point), want)[0] < 1e-9  # the class interface, too


def test_axis_gradient_is_the_derivative_of_m6():
    z = -(1.0 + np.linspace(0.5, 30.0, 40))
    h = 1e-4
    fd = (F.axis_bz(MAGONE, z + h) - F.axis_bz(MAGONE, z - h)) / (2 * h)
    assert np.allclose(F.axis_dbz_dz(MAGONE, z), fd, rtol=1e-7)
    fd2 = (F.axis_dbz_dz(MAGONE, z + h) - F.axis_dbz_dz(MAGONE, z - h)) / (2 * h)
    assert np.allclose(F.axis_dbz_dz(MAGONE, z, 2), fd2, rtol=1e-6)
    assert np.all(F.axis_dbz_dz(MAGONE, z) > 0)  # below the magnet Bz grows towards it


def test_multipoles_reproduce_m6_far_on_the_axis():
    A = F.axial_multipoles(MAGONE, 5)
    assert A[1] == pytest.approx(1.195e4 * 2.5**2 * 2.0 / 4)  # Br R^2 H / 4 = mu0 m / 4 pi
    assert A[3] / A[1] == pytest.approx(1.0 - 0.75 * 2.5**2)  # h^2 - 3 R^2 / 4
    for z in (20.0, 50.0, 200.0):
        series = sum((order + 1) * A[order] / z ** (order + 2) for order in (1, 3, 5))
        assert series == pytest.approx(float(F.axis_bz(MAGONE, z)), rel=3 * (2.7 / z) ** 6)


# ---- dipole: far away it is right, and how fast; near the magnet it refuses ----------------------


def test_dipole_error_falls_as_distance_squared():
    D = np.geomspace(25.0, 400.0, 5)  # 10 R .. 160 R
    for direction in ([0, 0, -1], [1, 0, -1], [1, 1, -0.2]):
        pts = along(direction, D)
        err = rel(F.dipole(MAGONE, pts, rtol=None), F.exact(MAGONE, pts))
        slope = np.polyfit(np.log(D), np.log(err), 1)[0]
        assert slope == pytest.approx(-2.0, abs=0.02)
        # the next-multipole estimate is asymptotically exact
        assert np.allclose(F.dipole_error_estimate(MAGONE, pts)[-2:], err[-2:], rtol=0.01)


def test_dipole_special_aspect_has_no_octupole():
    """At H = sqrt(3) R the l = 3 term vanishes: the dipole error falls as D^-4 instead."""
    magnet = F.Magnet(1.0, math.sqrt(3.0), 1.0)
    D = np.geomspace(10.0, 80.0, 4)
    pts = along([1, 0.5, -2], D)
    err = rel(F.dipole(magnet, pts, rtol=None), F.exact(magnet, pts))
    assert np.polyfit(np.log(D), np.log(err), 1)[0] == pytest.approx(-4.0, abs=0.05)


def test_dipole_refuses_near_the_magnet():
    inside_sphere = np.array([[0.0, 0.0, -1.5]])  # outside the magnet, inside r = 2.69 mm
    assert np.isinf(F.dipole_error_estimate(MAGONE, inside_sphere)).all()
    with pytest.raises(F.FieldModelError, match=r"too close to the magnet.*unbounded"):
        F.dipole(MAGONE, inside_sphere)
    near = F.working_volume(MAGONE, D_MIN, D_MAX, 8)  # 20-100 % wrong there
    with pytest.raises(F.FieldModelError, match=r"dipole: \d+ of 64 points"):
        F.dipole(MAGONE, near)
    assert F.model_error("dipole", MAGONE, near).relative > 0.2  # measured anyway with rtol=None
    far = along([1, 2, -3], [400.0])
    assert rel(F.dipole(MAGONE, far), F.exact(MAGONE, far))[0] < 1e-3


# ---- the on-axis form off the axis ---------------------------------------------------------------


def test_on_axis_error_grows_off_the_axis_and_is_detected():
    r = np.geomspace(1e-3, 0.25, 8)
    pts = np.column_stack([r, np.zeros_like(r), np.full_like(r, -(1.0 + 6.0))])
    err = rel(F.on_axis(MAGONE, pts, rtol=None), F.exact(MAGONE, pts))
    assert np.polyfit(np.log(r), np.log(err), 1)[0] == pytest.approx(1.0, abs=0.02)  # ~ r/2 |Bz'|/Bz
    assert np.allclose(F.on_axis_error_estimate(MAGONE, pts), err, rtol=0.01)
    ok = pts[err < 0.5e-3]
    assert len(ok) and np.array_equal(F.on_axis(MAGONE, ok)[:, 2], F.on_axis(MAGONE, ok, rtol=None)[:, 2])
    with pytest.raises(F.FieldModelError, match="too far off the axis"):
        F.on_axis(MAGONE, pts)
    with pytest.raises(F.FieldModelError, match="off the axis"):
        F.bz_br(MAGONE, 6.0, 1.0, model="on_axis")


# ---- exact: inside, on the surface and at the rim ------------------------------------------------


@pytest.mark.parametrize("point", [
    (0.0, 0.0, 0.0),  # centre
    (2.5, 0.0, 0.0),  # side face
    (0.0, 0.0, -1.0),  # lower face, on the axis
    (1.0, 1.0, 1.0),  # upper face
    (2.5, 0.0, -1.0),  # rim
    (0.0, 2.5 * (1 + 1e-7), -1.0),  # 1e-7 R from the rim
    (0.0, 0.0, -1.0 - 1e-7),  # 4e-8 R below the face
])
@pytest.mark.parametrize("model", ["exact", "on_axis", "dipole", "surrogate"])
def test_every_model_refuses_points_in_or_on_the_magnet(point, model):
    with pytest.raises(F.FieldModelError, match=f"{model}: 1 of 2 points"):
        F.MODELS[model].func(MAGONE, [point, (0.0, 0.0, -7.0)], rtol=None)


def test_exact_near_the_rim_is_finite_and_continuous():
    """The elliptic form holds right up to the rim (the log singularity is in B, not in the numerics)."""
    eps = np.geomspace(1e-5, 1e-2, 7) * 2.5
    below = np.column_stack([2.5 + 0 * eps, 0 * eps, -1.0 - eps])  # straight below the rim
    b = F.exact(MAGONE, below)
    assert np.isfinite(b).all()
    # B_rho ~ -(Br_rem / 2 pi) ln(R / eps) near the edge, as at the edge of a charged half-plane
    steps = np.diff(b[:, 0]) / np.diff(np.log(eps))
    assert np.allclose(steps[:3], 1.195e4 / (2 * math.pi), rtol=1e-3)
    side = np.array([[2.5 + 1e-9, 0.0, -2.0], [2.5 - 1e-9, 0.0, -2.0]])  # across r = R below the face
    b2 = F.exact(MAGONE, side)
    assert np.allclose(b2[0], b2[1], rtol=1e-6)


def test_exact_on_the_axis_has_no_radial_field():
    z = np.linspace(-8, -1.1, 20)
    on = np.column_stack([0 * z, 0 * z, z])
    near = np.column_stack([1e-12 + 0 * z, 0 * z, z])
    b_on, b_near = F.exact(MAGONE, on), F.exact(MAGONE, near)
    assert np.all(b_on[:, :2] == 0)
    assert np.allclose(b_on[:, 2], b_near[:, 2], rtol=1e-14)


# ---- far-field cancellation ----------------------------------------------------------------------


def test_far_field_cancellation_is_detected_and_avoided():
    z = -np.geomspace(25.0, 2.5e5, 9)  # 10 R .. 10^5 R
    pts = np.column_stack([0 * z, 0 * z, z])
    stable = F.axis_bz(MAGONE, z)
    dip = F.dipole(MAGONE, pts, rtol=None)[:, 2]
    # the cancellation-free axial form (M6) tends to the dipole at the dipole's own rate, to the farthest point
    assert np.allclose(stable[-3:], dip[-3:], rtol=1e-8)
    # the elliptic form loses digits as D^3; its estimate of that is an upper one
    raw = F.exact(MAGONE, pts, rtol=None)[:, 2]
    actual = np.abs(raw / stable - 1)
    assert actual[-1] > 1e-3  # at 10^5 R the elliptic form is wrong in the 3rd digit or worse
    estimate = F.exact_rounding_estimate(MAGONE, pts)
    assert np.all(actual <= estimate + 1e-15) and np.all(actual[-4:] > estimate[-4:] / 50)
    with pytest.raises(F.FieldModelError, match=r"cancellation.*use the dipole"):
        F.exact(MAGONE, pts)
    F.exact(MAGONE, pts[z > -1000.0])  # within ~400 R the default rtol is met


def test_relative_error_survives_bz_crossing_zero():
    """Off the axis near the face Bz changes sign: a component-wise relative error explodes there,
    the vector one (and the normalised one) stay small."""
    from scipy.optimize import brentq

    d = 0.5
    r0 = brentq(lambda r: float(F.bz_br(MAGONE, d, r)[0]), 2.6, 5.0)
    pts = np.array([[r0, 0.0, -(1.0 + d)], [r0 * 0.6, r0 * 0.8, -(1.0 + d)]])
    b, ref = F.surrogate(MAGONE, pts), F.exact(MAGONE, pts)
    assert abs(ref[0, 2]) < 1e-9 * np.linalg.norm(ref[0])
    assert abs(b[0, 2] - ref[0, 2]) / abs(ref[0, 2]) > 1e3  # component-wise: meaningless
    err = F.model_error("surrogate", MAGONE, pts)
    assert err.relative < F.SURROGATE_BUILD_RTOL and err.normalised <= err.relative


# ---- invariants ----------------------------------------------------------------------------------


@pytest.mark.parametrize("model", ["exact", "surrogate", "dipole", "on_axis"])
def test_scaling_all_lengths_leaves_b_unchanged(model):
    pts = F.working_volume(MAGONE, D_MIN, D_MAX, 7, r_max_mm=0.0 if model == "on_axis" else None)
    f = F.MODELS[model].func
    b = f(MAGONE, pts, rtol=None)
    for k in (1e-3, 0.37, 40.0):
        big = F.Magnet(2.5 * k, 2.0 * k, 1.195)
        assert np.allclose(f(big, pts * k, rtol=None), b, rtol=1e-12, atol=1e-12 * np.abs(b).max())


@pytest.mark.parametrize("model", ["exact", "surrogate", "dipole"])
def test_symmetries(model):
    f = lambda p: F.MODELS[model].func(MAGONE, p, rtol=None)
    pts = F.working_volume(MAGONE, D_MIN, D_MAX, 9)
    b = f(pts)
    # Bx / By = x / y: the transverse field is radial
    assert np.allclose(b[:, 0] * pts[:, 1], b[:, 1] * pts[:, 0], atol=1e-9 * np.abs(b).max())
    # rotation about z commutes with the field
    a = 0.7
    rot = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    assert np.allclose(f(pts @ rot.T), b @ rot.T, rtol=1e-10, atol=1e-10 * np.abs(b).max())
    # mirror in the mid-plane: Bz even, (Bx, By) odd
    m = f(pts * [1, 1, -1])
    assert np.allclose(m * [-1, -1, 1], b, rtol=1e-12, atol=1e-12 * np.abs(b).max())


# ---- surrogate ------------------------------------------------------------------------------------


def test_surrogate_magone_working_volume():
    pts = F.working_volume(MAGONE, D_MIN, D_MAX, 60)
    assert np.max(rel(F.surrogate(MAGONE, pts), F.magpylib_cylinder(MAGONE, pts))) < 1e-4


@pytest.mark.parametrize("h_over_d", [0.2, 0.35, 0.5, 0.75, 1.0])
def test_surrogate_other_aspect_ratios(h_over_d):
    magnet = F.Magnet(1.5, 3.0 * h_over_d, 1.3)
    pts = F.working_volume(magnet, 0.4 * 3.0, 2 * 3.0, 40)  # d from 0.4 D (near) to 2 D (guideline max)
    assert F.model_error("surrogate", magnet, pts).relative < 1e-3
    # the table's self-check bounds its error anywhere in its domain
    t = F.surrogate_table(magnet.aspect)
    d = t.domain
    rng = np.random.default_rng(7)
    n = 20000
    rho = 1.5 * d.rho_max * np.sqrt(rng.uniform(0, 1, n))
    gap = 1.5 * np.exp(rng.uniform(math.log(d.gap_min), math.log(d.gap_max), n))
    phi = rng.uniform(0, 2 * math.pi, n)
    side = rng.choice([-1.0, 1.0], n)
    anywhere = np.column_stack([rho * np.cos(phi), rho * np.sin(phi), side * (magnet.height_mm / 2 + gap)])
    assert F.model_error("surrogate", magnet, anywhere).relative <= t.max_error * 1.05
    assert t.max_error < F.SURROGATE_BUILD_RTOL


def test_surrogate_refuses_outside_its_table_and_beyond_its_accuracy():
    R = MAGONE.radius_mm
    for p in [(2.01 * R, 0, -7.0), (0, 0, -(1.0 + 0.19 * R)), (0, 0, -(1.0 + 10.1 * R)), (0, 0, 1.0 + 11 * R)]:
        with pytest.raises(F.FieldModelError, match=r"surrogate: 1 of 2 points.*outside its table"):
            F.surrogate(MAGONE, [p, (0.0, 0.0, -7.0)])
    edge = [(2 * R, 0, -(1.0 + 0.2 * R)), (0, 0, 1.0 + 10 * R)]  # the table's own corners are inside
    assert np.isfinite(F.surrogate(MAGONE, edge)).all()
    with pytest.raises(F.FieldModelError, match="table is good to"):
        F.surrogate(MAGONE, [(0, 0, -7.0)], rtol=1e-6)


def test_surrogate_is_deterministic():
    pts = F.working_volume(MAGONE, D_MIN, D_MAX, 30)
    first = F.surrogate_table(MAGONE.aspect)
    b1 = F.surrogate(MAGONE, pts)
    _build_table.cache_clear()
    second = F.surrogate_table(MAGONE.aspect)
    assert second is not first
    assert np.array_equal(first.coef, second.coef) and first.max_error == second.max_error
    assert np.array_equal(F.surrogate(MAGONE, pts), b1)
    # nearby aspects share a table
    assert F.surrogate_table(0.8 * (1 + 1e-12)) is F.surrogate_table(0.8)


def test_single_point_and_bad_input():
    b = F.exact(MAGONE, (0.0, 0.0, -7.0))
    assert b.shape == (3,) and b[2] > 0
    assert np.allclose(F.surrogate(MAGONE, (0.0, 0.0, -7.0)), b, rtol=1e-4)
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        F.exact(MAGONE, np.zeros((4, 2)))
    with pytest.raises(ValueError, match="finite"):
        F.dipole(MAGONE, [(0.0, 0.0, math.nan)])


# ---- the sensor's view and model choice ----------------------------------------------------------


def test_bz_br_signs_and_the_brief_on_br():
    bz, br = F.bz_br(MAGONE, [2.0, 6.0], 0.0)
    assert np.all(bz > 0) and np.all(br == 0)
    assert bz[0] > bz[1]
    r = np.linspace(0, MAGONE.radius_mm, 26)
    for d in np.linspace(D_MIN, D_MAX, 5):
        _, br = F.bz_br(MAGONE, d, r)
        assert np.all(np.diff(br) > 0)  # Br grows over the whole lateral travel: r is unambiguous
    r = np.linspace(0, 2 * MAGONE.radius_mm, 201)
    _, br = F.bz_br(MAGONE, D_MIN, r)
    assert r[np.argmax(br)] == pytest.approx(MAGONE.radius_mm, rel=0.05)  # "rises up to about R_m"
    # below the magnet the radial field points at the axis
    assert F.exact(MAGONE, (1.0, 0.0, -4.0))[0] < 0


def test_dbz_dz():
    d = np.array([2.0, 4.0, 6.0])
    analytic = F.dbz_dz(MAGONE, d, model="on_axis")
    assert np.all(analytic > 0)
    assert np.allclose(F.dbz_dz(MAGONE, d), analytic, rtol=1e-8)
    assert np.allclose(F.dbz_dz(MAGONE, d, model="surrogate"), analytic, rtol=2e-3)
    # = -dBz/dd
    h = 1e-4
    bz = lambda dd: F.bz_br(MAGONE, dd, 1.0)[0]
    assert F.dbz_dz(MAGONE, 4.0, 1.0) == pytest.approx(-(bz(4.0 + h) - bz(4.0 - h)) / (2 * h), rel=1e-7)


def test_choose_picks_the_cheapest_model_within_tolerance():
    volume = F.working_volume(MAGONE, D_MIN, D_MAX, 24)
    c = F.choose(MAGONE, volume, 1e-3)
    assert c.model == "surrogate" and c.error < 1e-4
    assert [name for name, _ in c.tried] == ["on_axis", "dipole", "surrogate"]
    assert all(err > 1e-3 for _, err in c.tried[:2])
    axis = F.working_volume(MAGONE, D_MIN, D_MAX, 24, r_max_mm=0.0)
    assert F.choose(MAGONE, axis, 1e-6).model == "on_axis"
    far = F.working_volume(MAGONE, 200.0, 600.0, 8)
    assert F.choose(MAGONE, far, 1e-3).model == "dipole"
    tight = F.choose(MAGONE, volume, 1e-6)
    assert (tight.model, tight.error) == ("exact", 0.0)
    assert F.choose(MAGONE, volume, 1e-3) == c  # deterministic
    with pytest.raises(ValueError, match="tolerance must be positive"):
        F.choose(MAGONE, volume, 0.0)


def test_measure_reports_every_model():
    rows = F.measure(MAGONE, D_MIN, D_MAX, n=12, repeat=1)
    by = {r.model: r for r in rows}
    assert list(by) == ["magpylib", "on_axis", "dipole", "surrogate", "exact"]
    assert by["exact"].relative_error < 1e-12
    assert by["surrogate"].relative_error < 1e-4
    assert by["dipole"].relative_error > 0.2 and by["on_axis"].relative_error > 0.5
    assert all(r.time_per_1e5_s > 0 and r.speedup_vs_magpylib > 0 for r in rows)


def test_import_is_cheap():
    code = "import sys, magfab.models.field; print(sorted(m for m in ('magpylib', 'matplotlib') if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_models_are_named_by_the_spec_enum_and_refusals_are_model_limits():
    from magfab.errors import ModelLimitError
    from magfab.spec import FieldModel

    by_enum = F.bz_br(MAGONE, 4.0, 1.0, model=FieldModel.SURROGATE)
    assert by_enum == F.bz_br(MAGONE, 4.0, 1.0, model="surrogate")
    assert by_enum[0] != F.bz_br(MAGONE, 4.0, 1.0, model="dipole", rtol=None)[0]
    assert F.model_error(FieldModel.DIPOLE, MAGONE, [(0.0, 0.0, -30.0)]).relative > 0
    for bad in ("auto", FieldModel.AUTO, "magic"):
        with pytest.raises(ValueError, match="model must be one of on_axis, dipole, surrogate, exact"):
            F.dbz_dz(MAGONE, 4.0, model=bad)
    with pytest.raises(ModelLimitError):
        F.exact(MAGONE, (0.0, 0.0, 0.0))
