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

import math
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
from ..models.predict import normal_curve, surrogate_curve, yeoh_ratios
from ..recipes.resolve import printer as printer_recipe
from ..spec import FieldModel, Spec, Tip
from .space import candidate_spec, saturation_floor
from .targets import Models, Objective, Targets

__all__ = ["SURROGATE", "FE", "REQUIREMENTS", "evaluate", "warm_up", "metrics_of", "constraint_names",
           "requirement_names", "margin_of", "slack_of", "shortfall", "bench_point", "bench_step_mm"]

SURROGATE, FE = Models.SURROGATE.value, Models.FE.value  # the model chains (TARGETS' study.models)


#: Each requirement and the figure it bounds: (figure, "at_most" | "at_least", depends on the models).
REQUIREMENTS: dict[str, tuple[str, str, bool]] = {
    "normal_resolution_mN": ("normal_resolution_mN", "at_most", True),
    "shear_resolution_mN": ("shear_resolution_mN", "at_most", True),
    "normal_range_N": ("normal_range_N", "at_least", True),
    "shear_range_N": ("shear_range_N", "at_least", True),
    "max_diameter_mm": ("diameter_mm", "at_most", False),
    "max_height_mm": ("height_mm", "at_most", False),
    "max_drift_mN_per_C": ("drift_mN_per_C", "at_most", True),
    "max_earth_field_mN": ("earth_field_mN", "at_most", True),
}


def requirement_names(targets: Targets) -> list[str]:
    """The requirements the targets give, in :data:`REQUIREMENTS`' order."""
    return [n for n in REQUIREMENTS if getattr(targets.require, n) is not None]


def constraint_names(targets: Targets) -> list[str]:
    """The constraints a result carries (each feasible when <= 0): the requirements given, then error findings."""
    return [*requirement_names(targets), "error_findings"]


def _drift_figures(pred, design) -> tuple[float, float]:
    """(temperature drift at rest, mN/C; turning over in the strongest Earth field, mN): the drift budget's figures
    (:mod:`magfab.models.drift`), NaN where the prediction has none. Drift: the normal force error at rest for +1 C
    from the calibration temperature, with the chip-temperature compensation when the firmware applies it
    (``firmware.temperature``), without otherwise. Earth field: the sensor turned over (180 deg) in the strongest
    field of the recipe's band (0.65 G, 65 uT), the larger normal error of at rest and at the end of the range."""
    d = pred.drift
    if d is None:
        return math.nan, math.nan
    case = "with" if design.spec.firmware.temperature else "without"
    turned = d.rotation_band[1]
    return (abs(float(d.temperature.per_C["normal_rest"][case])),
            max(abs(float(turned.normal_rest_mN)), abs(float(turned.normal_end_mN))))


def _model_error(pred, family: str, design) -> float:
    """A model's relative error estimate (predictions.json's ``models``); where it was not measured (NaN), the
    tolerance the spec holds the models to (``predict.tolerance_pct``)."""
    try:
        err = float(pred.model(family).error)
    except StopIteration:
        err = math.nan
    return err if math.isfinite(err) else design.spec.predict.tolerance_pct / 100.0


def _mechanics_errors(pred, design) -> dict[str, float]:
    """The mechanics model's relative errors a margin is made of: ``mechanics_error`` on a force (the FE's Richardson
    estimate; for the surrogate its held-out force error's 90th percentile, not the RMS its ModelUse reports, so
    nine designs in ten are inside it) and ``range_error`` on a range, which also moves with where the travel ends
    (the surrogate's held-out travel error's 90th percentile added; the FE's estimate covers its own travel)."""
    use = pred.model("mechanics")
    if use.name == SURROGATE:
        held = fe_surrogate.held_out_error(design.tip)  # each tip's table has its own held-out errors
        force = float(held["force_p90"])
        return {"mechanics_error": force, "range_error": force + float(held["travel_p90"])}
    err = max(_model_error(pred, "mechanics", design), 0.0)
    return {"mechanics_error": err, "range_error": err}


def metrics_of(pred, design) -> dict[str, float]:
    """The figures objectives and requirements are stated in (predictions.json's), the model errors the margins are
    made of, plus a few a table shows."""
    n, s = pred.normal, pred.shear
    drift_per_C, earth = _drift_figures(pred, design)
    return {
        Objective.NORMAL_RESOLUTION.value: float(n.resolution_mN),
        Objective.SHEAR_RESOLUTION.value: float(s.resolution_mN),
        Objective.NORMAL_RANGE.value: float(n.range_N),
        Objective.SHEAR_RANGE.value: float(s.range_N),
        Objective.DIAMETER.value: float(2.0 * design.elastomer_radius_mm),
        Objective.HEIGHT.value: float(design.elastomer_height_mm),
        Objective.DRIFT.value: drift_per_C,
        Objective.EARTH_FIELD.value: earth,
        "field_error": _model_error(pred, "field", design),
        **_mechanics_errors(pred, design),
        "normal_sensitivity_at_rest_G_per_N": float(n.sensitivity_at_rest_G_per_N["nominal"]),
        "Bz_rest_G": float(pred.field.Bz_rest_G),
        "saturation": float(pred.field.Bz_d_min_strongest_G / pred.chip.full_scale_z_G),
        "range_limit": n.range_limit,
    }


def margin_of(targets: Targets, name: str, m: dict[str, float]) -> float:
    """The relative margin requirement ``name`` must be met by, for a design with figures ``m``.

    ``margin = "model"`` (the default): the model chain's own error estimate for the figure, the field model's plus
    the mechanics model's (the FE's Richardson estimate, or the surrogate's held-out errors: force, and for a range
    travel too, :func:`_mechanics_errors`); every figure a requirement bounds is made of both (a resolution is noise
    over dB/dF; a range the force where the travel or the field ends; drift and the Earth field's error a field
    change through the calibration's inverse). The material's
    band needs no further term: every such figure is already its band's worst case (resolution over the material
    and grade bands, range the softest material's, drift the stiff material's with the weakest magnet). A number:
    that percentage for every figure the models predict. Sizes are geometry, exact: no margin (the written specs are
    rounded to the printer first, :func:`bench_point`)."""
    if not REQUIREMENTS[name][2]:
        return 0.0
    margin = targets.require.margin
    if margin != "model":
        return float(margin) / 100.0
    which = "range_error" if name.endswith("_range_N") and "range_error" in m else "mechanics_error"
    field, mech_ = m.get("field_error", math.nan), m.get(which, math.nan)
    total = (field if math.isfinite(field) else 0.0) + (mech_ if math.isfinite(mech_) else 0.0)
    return float(total)


def slack_of(targets: Targets, name: str, m: dict[str, float]) -> float:
    """How far a design meets requirement ``name``, relative to the requirement (> 0: met by that much, < 0: short;
    -inf for a figure the prediction lacks)."""
    figure, sense, _ = REQUIREMENTS[name]
    need = float(getattr(targets.require, name))
    value = float(m.get(figure, math.nan))
    if not math.isfinite(value):
        return -math.inf
    return (need - value) / need if sense == "at_most" else (value - need) / need


def findings_violation(targets: Targets, m: dict[str, float], errors: list[str]) -> float:
    """The error findings as one violation (0: none), graded where the finding has a measure, so that the sampler
    learns which way is closer: the chip's saturation by how far the strongest magnet's field at d_min exceeds full
    scale (its ratio less one), the resolution the targets ask for not at all (its requirement is a constraint of
    its own, graded), and one for each other error."""
    total = 0.0
    for code in (e.split(":")[0] for e in errors):
        if code == "chip-saturates" and math.isfinite(m.get("saturation", math.nan)):
            total += max(m["saturation"] - 1.0, 1e-6)
        elif code == "resolution-short" and targets.require.normal_resolution_mN is not None:
            continue
        else:
            total += 1.0
    return total


def _constraints(targets: Targets, m: dict[str, float], errors: list[str]) -> list[float]:
    """Violations (<= 0 feasible), in :func:`constraint_names`' order: for each requirement its margin less how far
    the design meets it (so a design must meet each by its margin: :func:`margin_of`), then the error findings
    (:func:`findings_violation`)."""
    out = []
    for name in requirement_names(targets):
        c = margin_of(targets, name, m) - slack_of(targets, name, m)
        out.append(c if math.isfinite(c) else 1e9)  # Optuna takes finite constraints only
    return [*out, findings_violation(targets, m, errors)]


def bench_step_mm(base: Spec) -> float:
    """The step the written dimensions are rounded to: the printer's layer height (recipes/printers.toml, the base
    spec's ``mould.printer``: 0.05 mm for resin, Formlabs' default layer height)."""
    return float(printer_recipe(base.mould.printer.value)["layer_height_mm"].nominal)


def _on_step(x: float, step: float, bounds: tuple[float, float] | None) -> float:
    """``x`` on the nearest multiple of ``step``, kept within ``bounds`` (a [low, high] range) when one fits."""
    v = round(round(x / step) * step, 6)
    if bounds is not None:
        lo, hi = bounds
        if v < lo:
            v = round(math.ceil(lo / step - 1e-9) * step, 6)
        elif v > hi:
            v = round(math.floor(hi / step + 1e-9) * step, 6)
        if not lo <= v <= hi:  # no multiple of the step in the range: the variable's own value
            v = x
    return v


def bench_point(point: dict[str, Any], base: Spec, targets: Targets) -> dict[str, Any]:
    """``point`` with its dimensions on what the printer makes (:func:`bench_step_mm`): d_max, d_min and the elastomer
    diameter on the step, and the cover adjusted so the elastomer's height is on it too. What the full chain verifies
    and the specs are written from, so the figures reported are the design's as built. Listed values stay as
    listed. d_min stays at or past the chip's saturation (the search's floor, :func:`saturation_floor`); a rounding
    the geometry refuses (a d_max past its stack's bound by less than a step) leaves the point as searched."""
    step = bench_step_mm(base)
    out = dict(point)
    v = targets.variables
    for key in ("d_max_mm", "d_min_mm", "elastomer_diameter_mm"):
        c = getattr(v, key)
        if not isinstance(c, list):
            lo, hi = c
            if key == "d_min_mm":
                lo = max(lo, saturation_floor(point, base, targets))
            out[key] = _on_step(float(point[key]), step, (lo, hi))
    if out["d_min_mm"] >= out["d_max_mm"]:  # rounding must not turn a design into one the spec refuses
        out["d_min_mm"], out["d_max_mm"] = point["d_min_mm"], point["d_max_mm"]
    if not isinstance(v.cover_mm, list):
        height = candidate_spec(out, base, targets, "bench").elastomer.height_mm
        cover = float(out["cover_mm"]) + _on_step(height, step, None) - height
        lo, hi = v.cover_mm
        if lo - 1e-9 <= cover <= hi + 1e-9:
            out["cover_mm"] = round(cover, 9)
    return out if _derives(out, base, targets) or not _derives(point, base, targets) else dict(point)


def _derives(point: dict[str, Any], base: Spec, targets: Targets) -> bool:
    try:
        derive(candidate_spec(point, base, targets, "bench"))
    except InputError:
        return False
    return True


#: The model label of a cheap design the FE evaluated: its body outside the surrogate's validated region.
OUTSIDE = "fe (outside surrogate region)"


def _elastomer_model(design) -> tuple[Any, str]:
    """The surrogate's elastomer model for ``design``, or (None, why not) outside its validated region or laws."""
    if not fe_surrogate.in_region(mech.Body.from_design(design), *yeoh_ratios(design)):
        return None, OUTSIDE
    return _surrogate_or_fe, SURROGATE


def _surrogate_or_fe(design, body, mu, indentation):
    """The surrogate's curve and shear response, or the FE's where the surrogate refuses the body once it has seen
    its table (:func:`~magfab.models.mechanics.fe_surrogate.normal_and_shear`: a curve that ends before two shear
    probes, or a force, travel or probe not positive at a small indentation, which log-log cannot extrapolate)."""
    try:
        return surrogate_curve(design, body, mu, indentation)
    except fe_surrogate.OutsideRegion:
        return normal_curve(design, body, mu, indentation)


@lru_cache(maxsize=4)
def _inputs(base_json: str, targets_json: str) -> tuple[Spec, Targets]:
    """The base spec and targets, parsed once per worker (every design of a study sends the same two strings)."""
    return Spec.model_validate_json(base_json), Targets.model_validate_json(targets_json)


def warm_up(tips: list[str]) -> None:
    """A worker's once-a-process work before its first design, done while the study plans its first phase
    (:func:`magfab.inverse.study.run_study` sends it to each worker first): this module's imports (its unpickling
    imports them) and the surrogate's tables of ``tips``. Each worker's first design had waited for them: about 0.8 s
    (0.4 s of imports, 0.4 s of tables) at the start of the example targets' 8 s search on two workers."""
    for tip in tips:
        fe_surrogate.load(Tip(tip))


def evaluate(point: dict[str, Any], base_json: str, targets_json: str, fidelity: str = SURROGATE,
             name: str = "candidate") -> dict[str, Any]:
    """Evaluate one point (module doc). Returns ``{"state": "ok" | "infeasible" | "failed", "reason", "model",
    "metrics", "constraints", "errors", "seconds"}``; never raises (a bug is a failed design whose reason says so)."""
    jobs = os.environ.get("MAGFAB_JOBS")
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
    finally:  # as it was: a design evaluated in the caller's own process leaves its later builds as they were
        if jobs is None:
            del os.environ["MAGFAB_JOBS"]
        else:
            os.environ["MAGFAB_JOBS"] = jobs
    out["seconds"] = time.perf_counter() - t0
    return out


def _run(point: dict[str, Any], base: Spec, targets: Targets, fidelity: str, name: str, out: dict[str, Any]) -> None:
    if fidelity == FE:  # the full chain judges the design as it will be printed: its dimensions on the printer's step
        point = bench_point(point, base, targets)
    spec = candidate_spec(point, base, targets, name)
    if fidelity == SURROGATE:  # the exact field: no per-aspect surrogate table to build for each new magnet (0.3 s)
        spec = spec.model_copy(update={"predict": spec.predict.model_copy(update={"field_model": FieldModel.EXACT})})
    design = preflight(derive(spec))  # a candidate the build would refuse (its cost past a limit) fails as it would
    model, label = (None, FE)
    if fidelity == SURROGATE:
        model, label = _elastomer_model(design)
    out["model"] = label
    pred, findings = predict_with_findings(design, model)
    if pred is not None and label == SURROGATE and pred.model("mechanics").name != SURROGATE:
        out["model"] = OUTSIDE  # the surrogate refused the body inside predict (_surrogate_or_fe)
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
        out["reason"] = "; ".join([shortfall(targets, n, metrics) for n, c in zip(requirement_names(targets),
                                                                                   constraints) if c > 0] + errors)


def shortfall(targets: Targets, name: str, m: dict[str, float]) -> str:
    """One requirement as met or not with its margin, e.g. "normal_range_N 0.98 against >= 1 (margin 2.5 %): short
    by 4.5 %"."""
    figure, sense, _ = REQUIREMENTS[name]
    need, value = getattr(targets.require, name), m.get(figure, math.nan)
    slack, margin = slack_of(targets, name, m), margin_of(targets, name, m)
    head = f"{name} {value:.4g} against {'<=' if sense == 'at_most' else '>='} {need:g} (margin {100 * margin:.1f} %)"
    if not math.isfinite(slack):
        return f"{name}: no figure (the prediction has none)"
    if slack >= margin:
        return f"{head}: met with margin, by {100 * slack:+.1f} %"
    return f"{head}: short by {100 * (margin - slack):.1f} %"

