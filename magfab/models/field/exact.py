"""The exact field: Derby & Olbert (2010), complete elliptic integrals, by magpylib's own kernel.

``magpylib.core.magnet_cylinder_axial_Bfield`` is the code ``magpylib.magnet.Cylinder`` runs; called directly
on cylindrical coordinates it skips ``getB``'s per-call bookkeeping (3-5x faster). Our own Derby-Olbert code
with Bulirsch's cel (bench/field.py) ran at 1.0-1.6x the speed of that kernel, not worth a second copy of the
special functions. magpylib is imported inside the functions, so importing this module stays cheap.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ...units import GAUSS_PER_TESLA
from .magnet import EXACT_RTOL, FieldModelError, Magnet, _cartesian, _points, _refuse_inside, _shaped, _where

# Imported lazily, inside the functions that use it, for speed: magpylib takes a
# noticeable time to import, and importing this module should not.

__all__ = ["exact", "exact_rounding_estimate", "magpylib_cylinder"]

_EPS = float(np.finfo(float).eps)


def _kernel(magnet: Magnet, rho_mm: np.ndarray, z_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Bz, B_rho) per unit polarization (dimensionless) by magpylib's Derby-Olbert kernel."""
    from magpylib.core import magnet_cylinder_axial_Bfield

    R = magnet.radius_mm
    b = magnet_cylinder_axial_Bfield(np.full(rho_mm.shape, magnet.height_mm / (2.0 * R)), rho_mm / R, z_mm / R)
    return b[2], b[0]


def exact_rounding_estimate(magnet: Magnet, points_mm: ArrayLike) -> np.ndarray:
    """Upper estimate of the relative rounding error of the elliptic-integral form at each point, (N,).

    Far away the field is the small difference of the two faces' terms, each ~Br_rem, while B ~ Br_rem
    R^2 H / D^3 (D from the centre): 4 eps D^3 / (R^2 H). Measured against the cancellation-free axial form
    (docs/models.md, M6) on the axis, where it is worst, for H/R 0.05 to 8 and D = 10 R to 10^5 R: the actual error
    stays under half of this; off the axis it is ~100x smaller still.
    """
    p = _points(points_mm)
    d3 = np.sum(p * p, axis=1) ** 1.5
    return 4.0 * _EPS * d3 / (magnet.radius_mm**2 * magnet.height_mm)


def exact(magnet: Magnet, points_mm: ArrayLike, *, rtol: float | None = EXACT_RTOL) -> np.ndarray:
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


def magpylib_cylinder(magnet: Magnet, points_mm: ArrayLike) -> np.ndarray:
    """The reference: ``magpylib.magnet.Cylinder(...).getB`` in SI, returned in G, no checks."""
    import magpylib

    p = _points(points_mm)
    cyl = magpylib.magnet.Cylinder(dimension=(2e-3 * magnet.radius_mm, 1e-3 * magnet.height_mm),
                                   polarization=(0.0, 0.0, magnet.remanence_T))
    b = np.asarray(cyl.getB(p * 1e-3), dtype=float).reshape(-1, 3)
    return _shaped(points_mm, b * GAUSS_PER_TESLA)
