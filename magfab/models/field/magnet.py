"""The magnet (an axially magnetised cylinder), the checks every model runs on its points, and the refusal.

Lengths in mm, remanence in T; the magnet is centred at the origin, axis on z, magnetised along +z.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from ...errors import ModelLimitError
from ...recipes.resolve import magnet_grade

if TYPE_CHECKING:
    from ...design import Design
    from ...recipes.resolve import MagnetGrade
    from ...spec import Spec

__all__ = ["FieldModelError", "Magnet", "MU0", "DEFAULT_RTOL", "EXACT_RTOL", "SURFACE_GAP"]

MU0 = 4.0e-7 * math.pi  # T m / A (the pre-2019 defined value; CODATA 2018's differs by 5.5e-10 relative)

#: Default error budget of the approximate models against the exact field: 0.1 %.
DEFAULT_RTOL = 1e-3
#: :func:`exact` is the reference the others are checked against, so it must be far better than them.
EXACT_RTOL = 1e-6
#: Points closer than this many magnet radii to the magnet (or inside it) are refused by every model.
SURFACE_GAP = 1e-6


class FieldModelError(ModelLimitError):
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
    def of(cls, spec: Spec, grade: MagnetGrade, band: str = "nominal") -> Magnet:
        """The spec's magnet disc with the remanence of ``grade`` (``band``: low, nominal or high)."""
        if band not in ("low", "nominal", "high"):
            raise ValueError(f"band must be 'low', 'nominal' or 'high'; instead received {band!r}")
        return cls(spec.magnet.diameter_mm / 2.0, spec.magnet.height_mm, getattr(grade.remanence_T, band))

    @classmethod
    def from_design(cls, design: Design, band: str = "nominal") -> Magnet:
        """The design's magnet, its remanence from the grade the design resolved (``band``: low, nominal or high)."""
        return cls.of(design.spec, design.magnet_grade, band)

    @classmethod
    def from_spec(cls, spec: Spec, band: str = "nominal") -> Magnet:
        """The spec's magnet, for scripts that hold a spec and no Design (the models take :meth:`from_design`)."""
        return cls.of(spec, magnet_grade(spec.magnet.grade), band)

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


def _points(points_mm: ArrayLike) -> np.ndarray:
    """``points_mm`` as a float (N, 3) array (a single (3,) point becomes (1, 3))."""
    p = np.asarray(points_mm, dtype=float)
    if p.ndim == 1 and p.shape[0] == 3:
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points_mm must be an array of shape (N, 3) in mm; instead received shape {p.shape}")
    if not np.isfinite(p).all():
        raise ValueError("points_mm must be finite; instead received NaN or infinity")
    return p


def _shaped(points_mm: ArrayLike, field: np.ndarray) -> np.ndarray:
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


def _refuse_estimate(p: np.ndarray, est: np.ndarray, rtol: float, message: Callable[[str, str], str]) -> None:
    """Raise :class:`FieldModelError` where a model's error estimate exceeds ``rtol``."""
    bad = est > rtol
    if bad.any():
        worst = "unbounded (inside the circumscribed sphere)" if np.isinf(est).any() else f"up to {est.max():.2g}"
        raise FieldModelError(message(_where(p, bad), worst))
