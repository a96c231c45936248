"""Studies of the FE itself, timed cold: mesh convergence (:func:`convergence`) and speed against accuracy of
every normal model (:func:`measure`, for bench/). Nothing here asserts on a time.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any

import numpy as np

from . import fe_surrogate
from .body import Body, Convergence, Curve, MechanicsError
from .closed_forms import column, hertz_column
from .discretisation import _axisym
from .fe import fe
from .mesh import _body_mesh, _unit_mesh
from .shear import _mode1_matrix
from .shear_surface import _operator

__all__ = ["convergence", "measure"]


def clear_caches() -> None:
    """Forget meshes and discretisations (for cold timings)."""
    for f in (_body_mesh, _unit_mesh, _axisym, _mode1_matrix, _operator):
        f.cache_clear()


def convergence(body: Body, mu_kPa: float, indentation_mm: Sequence[float] | np.ndarray,
                base_mesh_mm: float | None = None, levels: int = 3, **options: Any) -> Convergence:
    """FE on nested meshes (a base mesh, then ``levels`` uniform refinements halving the size) against the finest.

    ``error[k]`` = max over the curve of |F_k - F_finest| / max |F_finest|; ``rate`` the observed order of the
    last three meshes, log2(|F_{L-2} - F_{L-1}| / |F_{L-1} - F_L|) (Richardson: it needs no reference solution);
    ``rates`` every such triple's order, coarse to fine. Times are cold (caches cleared).
    """
    if int(levels) < 2:
        raise MechanicsError(f"Input levels must be at least 2 (three meshes give one rate); "
                             f"instead received {levels!r}")
    h0 = float(base_mesh_mm) if base_mesh_mm is not None else body.radius_mm / 6.0
    forces, times = [], []
    sizes_mm: list[float] = []
    for k in range(int(levels) + 1):
        clear_caches()
        t0 = time.perf_counter()
        c = fe(body, mu_kPa, indentation_mm, mesh_mm=h0, refine=k, **options)
        times.append(time.perf_counter() - t0)
        forces.append(c.force_N)
        assert c.mesh_mm is not None  # an FE curve records the mesh it was computed on
        sizes_mm.append(c.mesh_mm)
    F = np.array(forces)
    err = np.max(np.abs(F[:-1] - F[-1]), axis=1) / np.max(np.abs(F[-1]))
    diffs = np.max(np.abs(np.diff(F, axis=0)), axis=1)
    rates = np.log2(diffs[:-1] / diffs[1:])
    return Convergence(np.array(sizes_mm), F, err, float(rates[-1]), rates, sizes_mm[-1], np.array(times))


def measure(body: Body, mu_kPa: float, delta_max_mm: float, mesh_sizes_mm: Sequence[float] = (1.0, 0.75, 0.5, 0.35),
            reference_mesh_mm: float = 0.2, points: int = 13) -> dict[str, object]:
    """Speed against accuracy of every normal model on one body, for the chart.

    Runs the finest FE mesh (``reference_mesh_mm``) as the reference, then each closed form and the FE at each mesh
    size, on ``points`` indentations from 0 to ``delta_max_mm``. If the reference fails before ``delta_max_mm``
    (element inversion or excessive distortion), everything is compared over the range it reached and the failure
    is reported. Times are wall-clock seconds with caches cleared (meshing included).

    Returns {"rows": [{"model", "mesh_mm", "error", "time_s", "force_end_N", "failure"}...] (reference last),
    "compared_to_mm": float, "reference_failure": str | None}, where ``error`` is max |F - F_ref| / max |F_ref|
    over the compared range.
    """
    d = np.linspace(0.0, float(delta_max_mm), int(points))

    def timed(fn: Callable[[np.ndarray], Curve], dd: np.ndarray) -> tuple[Curve | None, float, str | None]:
        clear_caches()
        t0 = time.perf_counter()
        try:
            c = fn(dd)
        except MechanicsError as exc:
            return None, time.perf_counter() - t0, str(exc)
        return c, time.perf_counter() - t0, None

    ref, t_ref, _ = timed(lambda dd: fe(body, mu_kPa, dd, mesh_mm=reference_mesh_mm, on_failure="truncate"), d)
    assert ref is not None
    reached = ref.indentation_mm
    if reached.size < 2:
        raise MechanicsError(f"measure: the reference FE (mesh {reference_mesh_mm:g} mm) failed at once: "
                             f"{ref.info.get('failure')}")
    scale = float(np.max(np.abs(ref.force_N)))

    runs: list[tuple[str, float | None, Callable[[np.ndarray], Curve]]] = [
        ("column", None, lambda dd: column(body, mu_kPa, dd)),
        ("hertz_column", None, lambda dd: hertz_column(body, mu_kPa, dd)),
    ]
    if fe_surrogate.in_region(body):  # the design search's stand-in for the FE (its table loaded before the clock)
        fe_surrogate.held_out_error(body.tip)
        runs.append(("surrogate", None, lambda dd: fe_surrogate.curve(body, mu_kPa, dd)))
    for mesh in sorted((float(v) for v in mesh_sizes_mm), reverse=True):
        runs.append(("fe", mesh, partial(fe, body, mu_kPa, mesh_mm=mesh)))
    rows: list[dict[str, object]] = []
    for name, h, fn in runs:
        c, t, failure = timed(fn, reached)
        n = 0 if c is None else min(len(c.force_N), len(ref.force_N))  # the surrogate's curve may end at its reach
        err = math.nan if c is None else float(np.max(np.abs(c.force_N[:n] - ref.force_N[:n])) / scale)
        if c is not None and n < len(ref.force_N):
            failure = f"the curve ends at {float(c.indentation_mm[-1]):g} mm"
        rows.append({"model": name, "mesh_mm": h, "error": err, "time_s": t,
                     "force_end_N": math.nan if c is None else float(c.force_N[-1]), "failure": failure})
    rows.append({"model": "fe", "mesh_mm": float(reference_mesh_mm), "error": 0.0, "time_s": t_ref,
                 "force_end_N": float(ref.force_N[-1]), "failure": None})
    return {"rows": rows, "compared_to_mm": float(reached[-1]), "reference_failure": ref.info.get("failure")}
