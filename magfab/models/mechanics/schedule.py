"""The FE mesh schedule: which meshes the automatic FE choice runs for a design, coarse to fine.

One home for the schedule, so the prediction (:func:`magfab.models.predict.normal_curve`) solves on exactly the
meshes the cost limits (:mod:`magfab.limits`) estimated before the build.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ...design import Design

__all__ = ["FE_MESHES_MM", "FE_ORDER", "FE_ERROR_PER_H_OVER_R", "fe_meshes"]

#: Mesh sizes (mm) the automatic FE choice tries, coarse to fine; each is checked against the next finer.
FE_MESHES_MM = (1.0, 0.75, 0.5, 0.35)
#: Observed convergence order of the FE force under refinement (bench/mechanics.py measures it).
FE_ORDER = 1.0
#: Relative FE error per mesh size over the elastomer radius, err ~ C h / R (order 1, as FE_ORDER):
#: with the magnet's edges rounded and the mesh graded there, MagOne measured 0.0018 at h = 0.75 mm against 1 mm,
#: R = 6 mm (C = 0.014); 2x margin.
FE_ERROR_PER_H_OVER_R = 0.03


def fe_meshes(design: Design, tolerance_pct: float | None = None) -> tuple[float, ...]:
    """The FE meshes (mm) the normal curve is expected to run for ``predict.tolerance_pct`` (or the one given):
    coarse to fine from :data:`FE_MESHES_MM`, at least two, until the estimated error C h / R fits the tolerance;
    none for a closed-form mechanics model."""
    p = design.spec.predict
    if p.mechanics_model.value in ("column", "hertz_column"):
        return ()
    tol = (p.tolerance_pct if tolerance_pct is None else tolerance_pct) / 100.0
    meshes: list[float] = []
    for h in FE_MESHES_MM:
        meshes.append(h)
        if len(meshes) >= 2 and FE_ERROR_PER_H_OVER_R * h / design.elastomer_radius_mm <= tol:
            break
    return tuple(meshes)
