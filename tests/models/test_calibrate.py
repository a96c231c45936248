"""Calibration (docs/models.md, M12 to M14; docs/bundle.md): the scan CSV round trip, the simulated scan's physics,
the fit's errors against the injected noise, conditioning, the guard, calibration.json round trips and M14's
direction split (a law: rotating the scan rotates the forces)."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab import derive, parse_spec
from magfab.export.calibration_chart import chart
from magfab.formats import scan_csv as scan_format
from magfab.formats.scan_csv import read_scan_csv, scan_csv
from magfab.models import calibration as C
from magfab.models import field as F
from magfab.models.chip import chip_setting, noise
from magfab.models.region import _cross
from magfab.models.scan import scan_track, simulate_scan
from magfab.units import UT_PER_GAUSS

#: The neo-Hookean law, which this module's MagOne uses (:func:`design`).
NH = '[predict]\nmaterial_law = "neo-hookean"\n'


@pytest.fixture(scope="module")
def design(magone_neo_hookean):
    """MagOne with the neo-Hookean law: its range, and so its scan, ends at 1.6 N, where an order-4 polynomial sits on
    the noise floor; the default (Yeoh) scan reaches 4.9 N, past what order 4 fits to the noise
    (:func:`test_the_default_scan_is_fitted_within_its_tolerance`)."""
    return magone_neo_hookean[0]


@pytest.fixture(scope="module")
def pred(magone_neo_hookean):
    return magone_neo_hookean[1]


@pytest.fixture(scope="module")
def scan(design, pred):
    return simulate_scan(design, pred)


@pytest.fixture(scope="module")
def ideal(design, pred):
    return simulate_scan(design, pred, ideal=True)


@pytest.fixture(scope="module")
def result(design, scan):
    """The default (auto) fit, MLS included."""
    return C.fit(scan, design)


@pytest.fixture(scope="module")
def poly4(pred, scan):
    """The order-4 polynomial the paper used (method 'poly')."""
    return C.fit(scan, derive(parse_spec(NH + '[calibration]\nmethod = "poly"\norder = 4\n')), mls=False)


# ---- the scan CSV ---------------------------------------------------------------------------------


def test_csv_round_trip_is_exact(scan):
    text = scan_csv(scan)
    back = read_scan_csv(text)
    assert np.array_equal(back.time_s, scan.time_s) and np.array_equal(back.B_uT, scan.B_uT)
    assert np.array_equal(back.F_N, scan.F_N) and back.temperature_C is None
    assert back.sha256 == scan.sha256  # a simulated scan's hash is its CSV's


def test_csv_any_column_order_extra_columns_comments_and_temperature(scan, tmp_path):
    n = 60
    t = np.linspace(20.0, 21.0, n)
    s = C.Scan(scan.time_s[:n], scan.B_uT[:n], scan.F_N[:n], t, "x")
    lines = scan_csv(s, comments=["spec magone", "chip gain 0"]).splitlines()
    assert lines[0] == "# spec magone" and lines[2].startswith("time_s,Bx_uT")
    header = lines[2].split(",")
    order = list(reversed(range(len(header))))
    shuffled = [",".join([header[i] for i in order] + ["note"])]
    shuffled += [",".join([row.split(",")[i] for i in order] + ["free text"]) for row in lines[3:]]
    path = tmp_path / "scan.csv"
    path.write_text("\n".join(lines[:2] + shuffled) + "\n", encoding="utf-8")
    back = read_scan_csv(path)
    assert back.source == "scan.csv" and back.rows == n
    assert np.array_equal(back.temperature_C, t) and np.array_equal(back.B_uT, s.B_uT)
    assert np.array_equal(back.F_N, s.F_N)
    rec = read_scan_csv(scan_csv(C.Scan(s.time_s, s.B_uT, None)), require_force=False)
    assert rec.F_N is None and rec.rows == n


# ---- the simulated scan ---------------------------------------------------------------------------


def test_simulated_track_is_the_papers_y_z_raster(design, pred, scan):
    y, delta = scan_track(design, pred)
    cal = design.spec.calibration
    nominal = pred.curves["nominal"]
    delta_end = np.interp(pred.as_json()["normal"]["travel_mm"], nominal.magnet_displacement_mm, nominal.indentation_mm)
    ny = round(cal.scan_y_mm / cal.scan_step_mm) + 1  # MagOne: +-2 mm is inside the lateral range (R_m)
    nz = math.floor(min(cal.scan_z_mm, delta_end) / cal.scan_step_mm + 1e-9) + 1
    assert scan.rows == len(y) == ny * nz and scan.B_uT.shape == (ny * nz, 3) and scan.F_N.shape == (ny * nz, 3)
    assert y[:ny] == pytest.approx(np.linspace(-cal.scan_y_mm / 2, cal.scan_y_mm / 2, ny), abs=1e-12)
    assert np.all(delta[:ny] == 0.0) and delta.max() <= delta_end and delta.max() > delta_end - cal.scan_step_mm
    assert np.all(np.diff(scan.time_s) > 0)


def test_simulated_scan_physics(design, pred, ideal):
    y, delta = scan_track(design, pred)
    centre = (delta == 0) & (np.abs(y) < 1e-12)
    # at rest on the axis: the predicted rest field, no lateral field, no force
    magnet = F.Magnet.from_design(design)
    exact_rest = F.bz_br(magnet, design.d_rest_mm, 0.0, model="exact")[0] * UT_PER_GAUSS
    assert ideal.B_uT[centre, 2][0] == pytest.approx(exact_rest, rel=1e-12)
    # the prediction's own figure comes from its chosen (faster) field model
    assert ideal.B_uT[centre, 2][0] == pytest.approx(pred.as_json()["field"]["Bz_rest_G"] * UT_PER_GAUSS, rel=1e-3)
    assert np.abs(ideal.B_uT[centre, :2]).max() < 1e-9 and np.abs(ideal.F_N[centre]).max() == 0.0
    # below the magnet the radial field points towards the axis: By follows the magnet's offset y
    off = np.abs(y) > 0.1
    assert np.all(np.sign(ideal.B_uT[off, 1]) == np.sign(y[off])) and np.abs(ideal.B_uT[:, 0]).max() < 1e-9
    k_s = pred.as_json()["shear"]["stiffness_N_per_mm"]["nominal"]
    assert ideal.F_N[:, 1] == pytest.approx(k_s * y, abs=1e-12)
    # Bz grows with indentation (the gap closes)
    axis = np.abs(y) < 1e-12
    assert np.all(np.diff(ideal.B_uT[axis, 2]) > 0) and np.all(np.diff(ideal.F_N[axis, 2]) > 0)


def test_simulated_noise_matches_the_prediction_and_is_deterministic(design, pred, scan, ideal):
    nz = noise(design, chip_setting(design))
    chip = chip_setting(design)
    err = scan.B_uT - ideal.B_uT
    sigma = err.std(axis=0)
    assert sigma[:2] == pytest.approx([nz["total_xy_G"] * UT_PER_GAUSS] * 2, rel=0.06)
    assert sigma[2] == pytest.approx(nz["total_z_G"] * UT_PER_GAUSS, rel=0.06)
    counts = scan.B_uT / [chip.lsb_xy_uT, chip.lsb_xy_uT, chip.lsb_z_uT]
    assert np.abs(counts - np.round(counts)).max() < 1e-6  # on the chip's LSB grid
    q = design.spec.calibration.reference_resolution_mN / 1000.0
    assert np.abs(scan.F_N / q - np.round(scan.F_N / q)).max() < 1e-6
    assert np.sqrt(np.mean((scan.F_N[:, 2] - ideal.F_N[:, 2]) ** 2)) == pytest.approx(q / math.sqrt(12), rel=0.1)
    again = simulate_scan(design, pred)
    assert again.sha256 == scan.sha256 and np.array_equal(again.B_uT, scan.B_uT)
    other = simulate_scan(derive(parse_spec(NH + "[calibration]\nseed = 1\n")), pred)
    assert other.sha256 != scan.sha256 and np.array_equal(other.F_N, scan.F_N)


# ---- the fit ---------------------------------------------------------------------------------------


def _noise_floor(design, cal, ideal):
    """Expected held-out RMS (Fz, Fr) in N: the reference's quantisation (q / sqrt 12) and the field noise
    carried through the model's gradient, in quadrature."""
    nz = noise(design, chip_setting(design))
    sz, sxy = nz["total_z_G"] * UT_PER_GAUSS, nz["total_xy_G"] * UT_PER_GAUSS
    bz, br = ideal.B_uT[:, 2], ideal.Br_uT

    def model(bz, br):
        return cal.model(np.column_stack([br, np.zeros_like(br), bz]))

    h = 1.0  # uT
    gz = (model(bz + h, br) - model(bz - h, br)) / (2 * h)
    gr = (model(bz, br + h) - model(bz, br - h)) / (2 * h)
    field = np.sqrt(np.mean((gz * sz) ** 2 + (gr * sxy) ** 2, axis=0))
    q = design.spec.calibration.reference_resolution_mN / 1000.0 / math.sqrt(12)
    return field, np.sqrt(field**2 + q**2)


def test_fit_recovers_the_forces_to_the_injected_noise(design, scan, ideal, poly4):
    cal = poly4.calibration
    assert poly4.chosen == "poly 4" and cal.method == "poly" and cal.order == 4
    field, floor = _noise_floor(design, cal, ideal)
    c = poly4.candidate("poly 4")
    held = np.array([c.rms_holdout_N["Fz_N"], c.rms_holdout_N["Fr_N"]])
    # Fz: the floor within 15 %; Fr: below it (the gradient estimate overstates the noise of Br near Br = 0,
    # where Br = |B_lateral| is not gaussian), and above the reference quantisation alone
    assert held[0] == pytest.approx(floor[0], rel=0.15)
    q = design.spec.calibration.reference_resolution_mN / 1000.0 / math.sqrt(12)
    assert q < held[1] <= 1.05 * floor[1]
    # evaluated at the noisy readings, the error against the true force is the field-noise part
    f, inside = cal.evaluate(scan.B_uT)
    assert inside.all()
    err = np.sqrt(np.mean((f - ideal.F_N) ** 2, axis=0))
    assert err[2] == pytest.approx(field[0], rel=0.2)
    # at the noise-free readings only the fit's own error is left: well under the noise
    f0, _ = cal.evaluate(ideal.B_uT)
    err0 = np.sqrt(np.mean((f0 - ideal.F_N) ** 2, axis=0))
    assert err0[2] < 0.5 * floor[0] and np.hypot(err0[0], err0[1]) < 0.6 * floor[1]


def test_held_out_error_falls_with_order_then_levels_off(result):
    rms = {c.order: c.rms_holdout_N for c in result.candidates if c.method == "poly"}
    assert sorted(rms) == list(C.ORDERS)
    for f in C.FORCES:
        e = [rms[n][f] for n in C.ORDERS]
        assert e[0] > 5 * e[3]  # order 1 is far from the data's curvature
        assert e[0] > e[1] > e[2] > 0.98 * e[3]
        assert max(e[3:]) < 1.15 * min(e)  # orders 4-6 sit on the noise floor: flat
    for c in result.candidates:
        for f in C.FORCES:
            assert c.rms_fit_N[f] <= c.rms_holdout_N[f] * 1.001 and c.max_holdout_N[f] >= c.rms_holdout_N[f]


def test_the_default_scan_is_fitted_within_its_tolerance(magone_design, magone_prediction):
    """The default's scan runs to the 3 mm scan depth (4.9 N nominal): the error falls with the order, and the paper's
    order 4 meets calibration.tolerance_mN there, though its own error now shows above the noise (orders 5-6 lower)."""
    got = C.fit(simulate_scan(magone_design, magone_prediction), magone_design, mls=False)
    rms = {c.order: c.rms_holdout_N["Fz_N"] for c in got.candidates if c.method == "poly"}
    e = [rms[n] for n in C.ORDERS]
    assert all(a > b for a, b in itertools.pairwise(e))
    assert got.chosen == "poly 4" and 1000.0 * rms[4] <= magone_design.spec.calibration.tolerance_mN


def test_scaling_keeps_the_least_squares_well_conditioned(result):
    polys = [c for c in result.candidates if c.method == "poly"]
    for c in polys:
        assert c.condition < 1e4
        if c.order >= 2:
            assert c.condition_raw / c.condition > 1e8  # unscaled uT inputs: numerically singular by order 4
    assert [c.condition for c in polys] == sorted(c.condition for c in polys)


def test_mls_is_at_least_as_accurate_as_poly_order_4(result):
    mls, p4 = result.candidate("mls"), result.candidate("poly 4")
    for f in C.FORCES:
        assert mls.rms_holdout_N[f] <= p4.rms_holdout_N[f]
    assert mls.cost_ops > 100 * p4.cost_ops and mls.bandwidth > 0


def test_auto_takes_the_cheapest_within_tolerance(design, result):
    tol = design.spec.calibration.tolerance_mN
    polys = [c for c in result.candidates if c.method == "poly"]
    first = next(c for c in polys if c.worst_rms_N * 1000 <= tol)
    assert C.choose(result.candidates, "auto", design.spec.calibration.order, tol) == (first.label, True)
    # the spec's default is the paper's: poly, order 4
    assert result.chosen == f"poly {design.spec.calibration.order}" and result.meets_tolerance and result.message == ""
    chosen = result.candidate(result.chosen)
    assert result.calibration.errors["Fz_N"]["rms_holdout"] == chosen.rms_holdout_N["Fz_N"]
    assert result.calibration.errors["folds"] == design.spec.calibration.folds
    p4, mls = result.candidate("poly 4"), result.candidate("mls")
    assert C.choose(result.candidates, "auto", 4, p4.worst_rms_N * 1000 * 1.0001) == ("poly 4", True)
    assert C.choose(result.candidates, "auto", 3, p4.worst_rms_N * 1000 * 1.0001) == ("mls", True)
    assert C.choose(result.candidates, "auto", 4, mls.worst_rms_N * 500) == ("mls", False)
    assert C.choose(result.candidates, "poly", 6, 1e-6) == ("poly 6", False)


def test_no_fit_within_tolerance_is_a_flag_not_an_error(design, scan):
    r = C.fit(scan, derive(parse_spec(NH + "[calibration]\ntolerance_mN = 0.5\n")), mls=False)
    assert not r.meets_tolerance and "0.5 mN" in r.message and "\n" not in r.message
    assert r.chosen == min((c for c in r.candidates if c.order <= 4), key=lambda c: c.worst_rms_N).label


# ---- the guard -------------------------------------------------------------------------------------


def test_readings_outside_the_scanned_region_are_flagged(poly4, scan):
    cal = poly4.calibration
    reg = cal.region
    h = np.asarray(reg.hull)
    assert len(h) >= 3 and np.all(_cross(h, np.roll(h, -1, 0), np.roll(h, -2, 0)) > 0)  # convex, CCW
    _, inside = cal.evaluate(scan.B_uT)
    assert inside.all()
    (bz0, bz1), (br0, br1) = reg.bz_uT, reg.br_uT
    corners = [(bz, br) for bz in (bz0, bz1) for br in (br0, br1)]
    outside_hull = [p for p in corners if not reg.contains(*p)]
    assert outside_hull  # the hull is tighter than the box: a corner of the box was never scanned
    beyond = [(1.5 * bz1, 0.5 * (br0 + br1)), (0.5 * bz0, 0.5 * (br0 + br1)), (0.5 * (bz0 + bz1), 1.5 * br1)]
    b = np.array([[br, 0.0, bz] for bz, br in outside_hull + beyond] + [[np.nan, 0.0, bz1]])
    f, flags = cal.evaluate(b)
    assert not flags.any()
    assert np.isfinite(f[:-1]).all()  # the polynomial's value is still given, flagged
    single, flag = cal.evaluate(scan.B_uT[0])
    assert single.shape == (3,) and bool(flag)


def _area(polygon):
    h = np.asarray(polygon)
    return 0.5 * np.sum(h[:, 0] * np.roll(h[:, 1], -1) - np.roll(h[:, 0], -1) * h[:, 1])


def test_region_polygon_is_small_and_holds_the_scan(scan):
    bz, br = scan.B_uT[:, 2], scan.Br_uT
    hull = C.ValidRegion.of(bz, br, max_vertices=1000)  # the exact convex hull
    region = C.ValidRegion.of(bz, br)
    assert len(hull.hull) > C.HULL_MAX_VERTICES >= len(region.hull) >= 3
    assert region.contains(bz, br).all() and hull.contains(bz, br).all()
    assert 1.0 <= _area(region.hull) / _area(hull.hull) < 1.01  # encloses the hull, adds a sliver
    for k in range(3, 8):
        smaller = C.ValidRegion.of(bz, br, max_vertices=k)
        assert len(smaller.hull) == k and smaller.contains(bz, br).all()


def test_zeroing_sets_the_tare(poly4, scan, pred, design):
    y, delta = scan_track(design, pred)
    rest = scan.B_uT[(delta == 0) & (np.abs(y) < 0.3)]
    cal = poly4.calibration.zeroed(rest)
    assert cal.tare_N[0] != 0.0
    f, _ = cal.evaluate(rest)
    assert abs(f[:, 2].mean()) < 1e-12


# ---- calibration.json ------------------------------------------------------------------------------


def test_json_round_trip(poly4, result, design, scan):
    mls_cal = result.calibration_for("mls")
    for cal in (poly4.calibration, result.calibration, mls_cal):
        doc = cal.to_json()
        text = cal.dumps()
        assert json.loads(text) == doc and text == C.Calibration.from_json(json.loads(text)).dumps()
        back = C.Calibration.from_json(json.loads(text))
        assert np.array_equal(back.evaluate(scan.B_uT[:200])[0], cal.evaluate(scan.B_uT[:200])[0])
    doc = poly4.calibration.to_json()
    assert doc["format"] == C.FORMAT and doc["monomials"][:6] == [[0, 0], [1, 0], [0, 1], [2, 0], [1, 1], [0, 2]]
    assert len(doc["coefficients"]["Fz_N"]) == 15 and doc["scan"]["sha256"] == scan.sha256
    assert set(doc["chip"]) == {"gain_sel", "resolution", "osr", "dig_filt", "lsb_xy_uT", "lsb_z_uT"}
    mdoc = mls_cal.to_json()
    assert mdoc["method"] == "mls" and len(mdoc["mls"]["points"]["Fz_N"]) == scan.rows
    assert mdoc["order"] == result.firmware_order <= design.spec.calibration.order  # the firmware's polynomial
    assert mdoc["errors"]["Fz_N"]["rms_holdout"] == result.candidate("mls").rms_holdout_N["Fz_N"]
    assert np.array_equal(result.calibration_for("poly 4").coefficients, poly4.calibration.coefficients)
    f_mls, _ = mls_cal.evaluate(scan.B_uT[:50])
    f_poly, _ = mls_cal.evaluate(scan.B_uT[:50], method="poly")
    assert not np.array_equal(f_mls, f_poly) and np.abs(f_mls - f_poly).max() < 0.02


# ---- M14: the direction split ------------------------------------------------------------------


def _rotated(scan, angle_deg, flip_chip=False):
    c, s = math.cos(math.radians(angle_deg)), math.sin(math.radians(angle_deg))
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    b, f = scan.B_uT @ rot.T, scan.F_N @ rot.T
    if flip_chip:  # the chip mounted turned by 180 degrees: its x and y read the opposite way
        b = b * [-1.0, -1.0, 1.0]
    return C.Scan(scan.time_s, b, f, None, f"rotated {angle_deg}", "")


def test_direction_split_for_plus_and_minus_y(poly4, scan, ideal):
    cal = poly4.calibration
    assert cal.shear_sign == 1  # the simulated chip's axes are the sensor frame's
    f, _ = cal.evaluate(scan.B_uT)
    fy = ideal.F_N[:, 1]
    strong = np.abs(fy) > 0.03
    assert (fy > 0.03).any() and (fy < -0.03).any()
    assert np.all(np.sign(f[strong, 1]) == np.sign(fy[strong]))
    assert np.sqrt(np.mean((f[:, 1] - fy) ** 2)) < 0.005 and np.sqrt(np.mean(f[:, 0] ** 2)) < 0.002
    weak = scan.Br_uT < cal.direction_min_uT
    assert weak.any() and np.all(f[weak, :2] == 0.0)


@pytest.mark.parametrize("angle, flip", [(90.0, False), (-30.0, False), (0.0, True), (45.0, True)])
def test_rotating_the_scan_rotates_the_forces(poly4, design, scan, angle, flip):
    """Bz, Br and Fr do not change when the scan is turned about z, so the fitted polynomial is the same and
    M14 turns the lateral force with the field; a chip mounted the other way round gives shear_sign -1."""
    turned = _rotated(scan, angle, flip)
    cal = C.fit(turned, derive(parse_spec(NH + '[calibration]\nmethod = "poly"\n')), mls=False).calibration
    assert cal.shear_sign == (-1 if flip else 1)
    assert np.allclose(cal.coefficients, poly4.calibration.coefficients, rtol=1e-6, atol=1e-9)
    f, _ = cal.evaluate(turned.B_uT)
    expected = _rotated(C.Scan(scan.time_s, scan.B_uT, poly4.calibration.evaluate(scan.B_uT)[0]), angle).F_N
    assert np.allclose(f, expected, atol=1e-7)


# ---- moving least squares -------------------------------------------------------------------------


def _mls_reference(u, v, y, uq, vq, order, h):
    """MLS the plain way, one query at a time: the weighted design matrix, its normal equations with the ridge
    1e-12 trace, solved. Also each query's condition number and nearest squared distance (in h units)."""
    mono = C.monomials(order)
    out, cond, nearest = np.empty((len(uq), y.shape[1])), np.empty(len(uq)), np.empty(len(uq))
    for q in range(len(uq)):
        du, dv = (u - uq[q]) / h, (v - vq[q]) / h
        d2 = du**2 + dv**2
        w = np.exp(-0.5 * (d2 - d2.min()))
        a = np.column_stack([du**i * dv**j for i, j in mono])
        normal = a.T @ (w[:, None] * a)
        normal += 1e-12 * np.trace(normal) * np.eye(len(mono))
        out[q] = np.linalg.solve(normal, a.T @ (w[:, None] * y))[0]
        cond[q], nearest[q] = np.linalg.cond(normal), d2.min()
    return out, cond, nearest


@settings(max_examples=150, deadline=None, derandomize=True)
@given(order=st.integers(0, 3), n=st.integers(12, 150), log_h=st.floats(-3.5, 3.0), raster=st.booleans(),
       seed=st.integers(0, 2**32 - 1))
def test_mls_matches_the_plain_per_query_fit(order, n, log_h, raster, seed):
    """_mls (moments, blocks of queries) against :func:`_mls_reference`, bandwidths from far below the points'
    spacing to far above their spread, queries inside the data and up to 1000 spreads outside; on a raster
    (repeated coordinates, as a scan's) too. Agreement to 1e-8 of the larger of |y| and the value, except where
    the problem itself amplifies rounding: any reordering of the sums moves the answer by up to ~eps times the
    condition number (the ridge caps it at 1e12) times 1 + the nearest squared distance (the weights' exponent),
    so the tolerance is the larger of the two, with a margin (64) over the worst seen (2.6)."""
    rng = np.random.default_rng(seed)
    if raster:
        u, v = rng.integers(0, 6, n) / 5.0, rng.integers(0, 4, n) / 3.0
    else:
        u, v = rng.random(n), rng.random(n)
    y = np.column_stack([np.sin(3 * u) + v**2, u * v - 0.5]) + 0.01 * rng.standard_normal((n, 2))
    far = 10 ** rng.uniform(0, 3, 4) * rng.choice([-1.0, 1.0], 4)
    uq = np.concatenate([rng.random(8), far])
    vq = np.concatenate([rng.random(8), rng.uniform(-2.0, 3.0, 4)])
    h = 10.0**log_h
    ref, cond, nearest = _mls_reference(u, v, y, uq, vq, order, h)
    got = C._mls(u, v, y, uq, vq, order, h)
    scale = np.maximum(np.abs(y).max(), np.abs(ref).max(axis=1))
    tolerance = scale * np.maximum(1e-8, 64 * np.finfo(float).eps * cond * (1 + nearest))
    assert got.shape == ref.shape
    assert np.all(np.abs(got - ref).max(axis=1) <= tolerance), (np.abs(got - ref).max(axis=1) / scale, cond)


def test_mls_edge_cases():
    """No queries: an empty answer; a NaN coordinate: NaN rows, as the weights' exp would give, not a singular
    system; a quadratic is reproduced by order 2 (at bandwidths where the ridge does not bias its curvature)."""
    rng = np.random.default_rng(1)
    u, v = rng.random(40), rng.random(40)
    y = np.column_stack([1 + 2 * u - v + 0.5 * u * u - u * v, 3 * v * v])
    assert C._mls(u, v, y, np.empty(0), np.empty(0), 2, 0.1).shape == (0, 2)
    uq, vq = np.array([0.3, np.nan, 0.7]), np.array([0.4, 0.5, 0.2])
    got = C._mls(u, v, y, uq, vq, 2, 0.2)
    assert np.isnan(got[1]).all() and np.isfinite(got[[0, 2]]).all()
    for h in (0.2, 0.5):
        got = C._mls(u, v, y, uq[[0, 2]], vq[[0, 2]], 2, h)
        want = np.column_stack([1 + 2 * uq - vq + 0.5 * uq * uq - uq * vq, 3 * vq * vq])[[0, 2]]
        assert np.allclose(got, want, rtol=1e-8, atol=1e-8), (h, got - want)


# ---- the chart -------------------------------------------------------------------------------------


def test_chart_is_deterministic(result):
    a, b = chart(result), chart(result)
    assert set(a) == {"calibration_fit.svg", "calibration_fit.png"} and a == b
    assert a["calibration_fit.svg"].startswith(b"<?xml") and a["calibration_fit.png"][:8] == b"\x89PNG\r\n\x1a\n"
    assert b"<dc:date>" not in a["calibration_fit.svg"]


def test_the_too_few_rows_message_names_the_largest_fit():
    assert C.ORDERS[-1] == scan_format.LARGEST_ORDER and scan_format.MIN_ROWS == C.MIN_ROWS



@pytest.mark.parametrize("change", ["force x 1e300", "field x 1e300", "no lateral field", "Br on a line in Bz"])
def test_fit_refuses_an_implausible_or_flat_scan_before_any_work(design, scan, change, monkeypatch):
    """A scan built in memory (not read from a CSV) meets the same checks at the start of
    the fit: one ScanError line, no RuntimeWarning, and no candidate fitted."""
    import warnings
    from dataclasses import replace

    b, f = scan.B_uT.copy(), scan.F_N.copy()
    if change == "force x 1e300":
        f *= 1e300
    elif change == "field x 1e300":
        b *= 1e300
    elif change == "no lateral field":
        b[:, :2] = 0.0
    else:
        b[:, 0], b[:, 1] = 0.1 * (b[:, 2] - b[:, 2].min()), 0.0
    monkeypatch.setattr(C, "_poly_candidate", lambda *a, **k: pytest.fail("a candidate was fitted"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(C.ScanError) as info:
            C.fit(replace(scan, B_uT=b, F_N=f), design)
    assert "\n" not in str(info.value)
    assert ("plausible band" in str(info.value)) == ("1e300" in change)


def test_the_region_reaches_the_noise_beyond_the_scan(scan, poly4, design):
    """Widened by REGION_MARGIN_SIGMAS of the chip's noise: every scan point moved by the margin in Bz and Br is
    inside, one moved by twice it outward from a corner is not; a sensor at rest (the scan's rest point, a corner
    of the region, plus the chip's noise) reads inside nearly always (without the margin: about half the time)."""
    bz, br = scan.B_uT[:, 2], scan.Br_uT
    m = 40.0
    tight, wide = C.ValidRegion.of(bz, br), C.ValidRegion.of(bz, br, margin_uT=m)
    for dz in (-m, m):
        for dr in (-m, m):
            assert wide.contains(bz + dz, np.maximum(br + dr, 0.0)).all()
    assert not wide.contains(bz.max() + 2 * m, br.mean()) and wide.br_uT[0] == 0.0
    assert 1.0 < _area(wide.hull) / _area(tight.hull) < 1.2 and len(wide.hull) == len(tight.hull)
    cal = poly4.calibration
    _, noise_uT = C._chip_json(design)
    rest = np.argmin(np.abs(scan.F_N[:, 2]) + scan.Fr_N)
    rng = np.random.default_rng(1)
    B = scan.B_uT[rest] + rng.normal(0.0, noise_uT, (2000, 3))
    B[:, :2] = rng.normal(0.0, noise_uT, (2000, 2))  # at rest on the axis: the lateral field is the noise
    _, inside = cal.evaluate(B)
    assert inside.mean() > 0.99
    assert tight.contains(B[:, 2], np.hypot(B[:, 0], B[:, 1])).mean() < 0.9


# ---- temperature: the thermal coefficients fitted from a scan spanning temperatures, else the recipe's ----------

TRUE_PER_C = (-0.0012, -0.0012, -0.0020)  # the magnet's -0.12 %/C; the z reading 0.08 %/C more (a chip's drift)


@pytest.fixture(scope="module")
def warm_fit(pred):
    """A scan run twice while the tip warms from 20 to 35 C (each point read at two temperatures 7.5 C apart), on
    a 0.2 mm grid (378 rows: the default 0.05 mm's 5346 give sigmas four times smaller, at a hundred times the
    fit's time)."""
    coarse = derive(parse_spec(NH + "[calibration]\nscan_step_mm = 0.2\n"))
    scan = simulate_scan(coarse, pred, temperature_C=(20.0, 35.0), passes=2, thermal_per_C=TRUE_PER_C)
    return scan, C.fit(scan, coarse, mls=False)


def test_calibrate_recovers_the_thermal_coefficients_within_their_uncertainty(warm_fit):
    """The fit's (a_xy, a_z) are the injected ones (referred to the scan's mean temperature: a / (1 + a (T0 - 25)))
    within three of their stated sigmas (and the sigmas are small:
    the z axis is told apart from the recipe's -0.12 %/C); calibration.json says it fitted them and at what
    temperature; the forces of a reading at 35 C are those of the same point at 20 C."""
    scan, result = warm_fit
    t = result.calibration.thermal
    assert t.source == "fit" and t.span_C == pytest.approx(15.0, abs=0.05)
    assert t.reference_C == pytest.approx(27.5, abs=0.05)
    for a, true25, sigma in zip(t.coefficient_per_C, TRUE_PER_C, t.uncertainty_per_C):
        true = true25 / (1 + true25 * (t.reference_C - 25.0))  # the same line, referred to T0 instead of 25 C
        assert abs(a - true) <= 3 * sigma and sigma < 0.0001, (a, true, sigma)
    assert abs(t.coefficient_per_C[2] - t.recipe_per_C) > 5 * t.uncertainty_per_C[2]
    doc = result.calibration.to_json()
    assert doc["thermal"]["source"] == "fit" and "fitted over 15 C" in result.thermal_note
    back = C.Calibration.from_json(json.loads(json.dumps(doc)))
    assert back.thermal.coefficient_per_C == t.coefficient_per_C
    n = scan.rows // 2  # the same point in the first pass (cold) and in the second (warm)
    k = int(np.argmax(scan.F_N[:n, 2]))
    cold, _ = back.evaluate(scan.B_uT[k], temperature_C=scan.temperature_C[k])
    warm, _ = back.evaluate(scan.B_uT[k + n], temperature_C=scan.temperature_C[k + n])
    raw, _ = back.evaluate(scan.B_uT[k + n])
    assert abs(warm[2] - cold[2]) < 0.1 * abs(raw[2] - cold[2]) and abs(raw[2] - cold[2]) > 0.02


def test_without_a_temperature_span_calibrate_uses_the_recipe(design, pred, scan, result):
    """No temperature column (the default simulated scan): the recipe's -0.12 %/C on every axis at 25 C; a
    scan held at 30 C: the same coefficients at 30 C; a single warming pass (the temperature follows the
    position, so the force map absorbs it and a fit would be wrong with a small sigma): the recipe, and why."""
    t = result.calibration.thermal
    assert t.source == "recipe" and t.coefficient_per_C == (-0.0012,) * 3 and t.reference_C == 25.0
    assert "no temperature column" in result.thermal_note
    coarse = derive(parse_spec(NH + "[calibration]\nscan_step_mm = 0.2\n"))
    held = C.fit(simulate_scan(coarse, pred, temperature_C=30.0), coarse, mls=False).calibration.thermal
    assert held.source == "recipe" and held.reference_C == pytest.approx(30.0, abs=0.02) and held.span_C < 0.05
    once = C.fit(simulate_scan(coarse, pred, temperature_C=(20.0, 35.0)), coarse, mls=False).calibration.thermal
    assert once.source == "recipe" and "followed the scan's position" in once.note
    assert once.span_C == pytest.approx(15.0, abs=0.05)


@pytest.mark.slow
def test_the_thermal_fit_at_the_default_scan_step(design, pred):
    """The same at the spec's 0.05 mm step (5346 rows): within 3 sigma, sigma under 0.002 %/C."""
    scan = simulate_scan(design, pred, temperature_C=(20.0, 35.0), passes=2, thermal_per_C=TRUE_PER_C)
    t = C.fit(scan, design, mls=False).calibration.thermal
    assert t.source == "fit"
    for a, true25, sigma in zip(t.coefficient_per_C, TRUE_PER_C, t.uncertainty_per_C):
        true = true25 / (1 + true25 * (t.reference_C - 25.0))
        assert abs(a - true) <= 3 * sigma and sigma < 0.00002, (a, true, sigma)
