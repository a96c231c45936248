"""The surrogate: a table of the dimensionless exact field over (r/R, z/R), one per aspect H/R.

Built lazily (~0.1 s) from :func:`~magfab.models.field.exact.exact` and interpolated bilinearly: within 1e-4
of it over the MagOne working volume (3e-4 anywhere in its domain) and 40-80x faster than magpylib's ``getB``.
Refuses points outside its table (:class:`SurrogateDomain`) and an ``rtol`` tighter than the error the
table measured on itself when it was built.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from ...units import GAUSS_PER_TESLA
from .closed_forms import axis_dbz_dz
from .exact import _kernel, exact
from .magnet import DEFAULT_RTOL, FieldModelError, Magnet, _points, _shaped, _where

# Imported lazily, inside the functions that use it, for speed: magpylib takes a
# noticeable time to import, and importing this module should not.

__all__ = ["SURROGATE_BUILD_RTOL", "SurrogateDomain", "SurrogateTable", "surrogate_table", "surrogate"]


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


def surrogate(magnet: Magnet, points_mm: ArrayLike, *, rtol: float | None = DEFAULT_RTOL,
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
