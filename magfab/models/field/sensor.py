"""The sensor's view: (Bz, Br) and dBz/dz against the axial distance d below the magnet's lower face and
the radial offset r, in G and G/mm, with any model of the registry."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from ...spec import FieldModel
from .choice import MODELS, model_name
from .closed_forms import axis_dbz_dz
from .exact import exact
from .magnet import DEFAULT_RTOL, Magnet

__all__ = ["bz_br", "dbz_dz", "saturation_gap", "FD_STEP"]

#: Central-difference step for :func:`dbz_dz`, in magnet radii. Exact and dipole are smooth: a small
#: step (truncation ~1e-7, rounding ~1e-12). The surrogate is piecewise bilinear: the step must span
#: several cells (error ~1e-3, see tests).
FD_STEP = {FieldModel.EXACT.value: 1e-4, FieldModel.DIPOLE.value: 1e-4, FieldModel.SURROGATE.value: 0.05}


def _sensor_points(magnet: Magnet, d_mm: ArrayLike, r_mm: ArrayLike) -> tuple[np.ndarray, tuple[int, ...]]:
    d, r = np.broadcast_arrays(np.asarray(d_mm, dtype=float), np.asarray(r_mm, dtype=float))
    if (r < 0).any() or not np.isfinite(r).all():
        raise ValueError(f"r_mm must be finite and >= 0; instead received {r_mm!r}")
    if (d <= 0).any() or not np.isfinite(d).all():
        raise ValueError(f"d_mm must be finite and > 0; instead received {d_mm!r}")
    pts = np.column_stack([r.ravel(), np.zeros(r.size), -(magnet.height_mm / 2.0 + d.ravel())])
    return pts, d.shape


def _call(name: str, magnet: Magnet, pts: np.ndarray, rtol: float | None) -> np.ndarray:
    if name == FieldModel.EXACT.value:
        return exact(magnet, pts)
    return MODELS[name].func(magnet, pts, rtol=rtol)


def bz_br(magnet: Magnet, d_mm: ArrayLike, r_mm: ArrayLike = 0.0, model: FieldModel | str = FieldModel.EXACT,
          rtol: float | None = DEFAULT_RTOL) -> tuple[np.ndarray, np.ndarray]:
    """(Bz, Br) in G seen by a sensor at axial distance d below the lower face and radial offset r (mm,
    broadcast together). Br = sqrt(Bx^2 + By^2) >= 0 as in docs/models.md, M3 (the radial field points inwards
    below the magnet). ``rtol`` goes to the model (ignored by exact, which keeps its own)."""
    name = model_name(model)
    pts, shape = _sensor_points(magnet, d_mm, r_mm)
    b = _call(name, magnet, pts, rtol)
    return b[:, 2].reshape(shape)[()], np.hypot(b[:, 0], b[:, 1]).reshape(shape)[()]


def dbz_dz(magnet: Magnet, d_mm: ArrayLike, r_mm: ArrayLike = 0.0, model: FieldModel | str = FieldModel.EXACT,
           rtol: float | None = DEFAULT_RTOL) -> np.ndarray:
    """dBz/dz at the sensor, G/mm: z is the sensor's coordinate along the magnet axis (magnet frame, up),
    so this is the rate at which Bz grows as the gap d closes (= -dBz/dd; positive below the magnet).

    Analytic for ``on_axis`` (docs/models.md, M6, differentiated); central differences otherwise (``FD_STEP``).
    """
    name = model_name(model)
    pts, shape = _sensor_points(magnet, d_mm, r_mm)
    if name == FieldModel.ON_AXIS.value:
        _call(name, magnet, pts, rtol)  # its off-axis check
        return axis_dbz_dz(magnet, pts[:, 2]).reshape(shape)[()]
    dz = np.array([0.0, 0.0, FD_STEP[name] * magnet.radius_mm])
    up, down = _call(name, magnet, pts + dz, rtol), _call(name, magnet, pts - dz, rtol)
    return ((up[:, 2] - down[:, 2]) / (2.0 * dz[2])).reshape(shape)[()]


def saturation_gap(magnet: Magnet, full_scale_G: float, lo: float = 1e-3, hi: float = 1.0) -> float:
    """The axial distance d (mm) at which the exact Bz on the axis falls to ``full_scale_G``: nearer, a chip of that
    full scale saturates. Bisection (Bz falls with d) between ``lo`` and ``hi``, ``hi`` first doubled until the field
    there is under full scale; ``lo`` when the field is under it there already."""
    def over(d: float) -> bool:
        return float(bz_br(magnet, d, 0.0, model=FieldModel.EXACT)[0]) > full_scale_G

    if not over(lo):
        return lo
    while over(hi) and hi < 1e4:
        lo, hi = hi, 2.0 * hi
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if over(mid) else (lo, mid)
    return hi
