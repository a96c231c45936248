"""One design of the search, evaluated: the point's spec, its geometry checks, the model chain and the design
constraints (docs/models.md, M9).

:func:`evaluate` is what a Dask worker runs. It takes and returns plain data (the point, the base spec and the
targets as JSON), never raises, and says which models it used:

``surrogate``
    The elastomer surrogate (:mod:`magfab.models.mechanics.fe_surrogate`) in place of the FE, and the cheapest field
    model within tolerance: milliseconds per design. A body outside the surrogate's validated region falls back to
    the FE (``fe (outside surrogate region)``).
``fe``
    The full chain ``magfab build`` runs (:func:`magfab.models.predict.predict`, FE on the mesh its error estimate
    picks): what the designs near the front are re-verified with.

A design the spec or the models refuse is ``failed`` with the one-line reason; one that violates a requirement or
an error-level design check (M9: saturation at d_min, the resolution asked for; the printer's minimums) is
``infeasible``, with its figures and the violations, which Optuna's constrained samplers read.
"""

from __future__ import annotations

import os
import time
import traceback
from functools import lru_cache
from typing import Any

from ..check import design_findings, errors_in, predict_with_findings, preflight
from ..design import derive
from ..errors import InputError, ModelLimitError, Severity
from ..models import mechanics as mech
from ..models.mechanics import fe_surrogate
from ..models.predict import surrogate_curve
from ..spec import FieldModel, Spec
from .space import candidate_spec
from .targets import Models, Objective, Targets

__all__ = ["SURROGATE", "FE", "evaluate", "metrics_of", "constraint_names"]

SURROGATE, FE = Models.SURROGATE.value, Models.FE.value  # the model chains (TARGETS' study.models)


def constraint_names(targets: Targets) -> list[str]:
    """The constraints a result carries (each feasible when <= 0): the requirements given, then error findings."""
    r = targets.require
    names = [n for n in ("normal_resolution_mN", "shear_resolution_mN", "normal_range_N", "shear_range_N",
                         "max_diameter_mm", "max_height_mm") if getattr(r, n) is not None]
    return [*names, "error_findings"]


def metrics_of(pred, design) -> dict[str, float]:
    """The figures objectives and requirements are stated in (predictions.json's), plus a few a table shows."""
    n, s = pred.normal, pred.shear
    return {
        Objective.NORMAL_RESOLUTION.value: float(n.resolution_mN),
        Objective.SHEAR_RESOLUTION.value: float(s.resolution_mN),
        Objective.NORMAL_RANGE.value: float(n.range_N),
        Objective.SHEAR_RANGE.value: float(s.range_N),
        Objective.DIAMETER.value: float(2.0 * design.elastomer_radius_mm),
        Objective.HEIGHT.value: float(design.elastomer_height_mm),
        "normal_sensitivity_at_rest_G_per_N": float(n.sensitivity_at_rest_G_per_N["nominal"]),
        "Bz_rest_G": float(pred.field.Bz_rest_G),
        "range_limit": n.range_limit,
    }


def _constraints(targets: Targets, m: dict[str, float], errors: list[str]) -> list[float]:
    """Relative violations (<= 0 feasible), in :func:`constraint_names`' order."""
    r = targets.require
    out = []
    for name in constraint_names(targets)[:-1]:
        need = getattr(r, name)
        if name.startswith("max_"):
            value = m[name.removeprefix("max_")]
            out.append((value - need) / need)
        elif "resolution" in name:
            out.append((m[name] - need) / need)
        else:
            out.append((need - m[name]) / need)
    return [*out, float(len(errors))]


def _elastomer_model(design) -> tuple[Any, str]:
    """The surrogate's elastomer model for ``design``, or (None, why not) outside its validated region."""
    body = mech.Body.from_design(design)
    if not fe_surrogate.in_region(body):
        return None, "fe (outside surrogate region)"
    return surrogate_curve, SURROGATE


@lru_cache(maxsize=4)
def _inputs(base_json: str, targets_json: str) -> tuple[Spec, Targets]:
    """The base spec and targets, parsed once per worker (every design of a study sends the same two strings)."""
    return Spec.model_validate_json(base_json), Targets.model_validate_json(targets_json)


def evaluate(point: dict[str, Any], base_json: str, targets_json: str, fidelity: str = SURROGATE,
             name: str = "candidate") -> dict[str, Any]:
    """Evaluate one point (module doc). Returns ``{"state": "ok" | "infeasible" | "failed", "reason", "model",
    "metrics", "constraints", "errors", "seconds"}``; never raises (a bug is a failed design whose reason says so)."""
    os.environ["MAGFAB_JOBS"] = "1"  # the study runs designs side by side: no forked side branch inside one
    t0 = time.perf_counter()
    out: dict[str, Any] = {"state": "failed", "reason": "", "model": fidelity, "metrics": {}, "constraints": [],
                           "errors": []}
    try:
        base, targets = _inputs(base_json, targets_json)
        _run(point, base, targets, fidelity, name, out)
    except (InputError, ModelLimitError) as exc:
        out["reason"] = str(exc)
    except Exception as exc:  # one design's bug never stops a study; it is recorded and counted
        where = traceback.extract_tb(exc.__traceback__)[-1]
        out["reason"] = f"bug: {type(exc).__name__}: {exc} (at {where.name}, line {where.lineno})"
    out["seconds"] = time.perf_counter() - t0
    return out


def _run(point: dict[str, Any], base: Spec, targets: Targets, fidelity: str, name: str, out: dict[str, Any]) -> None:
    spec = candidate_spec(point, base, targets, name)
    if fidelity == SURROGATE:  # the exact field: no per-aspect surrogate table to build for each new magnet (0.3 s)
        spec = spec.model_copy(update={"predict": spec.predict.model_copy(update={"field_model": FieldModel.EXACT})})
    design = preflight(derive(spec))  # a candidate the build would refuse (its cost past a limit) fails as it would
    model, label = (None, FE)
    if fidelity == SURROGATE:
        model, label = _elastomer_model(design)
    out["model"] = label
    pred, findings = predict_with_findings(design, model)
    findings = design_findings(design) + findings
    if pred is None:
        out["reason"] = next(f.message for f in findings if f.severity is Severity.ERROR)
        return
    errors = [f"{f.code}: {f.message}" for f in errors_in(findings)]
    metrics = metrics_of(pred, design)
    constraints = _constraints(targets, metrics, errors)
    out.update(metrics=metrics, constraints=constraints, errors=errors,
               state="ok" if all(c <= 0.0 for c in constraints) else "infeasible")
    if out["state"] == "infeasible":
        names = constraint_names(targets)
        out["reason"] = "; ".join([f"{n} {100 * c:+.0f} %" for n, c in zip(names[:-1], constraints) if c > 0] + errors)

