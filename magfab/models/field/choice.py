"""Which model where: the working volume, a model's error against the exact field, the registry of models
and the choice of the cheapest one within a tolerance.

Error of a model at a point: ``|B_model - B_exact| / |B_exact|`` with vector norms. The vector norm does not
vanish outside the magnet, so this stays finite where Bz alone crosses zero off the axis (component-wise
relative errors would explode there). :func:`model_error` also gives the error normalised by the largest |B|
over the points, the figure to quote where |B| itself becomes small.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType

import numpy as np
from numpy.typing import ArrayLike

from ...spec import FieldModel
from .closed_forms import dipole, on_axis
from .exact import exact
from .magnet import FieldModelError, Magnet, _points
from .surrogate import surrogate

__all__ = ["FieldModel", "working_volume", "ModelAccuracy", "model_error", "Model", "MODELS", "model_name",
           "Choice", "choose"]


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
    d, r_grid = np.meshgrid(np.linspace(d_min_mm, d_max_mm, n), np.linspace(0.0, r_max, n), indexing="ij")
    phi = np.arange(n * n) * (math.pi * (3.0 - math.sqrt(5.0)))
    r = r_grid.ravel()
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), -(magnet.height_mm / 2.0 + d.ravel())])


@dataclass(frozen=True)
class ModelAccuracy:
    """Error of a model against :func:`exact` over a set of points.

    ``relative``: max over points of |B_model - B_exact| / |B_exact| (vector norms).
    ``normalised``: max |B_model - B_exact| / max |B_exact| -- the figure to quote where |B| gets small.
    ``worst_index``: the point with the largest relative error.
    """

    relative: float
    normalised: float
    worst_index: int
    n_points: int


def _errors(b: np.ndarray, ref: np.ndarray) -> ModelAccuracy:
    diff = np.linalg.norm(b - ref, axis=1)
    size = np.linalg.norm(ref, axis=1)
    rel = diff / size
    k = int(np.argmax(rel))
    return ModelAccuracy(float(rel[k]), float(diff.max() / size.max()), k, len(ref))


def model_error(model: FieldModel | str | Callable[[Magnet, np.ndarray], np.ndarray], magnet: Magnet,
                points_mm: ArrayLike) -> ModelAccuracy:
    """Error of ``model`` (a :class:`FieldModel` or its name, evaluated with ``rtol=None``, or a callable
    ``f(magnet, points) -> (N, 3) G``) against :func:`exact` at ``points_mm``."""
    p = _points(points_mm)
    if isinstance(model, str):
        entry = MODELS[model_name(model)]
        func = lambda m, q: entry.func(m, q, rtol=None)
    else:
        func = model
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
        Model("on_axis", on_axis, "Bz on the axis, Br = 0 (docs/models.md, M6; exact on the axis only)", 0),
        Model("dipole", dipole, "point dipole m = Br V / mu0 (far field)", 1),
        Model("surrogate", surrogate, "bilinear table of the exact field in (r/R)^2 and ln|z|, per H/R", 2),
        Model("exact", exact, "Derby & Olbert elliptic integrals (magpylib's kernel)", 3),
    )
})


def model_name(model: FieldModel | str) -> str:
    """The registry name of ``model`` (a :class:`FieldModel` other than ``auto``, or its value)."""
    try:
        kind = FieldModel(model)
    except ValueError:
        kind = FieldModel.AUTO
    if kind is FieldModel.AUTO:  # "auto" is :func:`choose`'s job, not a model
        raise ValueError(f"model must be one of {', '.join(MODELS)}; instead received {model!r}")
    return kind.value


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


def choose(magnet: Magnet, points_mm: ArrayLike, tolerance: float, sample: int = 256) -> Choice:
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
