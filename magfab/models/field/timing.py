"""Speed against accuracy: every model over a working volume, timed against magpylib's Cylinder.

For the benchmarks (bench/field.py) and the speed-accuracy chart; never asserted on in tests.
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from .choice import MODELS, _errors, working_volume
from .exact import magpylib_cylinder
from .magnet import Magnet
from .surrogate import surrogate_table

__all__ = ["Measurement", "measure"]


@dataclass(frozen=True)
class Measurement:
    """One model over a working volume: error against magpylib's Cylinder (see
    :class:`~magfab.models.field.choice.ModelAccuracy`), median and fastest wall time per 10^5 points (s),
    speed ratio of the medians to magpylib in the same run, one-off setup (s; the time the surrogate's
    table took to build)."""

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
    runs: list[tuple[str, str, Callable[[Magnet, np.ndarray], np.ndarray]]] = [
        ("magpylib", "magpylib.magnet.Cylinder(...).getB, the reference", magpylib_cylinder)]
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
