"""Closed forms (docs/models.md, M6 and M15): the field on the axis (and its derivatives), the point dipole and the
axial multipoles, each with the error estimate the model refuses points by. Fields in G, lengths in mm."""

from __future__ import annotations

import numpy as np
from numpy.polynomial import legendre
from numpy.typing import ArrayLike

from ...units import GAUSS_PER_TESLA
from .magnet import DEFAULT_RTOL, Magnet, _points, _refuse_estimate, _refuse_inside, _shaped

__all__ = ["axis_bz", "axis_dbz_dz", "on_axis_error_estimate", "on_axis",
           "axial_multipoles", "dipole_error_estimate", "dipole"]


def _axis_terms(magnet: Magnet, z_mm: np.ndarray) -> tuple[np.ndarray, ...]:
    """a = |z| + H/2, b = |z| - H/2 and sqrt(a^2 + R^2), sqrt(b^2 + R^2); valid for |z| > H/2."""
    az, h, R2 = np.abs(z_mm), magnet.height_mm / 2.0, magnet.radius_mm**2
    a, b = az + h, az - h
    return az, a, b, np.sqrt(a * a + R2), np.sqrt(b * b + R2)


def axis_bz(magnet: Magnet, z_mm: ArrayLike) -> np.ndarray:
    """Bz on the axis at height z (|z| > H/2), G: docs/models.md, M6, without its cancellation.

    M6 is Br_rem/2 [a/sqrt(a^2+R^2) - b/sqrt(b^2+R^2)]; the bracket equals
    R^2 (a^2 - b^2) / (sa sb (a sb + b sa)) with a^2 - b^2 = 2 H |z| exactly, so it keeps full relative
    precision at any distance (the printed form returns 0 beyond ~10^5 R).
    """
    z = np.asarray(z_mm, dtype=float)
    az, a, b, sa, sb = _axis_terms(magnet, z)
    bracket = magnet.radius_mm**2 * 2.0 * magnet.height_mm * az / (sa * sb * (a * sb + b * sa))
    return 0.5 * magnet.remanence_T * GAUSS_PER_TESLA * bracket


def axis_dbz_dz(magnet: Magnet, z_mm: ArrayLike, order: int = 1) -> np.ndarray:
    """d^n Bz / dz^n on the axis (n = ``order``, 1 or 2), G/mm^n, for |z| > H/2.

    From M6: d/dz [u / sqrt(u^2 + R^2)] = R^2 (u^2 + R^2)^-3/2 and its derivative
    -3 R^2 u (u^2 + R^2)^-5/2, with u = z + H/2 and z - H/2. Positive below the magnet for n = 1.
    """
    z = np.asarray(z_mm, dtype=float)
    h, R2 = magnet.height_mm / 2.0, magnet.radius_mm**2
    up, um = z + h, z - h
    sp, sm = up * up + R2, um * um + R2
    if order == 1:
        # sp^-1.5 - sm^-1.5 = (sm^1.5 - sp^1.5) / (sp sm)^1.5, and sm^1.5 - sp^1.5 is written through
        # sm - sp = (um - up)(um + up) = -2 h (2 z) so that it does not cancel far away.
        diff = -2.0 * h * 2.0 * z  # sm - sp
        num = diff * (sm + np.sqrt(sm * sp) + sp) / (np.sqrt(sm) + np.sqrt(sp))
        val = R2 * num / (sp * sm) ** 1.5
    elif order == 2:
        val = -3.0 * R2 * (up * sp**-2.5 - um * sm**-2.5)
    else:
        raise ValueError(f"order must be 1 or 2; instead received {order!r}")
    return 0.5 * magnet.remanence_T * GAUSS_PER_TESLA * val


def on_axis_error_estimate(magnet: Magnet, points_mm: ArrayLike) -> np.ndarray:
    """Leading-order relative error of :func:`on_axis` at each point, (N,).

    Paraxial expansion of an axisymmetric field: B_rho = -r/2 Bz0'(z), Bz = Bz0(z) - r^2/4 Bz0''(z) + ...
    The on-axis model drops both terms: estimate |(r/2 Bz0', r^2/4 Bz0'')| / |Bz0|. Tends to the actual
    error as r -> 0; an estimate, not a bound, once r is a sizeable fraction of the distance to the rim.
    """
    p = _points(points_mm)
    r = np.hypot(p[:, 0], p[:, 1])
    z = p[:, 2]
    bz0 = axis_bz(magnet, z)
    e1 = 0.5 * r * axis_dbz_dz(magnet, z, 1)
    e2 = 0.25 * r * r * axis_dbz_dz(magnet, z, 2)
    return np.hypot(e1, e2) / np.abs(bz0)


def on_axis(magnet: Magnet, points_mm: ArrayLike, *, rtol: float | None = DEFAULT_RTOL) -> np.ndarray:
    """(0, 0, Bz0(z)) from the axial closed form (docs/models.md, M6), G, at points near the axis (mm).

    Raises :class:`FieldModelError` inside or on the magnet, and (unless ``rtol`` is None) where
    :func:`on_axis_error_estimate` exceeds ``rtol``: off the axis the model ignores Br altogether.
    """
    p = _points(points_mm)
    _refuse_inside("on_axis", magnet, p)
    if rtol is not None:
        est = on_axis_error_estimate(magnet, p)
        _refuse_estimate(p, est, rtol, lambda where, worst: (
            f"on_axis: {where} are too far off the axis for the axial closed form (estimated relative error {worst} > "
            f"rtol {rtol:g}; it neglects Br = -r/2 dBz/dz); use surrogate or exact"))
    out = np.zeros_like(p)
    out[:, 2] = axis_bz(magnet, p[:, 2])
    return _shaped(points_mm, out)


# ---- dipole and multipoles ------------------------------------------------------------------------


def axial_multipoles(magnet: Magnet, lmax: int = 5) -> dict[int, float]:
    """Coefficients A_l (odd l <= lmax) of the exterior potential, G mm^(l+2).

    Outside the circumscribed sphere B = -grad sum_l A_l P_l(cos t) / D^(l+1), so on the axis
    Bz = sum_l (l + 1) A_l / z^(l+2). Matching the expansion of the axial field (M6) in 1/z: with
    u/sqrt(u^2+R^2) = sum_n c_n R^2n u^-2n (c_n = binom(-1/2, n)) and (z +- h)^-2n expanded in h/z,
    A_l = Br_rem / (l + 1) * sum_{2n + m = l + 2, m odd} c_n binom(-2n, m) R^2n h^m.
    A_1 = Br_rem R^2 H / 4 is the dipole (m mu0 / 4 pi); A_3 / A_1 = h^2 - 3 R^2 / 4 vanishes at H = sqrt(3) R.
    """
    R, h = magnet.radius_mm, magnet.height_mm / 2.0
    br = magnet.remanence_T * GAUSS_PER_TESLA
    out = {}
    for order in range(1, lmax + 1, 2):
        total = 0.0
        for n in range(1, (order + 1) // 2 + 1):
            m = order + 2 - 2 * n
            if m % 2 == 1 and m > 0:
                total += _binom(-0.5, n) * _binom(-2.0 * n, m) * R ** (2 * n) * h**m
        out[order] = br * total / (order + 1)
    return out


def _binom(a: float, k: int) -> float:
    """Generalised binomial coefficient a (a - 1) ... (a - k + 1) / k! for any real a."""
    out = 1.0
    for i in range(k):
        out *= (a - i) / (i + 1)
    return out


def _multipole_magnitude(order: int, mu: np.ndarray) -> np.ndarray:
    """|B_l| D^(l+2) / |A_l| = sqrt((l+1)^2 P_l^2 + (1 - mu^2) P_l'^2) at mu = cos t, for l = ``order``."""
    c = np.zeros(order + 1)
    c[order] = 1.0
    pl = legendre.legval(mu, c)
    dpl = legendre.legval(mu, legendre.legder(c))
    return np.sqrt((order + 1) ** 2 * pl * pl + (1.0 - mu * mu) * dpl * dpl)


def dipole_error_estimate(magnet: Magnet, points_mm: ArrayLike) -> np.ndarray:
    """Relative error of :func:`dipole` from the next two multipoles (l = 3, 5), (N,).

    Asymptotically exact far away (error ~ (R/D)^2); ``inf`` inside the circumscribed sphere, where
    the multipole series diverges and nothing bounds the dipole's error.
    """
    p = _points(points_mm)
    D = np.sqrt(np.sum(p * p, axis=1))
    mu = np.divide(p[:, 2], D, out=np.zeros_like(D), where=D > 0)
    A = axial_multipoles(magnet, 5)
    with np.errstate(divide="ignore", invalid="ignore"):
        dip = abs(A[1]) * _multipole_magnitude(1, mu) / D**3
        rest = sum(abs(A[order]) * _multipole_magnitude(order, mu) / D ** (order + 2) for order in (3, 5))
        est = rest / dip
    return np.where(magnet.circumscribed_radius_mm < D, est, np.inf)


def dipole(magnet: Magnet, points_mm: ArrayLike, *, rtol: float | None = DEFAULT_RTOL) -> np.ndarray:
    """Point-dipole field, G, m = Br_rem V / mu0 along +z at the centre: B = A_1 (3 z r / D^5 - e_z / D^3).

    Raises :class:`FieldModelError` inside or on the magnet, and (unless ``rtol`` is None) inside the
    circumscribed sphere or where :func:`dipole_error_estimate` exceeds ``rtol``.
    """
    p = _points(points_mm)
    _refuse_inside("dipole", magnet, p)
    if rtol is not None:
        est = dipole_error_estimate(magnet, p)
        _refuse_estimate(p, est, rtol, lambda where, worst: (
            f"dipole: {where} are too close to the magnet for a point dipole (estimated relative error {worst} > "
            f"rtol {rtol:g}); use surrogate or exact"))
    a1 = magnet.remanence_T * GAUSS_PER_TESLA * magnet.radius_mm**2 * magnet.height_mm / 4.0
    d2 = np.sum(p * p, axis=1)
    inv3 = d2**-1.5
    k = 3.0 * a1 * p[:, 2] * inv3 / d2
    out = p * k[:, None]
    out[:, 2] -= a1 * inv3
    return _shaped(points_mm, out)
