"""Field of the magnet: an axially magnetised cylinder, four models of it, their errors and their cost.

Frame and units. The magnet is centred at the origin with its axis on z and is magnetised along +z;
its lower face is at z = -H/2. Lengths are in mm at the API, the remanence Br_rem in tesla, and every
field comes back in gauss (1 T = 10^4 G). A sensor at axial distance d below the lower face and radial
offset r sits at (r, 0, -(H/2 + d)). Below the magnet Bz > 0 and the radial component points inwards.

The models (BRIEF sec. 3), each ``model(magnet, points_mm, *, rtol=...) -> (N, 3)`` gauss:

* :func:`exact` -- Derby & Olbert (2010), complete elliptic integrals: magpylib's own kernel
  (``magpylib.core.magnet_cylinder_axial_Bfield``, the code ``magpylib.magnet.Cylinder`` runs), called
  directly on cylindrical coordinates so it skips ``getB``'s per-call bookkeeping (3-5x faster). The
  reference everything else is measured against; :func:`magpylib_cylinder` is the same field through
  magpylib's class interface and the tests pin the two together. Our own Derby-Olbert code with
  Bulirsch's cel (bench/field.py) ran at 1.0-1.6x the speed of that kernel under varying machine
  load, so it is not kept here: a second copy of the special functions is not worth that.
* :func:`on_axis` -- BRIEF eq. 6, Bz on the axis, Bx = By = 0. Exact on the axis (written here in a
  form without the far-field cancellation of eq. 6 as printed); wrong off it.
* :func:`dipole` -- a point dipole of moment m = Br_rem V / mu0. Wrong near the magnet.
* :func:`surrogate` -- a table of the dimensionless exact field over (r/R, z/R), one per aspect H/R,
  built lazily (~0.1 s) from :func:`exact` and interpolated bilinearly: within 1e-4 of it over the
  MagOne working volume (3e-4 anywhere in its domain) and 40-80x faster than magpylib's ``getB``.

Failures are detected and raised as :class:`FieldModelError`, never returned as numbers:

* every model refuses points inside the magnet or within ``SURFACE_GAP`` R of its surface (the sensor
  cannot be there; Bz jumps across the side face and Br diverges logarithmically at the rim);
* :func:`exact` refuses points so far away that its two face terms cancel to below ``rtol`` (relative
  rounding error ~ eps D^3 / (R^2 H); from D ~ 1000 R on the dipole is the more accurate of the two);
* :func:`on_axis` refuses points off the axis whose paraxial error estimate exceeds ``rtol``;
* :func:`dipole` refuses points inside the magnet's circumscribed sphere (the multipole series
  diverges: no error estimate) or whose next-multipole error estimate exceeds ``rtol``;
* :func:`surrogate` refuses points outside its table (``SurrogateDomain``) or an ``rtol`` tighter
  than the error the table measured on itself when it was built.

``rtol=None`` turns the error-estimate checks off (never the inside-the-magnet check): benchmarks use
it to measure how wrong a model is where it would refuse.

Error of a model at a point: ``|B_model - B_exact| / |B_exact|`` with vector norms. The vector norm
does not vanish outside the magnet, so this stays finite where Bz alone crosses zero off the axis
(component-wise relative errors would explode there). :func:`model_error` also gives the error
normalised by the largest |B| over the points, the figure to quote where |B| itself becomes small.
"""

from __future__ import annotations

import math
import statistics
import time
from dataclasses import dataclass, replace
from functools import lru_cache
from types import MappingProxyType
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

import numpy as np

if TYPE_CHECKING:
    from ..spec import Spec

__all__ = [
    "FieldModelError", "Magnet", "GAUSS_PER_TESLA", "DEFAULT_RTOL", "EXACT_RTOL", "SURFACE_GAP",
    "exact", "magpylib_cylinder", "exact_rounding_estimate",
    "on_axis", "on_axis_error_estimate", "axis_bz", "axis_dbz_dz",
    "dipole", "dipole_error_estimate", "axial_multipoles",
    "SurrogateDomain", "SurrogateTable", "surrogate_table", "surrogate",
    "working_volume", "ModelError", "model_error",
    "Model", "MODELS", "Choice", "choose", "bz_br", "dbz_dz", "Measurement", "measure",
]

GAUSS_PER_TESLA = 1.0e4
MU0 = 4.0e-7 * math.pi  # T m / A (the pre-2019 defined value; CODATA 2018's differs by 5.5e-10 relative)

#: Default error budget of the approximate models: the issue's 0.1 %.
DEFAULT_RTOL = 1e-3
#: :func:`exact` is the reference the others are checked against, so it must be far better than them.
EXACT_RTOL = 1e-6
#: Points closer than this many magnet radii to the magnet (or inside it) are refused by every model.
SURFACE_GAP = 1e-6

_EPS = float(np.finfo(float).eps)


class FieldModelError(ValueError):
    """A model was asked for a field it cannot give to its stated accuracy (or at all): says which
    points, why, and what to use instead."""


# ---- the magnet ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class Magnet:
    """An axially magnetised cylinder: radius and height in mm, remanence Br_rem in T."""

    radius_mm: float
    height_mm: float
    remanence_T: float

    def __post_init__(self) -> None:
        for name in ("radius_mm", "height_mm", "remanence_T"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(value) or value <= 0:
                raise ValueError(f"Magnet.{name} must be a positive finite number; instead received {value!r}")

    @classmethod
    def from_spec(cls, spec: "Spec", band: str = "nominal") -> "Magnet":
        """The spec's magnet, its remanence from recipes/magnets.toml (``band``: low, nominal or high)."""
        from ..recipes import catalogue

        br = catalogue("magnets")[spec.magnet.grade]["remanence_T"]
        if band not in ("low", "nominal", "high"):
            raise ValueError(f"band must be 'low', 'nominal' or 'high'; instead received {band!r}")
        return cls(spec.magnet.diameter_mm / 2.0, spec.magnet.height_mm, getattr(br, band))

    @property
    def aspect(self) -> float:
        """H / R, dimensionless (the paper's guideline H/D = 0.2-0.5 is aspect 0.4-1)."""
        return self.height_mm / self.radius_mm

    @property
    def volume_mm3(self) -> float:
        return math.pi * self.radius_mm**2 * self.height_mm

    @property
    def moment_A_m2(self) -> float:
        """Dipole moment m = Br_rem V / mu0, A m^2."""
        return self.remanence_T * self.volume_mm3 * 1e-9 / MU0

    @property
    def circumscribed_radius_mm(self) -> float:
        """Radius of the smallest sphere about the centre holding the magnet, mm."""
        return math.hypot(self.radius_mm, self.height_mm / 2.0)


# ---- points ---------------------------------------------------------------------------------------


def _points(points_mm: object) -> np.ndarray:
    """``points_mm`` as a float (N, 3) array (a single (3,) point becomes (1, 3))."""
    p = np.asarray(points_mm, dtype=float)
    if p.ndim == 1 and p.shape[0] == 3:
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points_mm must be an array of shape (N, 3) in mm; instead received shape {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError("points_mm must be finite; instead received NaN or infinity")
    return p


def _shaped(points_mm: object, field: np.ndarray) -> np.ndarray:
    """Give ``field`` (N, 3) the shape of the caller's points ((3,) in, (3,) out)."""
    return field[0] if np.ndim(points_mm) == 1 else field


def _where(points: np.ndarray, bad: np.ndarray, limit: int = 3) -> str:
    """'k of N points, first at index i: (x, y, z) mm' for an error message."""
    idx = np.flatnonzero(bad)
    shown = ", ".join(f"#{i} ({points[i, 0]:.6g}, {points[i, 1]:.6g}, {points[i, 2]:.6g})" for i in idx[:limit])
    more = f" and {idx.size - limit} more" if idx.size > limit else ""
    return f"{idx.size} of {len(points)} points: {shown}{more} mm"


def _refuse_inside(model: str, magnet: Magnet, p: np.ndarray) -> None:
    """Raise if a point is inside the magnet or within SURFACE_GAP * R of it (a slightly larger box)."""
    gap = SURFACE_GAP * magnet.radius_mm
    rho2 = p[:, 0] ** 2 + p[:, 1] ** 2
    bad = (rho2 < (magnet.radius_mm + gap) ** 2) & (np.abs(p[:, 2]) < magnet.height_mm / 2.0 + gap)
    if bad.any():
        raise FieldModelError(
            f"{model}: {_where(p, bad)} are inside the magnet or within {SURFACE_GAP:g} R of its surface, "
            "where the sensor cannot be (Bz jumps across the side face, Br diverges at the rim)")


def _cartesian(p: np.ndarray, bz: np.ndarray, brho: np.ndarray) -> np.ndarray:
    """(Bx, By, Bz) from the axial and the signed radial component (any unit), (N, 3)."""
    rho = np.hypot(p[:, 0], p[:, 1])
    q = np.divide(brho, rho, out=np.zeros_like(brho), where=rho > 0)
    return np.column_stack([q * p[:, 0], q * p[:, 1], bz])


# ---- exact ----------------------------------------------------------------------------------------


def _kernel(magnet: Magnet, rho_mm: np.ndarray, z_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Bz, B_rho) per unit polarization (dimensionless) by magpylib's Derby-Olbert kernel."""
    from magpylib.core import magnet_cylinder_axial_Bfield

    R = magnet.radius_mm
    b = magnet_cylinder_axial_Bfield(np.full(rho_mm.shape, magnet.height_mm / (2.0 * R)), rho_mm / R, z_mm / R)
    return b[2], b[0]


def exact_rounding_estimate(magnet: Magnet, points_mm: object) -> np.ndarray:
    """Upper estimate of the relative rounding error of the elliptic-integral form at each point, (N,).

    Far away the field is the small difference of the two faces' terms, each ~Br_rem, while B ~ Br_rem
    R^2 H / D^3 (D from the centre): 4 eps D^3 / (R^2 H). Measured against the cancellation-free eq. 6
    on the axis, where it is worst, for H/R 0.05 to 8 and D = 10 R to 10^5 R: the actual error stays
    under half of this; off the axis it is ~100x smaller still.
    """
    p = _points(points_mm)
    d3 = np.sum(p * p, axis=1) ** 1.5
    return 4.0 * _EPS * d3 / (magnet.radius_mm**2 * magnet.height_mm)


def exact(magnet: Magnet, points_mm: object, *, rtol: float | None = EXACT_RTOL) -> np.ndarray:
    """Exact field (Bx, By, Bz), G, shape of ``points_mm`` ((N, 3) or (3,), mm).

    Raises :class:`FieldModelError` at points inside or on the magnet, and (unless ``rtol`` is None)
    where :func:`exact_rounding_estimate` exceeds ``rtol`` -- there use :func:`dipole`.
    """
    p = _points(points_mm)
    _refuse_inside("exact", magnet, p)
    if rtol is not None:
        # est > rtol  <=>  D^2 > (rtol R^2 H / 4 eps)^(2/3): compare squared distances, no powers
        d2_max = (rtol * magnet.radius_mm**2 * magnet.height_mm / (4.0 * _EPS)) ** (2.0 / 3.0)
        d2 = np.einsum("ij,ij->i", p, p)
        if d2.max(initial=0.0) > d2_max:
            bad = d2 > d2_max
            est = exact_rounding_estimate(magnet, p)
            raise FieldModelError(
                f"exact: {_where(p, bad)} are so far from the magnet that the elliptic-integral form loses "
                f"precision to cancellation (estimated relative rounding error up to {est.max():.1e} > "
                f"rtol {rtol:g}); use the dipole there (its error ~ (R/D)^2 is smaller)")
    bz, brho = _kernel(magnet, np.hypot(p[:, 0], p[:, 1]), p[:, 2])
    return _shaped(points_mm, _cartesian(p, bz, brho) * (magnet.remanence_T * GAUSS_PER_TESLA))


def magpylib_cylinder(magnet: Magnet, points_mm: object) -> np.ndarray:
    """The reference: ``magpylib.magnet.Cylinder(...).getB`` in SI, returned in G, no checks."""
    import magpylib

    p = _points(points_mm)
    cyl = magpylib.magnet.Cylinder(dimension=(2e-3 * magnet.radius_mm, 1e-3 * magnet.height_mm),
                                   polarization=(0.0, 0.0, magnet.remanence_T))
    b = np.asarray(cyl.getB(p * 1e-3), dtype=float).reshape(-1, 3)
    return _shaped(points_mm, b * GAUSS_PER_TESLA)


# ---- on the axis (eq. 6) --------------------------------------------------------------------------


def _axis_terms(magnet: Magnet, z_mm: np.ndarray) -> tuple[np.ndarray, ...]:
    """a = |z| + H/2, b = |z| - H/2 and sqrt(a^2 + R^2), sqrt(b^2 + R^2); valid for |z| > H/2."""
    az, h, R2 = np.abs(z_mm), magnet.height_mm / 2.0, magnet.radius_mm**2
    a, b = az + h, az - h
    return az, a, b, np.sqrt(a * a + R2), np.sqrt(b * b + R2)


def axis_bz(magnet: Magnet, z_mm: object) -> np.ndarray:
    """Bz on the axis at height z (|z| > H/2), G: eq. 6 without its cancellation.

    eq. 6 is Br_rem/2 [a/sqrt(a^2+R^2) - b/sqrt(b^2+R^2)]; the bracket equals
    R^2 (a^2 - b^2) / (sa sb (a sb + b sa)) with a^2 - b^2 = 2 H |z| exactly, so it keeps full relative
    precision at any distance (the printed form returns 0 beyond ~10^5 R).
    """
    z = np.asarray(z_mm, dtype=float)
    az, a, b, sa, sb = _axis_terms(magnet, z)
    bracket = magnet.radius_mm**2 * 2.0 * magnet.height_mm * az / (sa * sb * (a * sb + b * sa))
    return 0.5 * magnet.remanence_T * GAUSS_PER_TESLA * bracket


def axis_dbz_dz(magnet: Magnet, z_mm: object, order: int = 1) -> np.ndarray:
    """d^n Bz / dz^n on the axis (n = ``order``, 1 or 2), G/mm^n, for |z| > H/2.

    From eq. 6: d/dz [u / sqrt(u^2 + R^2)] = R^2 (u^2 + R^2)^-3/2 and its derivative
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


def on_axis_error_estimate(magnet: Magnet, points_mm: object) -> np.ndarray:
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


def _refuse_estimate(p: np.ndarray, est: np.ndarray, rtol: float, message: Callable[[str, str], str]) -> None:
    """Raise :class:`FieldModelError` where a model's error estimate exceeds ``rtol``."""
    bad = est > rtol
    if bad.any():
        worst = "unbounded (inside the circumscribed sphere)" if np.isinf(est).any() else f"up to {est.max():.2g}"
        raise FieldModelError(message(_where(p, bad), worst))


def on_axis(magnet: Magnet, points_mm: object, *, rtol: float | None = DEFAULT_RTOL) -> np.ndarray:
    """(0, 0, Bz0(z)) from eq. 6, G, at points near the axis (mm).

    Raises :class:`FieldModelError` inside or on the magnet, and (unless ``rtol`` is None) where
    :func:`on_axis_error_estimate` exceeds ``rtol``: off the axis the model ignores Br altogether.
    """
    p = _points(points_mm)
    _refuse_inside("on_axis", magnet, p)
    if rtol is not None:
        est = on_axis_error_estimate(magnet, p)
        _refuse_estimate(p, est, rtol, lambda where, worst: (
            f"on_axis: {where} are too far off the axis for eq. 6 (estimated relative error {worst} > rtol {rtol:g}; "
            "it neglects Br = -r/2 dBz/dz); use surrogate or exact"))
    out = np.zeros_like(p)
    out[:, 2] = axis_bz(magnet, p[:, 2])
    return _shaped(points_mm, out)


# ---- dipole and multipoles ------------------------------------------------------------------------


def axial_multipoles(magnet: Magnet, lmax: int = 5) -> dict[int, float]:
    """Coefficients A_l (odd l <= lmax) of the exterior potential, G mm^(l+2).

    Outside the circumscribed sphere B = -grad sum_l A_l P_l(cos t) / D^(l+1), so on the axis
    Bz = sum_l (l + 1) A_l / z^(l+2). Matching the expansion of eq. 6 in 1/z: with
    u/sqrt(u^2+R^2) = sum_n c_n R^2n u^-2n (c_n = binom(-1/2, n)) and (z +- h)^-2n expanded in h/z,
    A_l = Br_rem / (l + 1) * sum_{2n + m = l + 2, m odd} c_n binom(-2n, m) R^2n h^m.
    A_1 = Br_rem R^2 H / 4 is the dipole (m mu0 / 4 pi); A_3 / A_1 = h^2 - 3 R^2 / 4 vanishes at H = sqrt(3) R.
    """
    R, h = magnet.radius_mm, magnet.height_mm / 2.0
    br = magnet.remanence_T * GAUSS_PER_TESLA
    out = {}
    for l in range(1, lmax + 1, 2):
        total = 0.0
        for n in range(1, (l + 1) // 2 + 1):
            m = l + 2 - 2 * n
            if m % 2 == 1 and m > 0:
                total += _binom(-0.5, n) * _binom(-2.0 * n, m) * R ** (2 * n) * h**m
        out[l] = br * total / (l + 1)
    return out


def _binom(a: float, k: int) -> float:
    """Generalised binomial coefficient a (a - 1) ... (a - k + 1) / k! for any real a."""
    out = 1.0
    for i in range(k):
        out *= (a - i) / (i + 1)
    return out


def _multipole_magnitude(l: int, mu: np.ndarray) -> np.ndarray:
    """|B_l| D^(l+2) / |A_l| = sqrt((l+1)^2 P_l^2 + (1 - mu^2) P_l'^2) at mu = cos t."""
    from numpy.polynomial import legendre

    c = np.zeros(l + 1)
    c[l] = 1.0
    pl = legendre.legval(mu, c)
    dpl = legendre.legval(mu, legendre.legder(c))
    return np.sqrt((l + 1) ** 2 * pl * pl + (1.0 - mu * mu) * dpl * dpl)


def dipole_error_estimate(magnet: Magnet, points_mm: object) -> np.ndarray:
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
        rest = sum(abs(A[l]) * _multipole_magnitude(l, mu) / D ** (l + 2) for l in (3, 5))
        est = rest / dip
    return np.where(D > magnet.circumscribed_radius_mm, est, np.inf)


def dipole(magnet: Magnet, points_mm: object, *, rtol: float | None = DEFAULT_RTOL) -> np.ndarray:
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


# ---- surrogate ------------------------------------------------------------------------------------

#: Table resolution: cells per unit of s = (r/R)^2 and per unit of v = ln(|z|/R - shift). Chosen so the
#: table's self-check stays under 3e-4 for H/R 0.05 to 20 (1.0e-4 at MagOne's 0.8).
_S_CELLS = 64
_V_CELLS = 96
#: A table whose own error check (cell centres and edge midpoints against exact) exceeds this is not used.
SURROGATE_BUILD_RTOL = 3e-4


@dataclass(frozen=True)
class SurrogateDomain:
    """Where a surrogate table is valid, in magnet radii: 0 <= r/R <= rho_max, and the gap between the
    point and the nearer face, (|z| - H/2)/R, in [gap_min, gap_max]. Covers both sides of the magnet."""

    rho_max: float = 2.0
    gap_min: float = 0.2
    gap_max: float = 10.0

    def __post_init__(self) -> None:
        if not (self.rho_max > 0 and 0 < self.gap_min < self.gap_max and math.isfinite(self.gap_max)):
            raise ValueError(f"SurrogateDomain needs rho_max > 0 and 0 < gap_min < gap_max; instead received {self}")


@dataclass(frozen=True, eq=False)
class SurrogateTable:
    """Dimensionless field table for one aspect H/R, bilinear in s = (r/R)^2 and v = ln(|z|/R - shift).

    ``shift`` = H/2R - min(H/2R, 1): zero up to H/R = 2, so v = ln(|z|/R) spaces the cells in proportion
    to the distance from the centre; for longer magnets it keeps the cells near the face as fine as
    the gap to it.

    Tabulated: F_z = (Bz / Br_rem) zeta^2 and F_q = (B_rho / Br_rem) / (r/R) zeta^2, zeta = |z|/R, for
    z < 0. Both are smooth (even in r, hence in s; the zeta^2 takes out most of the decay), B_rho / r
    needs no square root and gives Bx = x B_rho/r directly; above the magnet Bz is even and B_rho odd
    in z. ``coef`` holds, per cell, the bilinear coefficients (c00, c10, c01, c11) of F_z then of F_q (rows).
    """

    aspect: float
    domain: SurrogateDomain
    ns: int
    nv: int
    shift: float
    v0: float
    hs: float
    hv: float
    coef: np.ndarray  # (8, ns * nv): one row per coefficient, so that each gather is contiguous
    max_error: float  # largest relative vector error against exact at cell centres and edge midpoints
    build_s: float  # wall time of the build, s


def _table_samples(aspect: float, shift: float, s: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """F_z, F_q on the grid s x v (see SurrogateTable), for unit radius and polarization."""
    unit = Magnet(1.0, aspect, 1.0)
    S, V = np.meshgrid(s, v, indexing="ij")
    rho, z = np.sqrt(S), -(np.exp(V) + shift)
    bz, brho = _kernel(unit, rho.ravel(), z.ravel())
    bz, brho = bz.reshape(S.shape), brho.reshape(S.shape)
    q = np.divide(brho, rho, out=np.zeros_like(brho), where=rho > 0)
    q[0] = -0.5 * axis_dbz_dz(unit, z[0], 1) / GAUSS_PER_TESLA  # s = 0: B_rho / r -> -Bz0'(z) / 2
    w = z * z
    return bz * w, q * w


@lru_cache(maxsize=16)
def _build_table(aspect: float, domain: SurrogateDomain) -> SurrogateTable:
    import magpylib.core  # noqa: F401 - imported before the clock starts: build_s is the build alone

    t0 = time.perf_counter()
    h = aspect / 2.0
    smax = domain.rho_max**2
    shift = h - min(h, 1.0)
    v0, v1 = math.log(h - shift + domain.gap_min), math.log(h - shift + domain.gap_max)
    ns, nv = max(8, math.ceil(smax * _S_CELLS)), max(8, math.ceil((v1 - v0) * _V_CELLS))
    s, v = np.linspace(0.0, smax, ns + 1), np.linspace(v0, v1, nv + 1)
    fz, fq = _table_samples(aspect, shift, s, v)
    blocks = []
    for f in (fz, fq):
        c00 = f[:-1, :-1]
        blocks += [c00, f[1:, :-1] - c00, f[:-1, 1:] - c00, f[1:, 1:] - f[1:, :-1] - f[:-1, 1:] + c00]
    coef = np.ascontiguousarray(np.stack([b.ravel() for b in blocks], axis=0))
    table = SurrogateTable(aspect, domain, ns, nv, shift, v0, smax / ns, (v1 - v0) / nv, coef, math.nan, math.nan)
    err = _self_check(table, s, v)
    if not err <= SURROGATE_BUILD_RTOL:
        raise FieldModelError(f"surrogate: the table for H/R = {aspect:g} over {domain} misses its own check "
                              f"({err:.2g} > {SURROGATE_BUILD_RTOL:g}); use exact")
    return replace(table, max_error=err, build_s=time.perf_counter() - t0)


def _self_check(t: SurrogateTable, s: np.ndarray, v: np.ndarray) -> float:
    """Largest relative error of table ``t`` (nodes ``s`` x ``v``) against exact where bilinear
    interpolation errs most: the cell centres and the midpoints of the cell edges."""
    sm, vm = 0.5 * (s[1:] + s[:-1]), 0.5 * (v[1:] + v[:-1])
    pairs = [np.meshgrid(a, b, indexing="ij") for a, b in ((sm, vm), (s, vm), (sm, v))]
    S, V = (np.concatenate([g[k].ravel() for g in pairs]) for k in (0, 1))
    pts = np.column_stack([np.sqrt(S), np.zeros(S.size), -(np.exp(V) + t.shift)])
    got = _evaluate(t, pts, 1.0, 1.0)
    want = exact(Magnet(1.0, t.aspect, 1.0), pts, rtol=None) / GAUSS_PER_TESLA
    return float(np.max(np.linalg.norm(got - want, axis=1) / np.linalg.norm(want, axis=1)))


def surrogate_table(aspect: float, domain: SurrogateDomain = SurrogateDomain()) -> SurrogateTable:
    """The (cached) table for aspect H/R, rounded to 9 significant digits so nearby magnets share it.

    Deterministic: the same aspect and domain always give the same numbers. Built in ~0.1 s.
    """
    if not (math.isfinite(aspect) and aspect > 0):
        raise ValueError(f"aspect must be a positive finite H/R; instead received {aspect!r}")
    return _build_table(float(f"{aspect:.9g}"), domain)


#: Points per block in :func:`_evaluate`. Whole-array temporaries (~30 per call, 0.8 MB each at 10^5
#: points) are returned to the OS between calls and page-faulted back in, which cost 3-4x the
#: arithmetic; blocks of this size reuse one small set of buffers that stays in cache.
_BLOCK = 16384
#: Rounding allowance at the table's edges, in cells.
_SLACK = 1e-9


def _evaluate(t: SurrogateTable, p: np.ndarray, radius: float, scale: float) -> np.ndarray:
    """Interpolate table ``t`` at points ``p`` ((N, 3), mm) of a magnet of ``radius`` mm; ``scale`` =
    Br_rem in the output unit. Raises if a point is outside the table. The hot path."""
    n = len(p)
    out = np.empty((n, 3))
    work = np.empty((16, min(n, _BLOCK)))
    idx = np.empty((2, min(n, _BLOCK)), dtype=np.intp)
    ku, v_off, kv = 1.0 / (radius * radius * t.hs), t.v0 + math.log(radius), 1.0 / t.hv
    z_off = t.shift * radius
    kz, kq = scale * radius * radius, -scale * radius
    for start in range(0, n, _BLOCK):
        stop = min(n, start + _BLOCK)
        m = stop - start
        x, y, z = p[start:stop, 0], p[start:stop, 1], p[start:stop, 2]
        u, v, az, fu, fv, fz, fq, tmp, *c = (w[:m] for w in work)
        i, j = idx[0, :m], idx[1, :m]
        np.multiply(x, x, out=u)
        np.multiply(y, y, out=tmp)
        u += tmp
        u *= ku  # (r/R)^2 in cells
        np.abs(z, out=az)
        np.subtract(az, z_off, out=v)
        with np.errstate(divide="ignore", invalid="ignore"):  # z = 0 or inside a long magnet: refused below
            np.log(v, out=v)
        v -= v_off
        v *= kv  # ln(|z|/R - shift) in cells
        if not (u.max() <= t.ns + _SLACK and v.min() >= -_SLACK and v.max() <= t.nv + _SLACK):  # NaN-safe
            _refuse_outside(t, p, radius)
        np.copyto(i, u, casting="unsafe")  # truncation = floor, as both are > -1 here
        np.copyto(j, v, casting="unsafe")
        np.minimum(i, t.ns - 1, out=i)  # the far edges belong to the last cell
        np.minimum(j, t.nv - 1, out=j)
        np.subtract(u, i, out=fu)
        np.subtract(v, j, out=fv)
        i *= t.nv
        i += j
        for row, dest in zip(t.coef, c):
            np.take(row, i, out=dest, mode="clip")
        # F = c00 + c10 fu + fv (c01 + c11 fu), for F_z (c[0:4]) and F_q (c[4:8])
        for f, (c00, c10, c01, c11) in ((fz, c[0:4]), (fq, c[4:8])):
            np.multiply(c11, fu, out=f)
            f += c01
            f *= fv
            f += c00
            np.multiply(c10, fu, out=tmp)
            f += tmp
        # undo zeta^2 = (z/R)^2; B_rho is odd in z (the table is for z < 0): q = -F_q Br R / (z |z|)
        np.multiply(az, az, out=tmp)
        fz *= kz
        np.divide(fz, tmp, out=out[start:stop, 2])
        np.multiply(z, az, out=tmp)
        fq *= kq
        fq /= tmp
        np.multiply(x, fq, out=out[start:stop, 0])
        np.multiply(y, fq, out=out[start:stop, 1])
    return out


def _refuse_outside(t: SurrogateTable, p: np.ndarray, radius: float) -> None:
    """Raise for the points of ``p`` that fall outside table ``t`` (same test as :func:`_evaluate`)."""
    d = t.domain
    u = (p[:, 0] ** 2 + p[:, 1] ** 2) / (radius * radius * t.hs)
    with np.errstate(invalid="ignore", divide="ignore"):
        v = (np.log(np.abs(p[:, 2]) - t.shift * radius) - t.v0 - math.log(radius)) / t.hv
    bad = ~((u <= t.ns + _SLACK) & (v >= -_SLACK) & (v <= t.nv + _SLACK))
    raise FieldModelError(
        f"surrogate: {_where(p, bad)} are outside its table (r <= {d.rho_max:g} R, gap to the nearer face "
        f"{d.gap_min:g} R to {d.gap_max:g} R); use exact, or dipole far away")


def surrogate(magnet: Magnet, points_mm: object, *, rtol: float | None = DEFAULT_RTOL,
              domain: SurrogateDomain = SurrogateDomain()) -> np.ndarray:
    """Field (Bx, By, Bz), G, interpolated from the dimensionless table of the magnet's aspect.

    Raises :class:`FieldModelError` outside ``domain`` (which lies outside the magnet), and when
    ``rtol`` is tighter than the error the table measured on itself (``SurrogateTable.max_error``,
    at the cell centres and edge midpoints, where bilinear interpolation errs most).
    """
    p = _points(points_mm)
    table = surrogate_table(magnet.aspect, domain)
    if rtol is not None and table.max_error > rtol:
        raise FieldModelError(f"surrogate: its table is good to {table.max_error:.2g}, not rtol {rtol:g}; use exact")
    return _shaped(points_mm, _evaluate(table, p, magnet.radius_mm, magnet.remanence_T * GAUSS_PER_TESLA))


# ---- working volume and errors --------------------------------------------------------------------


def working_volume(magnet: Magnet, d_min_mm: float, d_max_mm: float, n: int = 24,
                   r_max_mm: float | None = None) -> np.ndarray:
    """Sensor positions relative to the magnet, (n * n, 3) mm in the magnet frame.

    An n x n grid of axial distance d (lower face to sensing point, d_min..d_max) and radial offset r
    (0..r_max, default the magnet radius: its lateral travel must stay under R), the azimuth turning
    by the golden angle from point to point so that Bx and By are both exercised.
    """
    if not (0 < d_min_mm <= d_max_mm and math.isfinite(d_max_mm)):
        raise ValueError(f"need 0 < d_min_mm <= d_max_mm; instead received {d_min_mm!r}, {d_max_mm!r}")
    if n < 2:
        raise ValueError(f"n must be at least 2; instead received {n!r}")
    r_max = magnet.radius_mm if r_max_mm is None else r_max_mm
    if not (0 <= r_max < math.inf):
        raise ValueError(f"r_max_mm must be finite and >= 0; instead received {r_max_mm!r}")
    d, r = np.meshgrid(np.linspace(d_min_mm, d_max_mm, n), np.linspace(0.0, r_max, n), indexing="ij")
    phi = np.arange(n * n) * (math.pi * (3.0 - math.sqrt(5.0)))
    r = r.ravel()
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), -(magnet.height_mm / 2.0 + d.ravel())])


@dataclass(frozen=True)
class ModelError:
    """Error of a model against :func:`exact` over a set of points.

    ``relative``: max over points of |B_model - B_exact| / |B_exact| (vector norms).
    ``normalised``: max |B_model - B_exact| / max |B_exact| -- the figure to quote where |B| gets small.
    ``worst_index``: the point with the largest relative error.
    """

    relative: float
    normalised: float
    worst_index: int
    n_points: int


def _errors(b: np.ndarray, ref: np.ndarray) -> ModelError:
    diff = np.linalg.norm(b - ref, axis=1)
    size = np.linalg.norm(ref, axis=1)
    rel = diff / size
    k = int(np.argmax(rel))
    return ModelError(float(rel[k]), float(diff.max() / size.max()), k, len(ref))


def model_error(model: "str | Callable[[Magnet, np.ndarray], np.ndarray]", magnet: Magnet,
                points_mm: object) -> ModelError:
    """Error of ``model`` (a name in :data:`MODELS`, evaluated with ``rtol=None``, or a callable
    ``f(magnet, points) -> (N, 3) G``) against :func:`exact` at ``points_mm``."""
    p = _points(points_mm)
    func = (lambda m, q: MODELS[model].func(m, q, rtol=None)) if isinstance(model, str) else model
    return _errors(np.asarray(func(magnet, p)).reshape(-1, 3), exact(magnet, p))


# ---- registry and model choice --------------------------------------------------------------------


@dataclass(frozen=True)
class Model:
    """A field model: ``func(magnet, points_mm, *, rtol) -> (N, 3) G``; ``cost_rank`` orders them from
    cheapest (0), as measured by :func:`measure` (bench/field.py prints the times)."""

    name: str
    func: Callable[..., np.ndarray]
    description: str
    cost_rank: int


MODELS: Mapping[str, Model] = MappingProxyType({
    m.name: m for m in (
        Model("on_axis", on_axis, "eq. 6: Bz on the axis, Br = 0 (exact on the axis only)", 0),
        Model("dipole", dipole, "point dipole m = Br V / mu0 (far field)", 1),
        Model("surrogate", surrogate, "bilinear table of the exact field in (r/R)^2 and ln|z|, per H/R", 2),
        Model("exact", exact, "Derby & Olbert elliptic integrals (magpylib's kernel)", 3),
    )
})


@dataclass(frozen=True)
class Choice:
    """The cheapest model within tolerance, its measured error, and every model tried (name, error;
    ``inf`` when the model refused the points)."""

    model: str
    error: float
    tried: tuple[tuple[str, float], ...]


def _sample(p: np.ndarray, size: int) -> np.ndarray:
    """Evenly spaced subset of ``p`` plus its extreme points (nearest, farthest, most off-axis)."""
    if len(p) <= size:
        return p
    idx = set(np.linspace(0, len(p) - 1, size).round().astype(int).tolist())
    rho = np.hypot(p[:, 0], p[:, 1])
    az = np.abs(p[:, 2])
    idx |= {int(np.argmax(rho)), int(np.argmin(az)), int(np.argmax(az)), int(np.argmax(rho / az))}
    return p[sorted(idx)]


def choose(magnet: Magnet, points_mm: object, tolerance: float, sample: int = 256) -> Choice:
    """The cheapest model (by ``cost_rank``) whose relative error against :func:`exact`, measured on a
    deterministic sample of ``points_mm`` (at most ``sample`` points plus the extreme ones), is at most
    ``tolerance``. :func:`exact` itself always qualifies (error 0)."""
    if not (tolerance > 0):
        raise ValueError(f"tolerance must be positive; instead received {tolerance!r}")
    p = _sample(_points(points_mm), sample)
    ref = exact(magnet, p)
    tried = []
    for m in sorted(MODELS.values(), key=lambda m: m.cost_rank):
        if m.name == "exact":
            tried.append(("exact", 0.0))
            return Choice("exact", 0.0, tuple(tried))
        try:
            err = _errors(m.func(magnet, p, rtol=None), ref).relative
        except FieldModelError:
            err = math.inf
        tried.append((m.name, err))
        if err <= tolerance:
            return Choice(m.name, err, tuple(tried))
    raise AssertionError("unreachable: exact is in MODELS")


# ---- the sensor's view: (Bz, Br) against (d, r) ---------------------------------------------------


def _sensor_points(magnet: Magnet, d_mm: object, r_mm: object) -> tuple[np.ndarray, tuple[int, ...]]:
    d, r = np.broadcast_arrays(np.asarray(d_mm, dtype=float), np.asarray(r_mm, dtype=float))
    if (r < 0).any() or not np.isfinite(r).all():
        raise ValueError(f"r_mm must be finite and >= 0; instead received {r_mm!r}")
    if (d <= 0).any() or not np.isfinite(d).all():
        raise ValueError(f"d_mm must be finite and > 0; instead received {d_mm!r}")
    pts = np.column_stack([r.ravel(), np.zeros(r.size), -(magnet.height_mm / 2.0 + d.ravel())])
    return pts, d.shape


def bz_br(magnet: Magnet, d_mm: object, r_mm: object = 0.0, model: str = "exact",
          rtol: float | None = DEFAULT_RTOL) -> tuple[np.ndarray, np.ndarray]:
    """(Bz, Br) in G seen by a sensor at axial distance d below the lower face and radial offset r (mm,
    broadcast together). Br = sqrt(Bx^2 + By^2) >= 0 as in BRIEF eq. 4 (the radial field points inwards
    below the magnet). ``rtol`` goes to the model (ignored by exact, which keeps its own)."""
    pts, shape = _sensor_points(magnet, d_mm, r_mm)
    b = _call(model, magnet, pts, rtol)
    return b[:, 2].reshape(shape)[()], np.hypot(b[:, 0], b[:, 1]).reshape(shape)[()]


def _call(model: str, magnet: Magnet, pts: np.ndarray, rtol: float | None) -> np.ndarray:
    if model not in MODELS:
        raise ValueError(f"model must be one of {', '.join(MODELS)}; instead received {model!r}")
    if model == "exact":
        return exact(magnet, pts)
    return MODELS[model].func(magnet, pts, rtol=rtol)


#: Central-difference step for :func:`dbz_dz`, in magnet radii. Exact and dipole are smooth: a small
#: step (truncation ~1e-7, rounding ~1e-12). The surrogate is piecewise bilinear: the step must span
#: several cells (error ~1e-3, see tests).
FD_STEP = {"exact": 1e-4, "dipole": 1e-4, "surrogate": 0.05}


def dbz_dz(magnet: Magnet, d_mm: object, r_mm: object = 0.0, model: str = "exact",
           rtol: float | None = DEFAULT_RTOL) -> np.ndarray:
    """dBz/dz at the sensor, G/mm: z is the sensor's coordinate along the magnet axis (magnet frame, up),
    so this is the rate at which Bz grows as the gap d closes (= -dBz/dd; positive below the magnet).

    Analytic for ``on_axis`` (eq. 6 differentiated); central differences otherwise (``FD_STEP``).
    """
    pts, shape = _sensor_points(magnet, d_mm, r_mm)
    if model == "on_axis":
        _call(model, magnet, pts, rtol)  # its off-axis check
        return axis_dbz_dz(magnet, pts[:, 2]).reshape(shape)[()]
    step = FD_STEP.get(model)
    if step is None:
        raise ValueError(f"model must be one of {', '.join(MODELS)}; instead received {model!r}")
    dz = np.array([0.0, 0.0, step * magnet.radius_mm])
    up, down = _call(model, magnet, pts + dz, rtol), _call(model, magnet, pts - dz, rtol)
    return ((up[:, 2] - down[:, 2]) / (2.0 * dz[2])).reshape(shape)[()]


# ---- speed against accuracy -----------------------------------------------------------------------


@dataclass(frozen=True)
class Measurement:
    """One model over a working volume: error against magpylib's Cylinder (see :class:`ModelError`),
    median and fastest wall time per 10^5 points (s), speed ratio of the medians to magpylib in the same
    run, one-off setup (s; the time the surrogate's table took to build)."""

    model: str
    description: str
    relative_error: float
    normalised_error: float
    time_per_1e5_s: float
    time_min_per_1e5_s: float
    speedup_vs_magpylib: float
    setup_s: float


def measure(magnet: Magnet, d_min_mm: float, d_max_mm: float, n: int = 317, repeat: int = 7,
            extra: Sequence[tuple[str, str, Callable[[Magnet, np.ndarray], np.ndarray]]] = ()) -> list[Measurement]:
    """magpylib, every model of :data:`MODELS` and any ``extra`` (name, description, func) candidates over
    the working volume (n x n points; 317^2 ~ 10^5): the error against ``magpylib.magnet.Cylinder`` and
    the wall time of ``repeat`` calls each, scaled to 10^5 points.

    The calls are timed round-robin (one call of each model per round) so that a change of machine load
    during the run hits every model alike; the first, untimed call of each gives its error. Approximate
    models run with ``rtol=None`` so that their error is measured where they would refuse. The
    surrogate's table is built before anything is timed; its build time is the row's ``setup_s``.
    """
    pts = working_volume(magnet, d_min_mm, d_max_mm, n)
    table_s = surrogate_table(magnet.aspect).build_s
    runs = [("magpylib", "magpylib.magnet.Cylinder(...).getB, the reference", magpylib_cylinder)]
    runs += [(m.name, m.description, (lambda f: lambda mg, q: f(mg, q, rtol=None))(m.func))
             for m in sorted(MODELS.values(), key=lambda m: m.cost_rank)]
    runs += list(extra)
    ref = magpylib_cylinder(magnet, pts)
    errors = {name: _errors(np.asarray(func(magnet, pts)), ref) for name, _, func in runs}
    samples: dict[str, list[float]] = {name: [] for name, _, _ in runs}
    for _ in range(repeat):
        for name, _, func in runs:
            t = time.perf_counter()
            func(magnet, pts)
            samples[name].append((time.perf_counter() - t) * 1e5 / len(pts))
    t_ref = statistics.median(samples["magpylib"])
    return [Measurement(name, description, errors[name].relative, errors[name].normalised,
                        statistics.median(samples[name]), min(samples[name]),
                        t_ref / statistics.median(samples[name]), table_s if name == "surrogate" else 0.0)
            for name, description, _ in runs]
