"""What the sensor will do: sensitivity, resolution and range, normal and shear (docs/models.md, M5 to M11).

The chain, for a force on the tip:

    indentation --(elastomer model)--> force F and magnet displacement u
    u --------------------------------> gap d = d_rest - u (normal) or lateral offset r (shear)
    (d, r) ----(field model)----------> (Bz, Br) at the Hall point

    S_B = dB/du          field change per mm of magnet travel             (M5)
    K_e = dF/du          elastomer stiffness at the magnet                 (M7)
    S_F = S_B / K_e      field change per newton                           (M10)
    R   = N_B / S_F      force resolution: field noise over sensitivity    (M11)

The material is a band (soft / nominal / stiff shear modulus from the recipe) and the magnet's remanence a
band (the grade's min / nominal / max); every figure is given over the band, and the worst case is the
combination that makes it worst (resolution: stiff material, weakest magnet, at rest). Noise N_B is the
environment's (``predict.noise_G``) and the chip's own (at its OSR/DIG_FILT) and quantisation, in quadrature.

The force range ends at the first of the sensor's limits: the magnet reaching d_min, the chip's output reaching full
scale at its configured gain and resolution, the field-to-force map ceasing to be one-to-one (``invertibility``: the
force or the field stops rising with the magnet's travel), the depth the spec calibrates over (the scan depth, where
the FE is solved to), and the user's own ``predict.max_stretch`` if given (``stretch``). Or it ends at a model's
reach, and is then "at least" its figure (:data:`MODEL_REACH`): the silicone reaching the stretch where the material
law's data end (``material data``: 2 for the neo-Hookean bands, the Yeoh fit's for ``predict.material_law =
"yeoh"``), or the FE stopping (``model``). Stretches are the FE's principal stretch averaged with a smooth kernel of
radius R/30 about each point (:mod:`.mechanics.energy`: it converges under refinement where a pointwise stretch at a
corner does not).

Models: ``predict.field_model`` and ``predict.mechanics_model``; ``auto`` takes the cheapest field model whose
error over the working volume fits ``predict.tolerance_pct`` (measured against the exact field, per build), and
the finite-element model on the coarsest mesh whose estimated discretisation error fits it (two meshes,
Richardson). :class:`Prediction` records which models were used and their errors.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from ..fork import side_branch
from ..reference_chip import reference_chip
from ..spec import FieldModel, MaterialLaw, MaterialLawChoice, MechanicsModel
from ..spec_options import CLOSED_FORMS
from ..units import MN_PER_N
from . import drift
from . import field as fieldmod
from . import mechanics as mech
from .chip import ChipSetting, chip_setting, noise
from .mechanics import fe_surrogate
from .mechanics.schedule import FE_ORDER, fe_meshes  # the meshes the spec's cost limits were checked against
from .reference import budget
from .shear_figures import SHEAR_DESCRIPTION, ShearFigures, _crossing, rest_response, shear_figures, shear_probe_depths

if TYPE_CHECKING:
    from ..design import Design
    from .drift import Drift

N_INDENT = 21  # indentation steps along the normal curve
SHEAR_STEP_MM = 0.01  # finite-difference step for dBr/dr at the axis


# ---------------------------------------------------------------------------------------------------
# Model choice


@dataclass(frozen=True)
class ModelUse:
    """Which model a prediction used, and what it is known to cost in error."""

    family: str  # "field", "mechanics", "shear"
    name: str
    error: float  # relative, against the family's reference (nan: not measured)
    detail: str
    chosen_by: str  # "auto" or "spec"

    def as_dict(self) -> dict[str, object]:
        return {"model": self.name, "relative_error": _finite(self.error), "detail": self.detail,
                "chosen_by": self.chosen_by}


def _finite(x: float) -> float | None:
    return None if not math.isfinite(x) else float(x)


def choose_field(design: Design, magnet: fieldmod.Magnet) -> ModelUse:
    """The field model: measured against the exact field over this design's working volume (d_min..d_max,
    r 0..R_m) -- cheapest within tolerance for ``auto``, or the spec's choice with its error."""
    p = design.spec.predict
    sen = design.spec.sensor
    points = fieldmod.working_volume(magnet, sen.d_min_mm, design.d_rest_mm, n=16)
    tol = p.tolerance_pct / 100.0
    if p.field_model.value == "auto":
        c = fieldmod.choose(magnet, points, tol)
        tried = ", ".join(f"{n} {e:.2g}" if math.isfinite(e) else f"{n} refused" for n, e in c.tried)
        return ModelUse("field", c.model, c.error, f"errors over the working volume: {tried}", "auto")
    name = p.field_model.value
    if name == FieldModel.EXACT.value:  # the reference: nil against itself, not measured (5 % of a search's design)
        err = 0.0
    else:
        try:
            err = fieldmod.model_error(name, magnet, points).relative
        except fieldmod.FieldModelError:
            err = math.inf
    return ModelUse("field", name, err, "error over the working volume, measured against the exact field", "spec")


#: What ends a normal curve solved to the scan depth, and one the FE could not take further (range limit labels).
SCAN_DEPTH, MODEL = "scan depth", "model"
#: The range limit where the material law's data end, and the user's own stretch limit (predict.max_stretch).
MATERIAL_DATA, STRETCH = "material data", "stretch"
#: The range limit where the field-to-force map stops being one-to-one, and the slope (of its largest) below which the
#: force or the field has stopped rising.
INVERTIBILITY, FLAT = "invertibility", 1e-6
#: Limits of the models, not of the sensor: a range they end is "at least" its figure (NormalFigures.range_text).
MODEL_REACH = frozenset({MODEL, MATERIAL_DATA})
#: The stretch where the neo-Hookean bands' data end: they are fitted to engineering strains up to 100 %
#: (recipes/materials.toml).
NEO_HOOKEAN_DATA_END = 2.0


def _fe_curve(body: mech.Body, mu: float, indentation: np.ndarray, mesh: float, depth_mm: float,
              probe: mech.ShearProbe | None = None, law: Mapping[str, Any] | None = None) -> mech.Curve:
    """The FE curve up to ``depth_mm``, the deepest indentation the design is used over (see :func:`normal_curve`):
    the FE is solved there and no deeper, and the curve says so in ``info["failure"]``, so the range ends there if
    nothing ends it earlier. A failure before that depth (element inversion, non-convergence) truncates the curve
    where the model stopped. ``probe``: solved at each converged indentation (the shear response along the scan).
    ``law``: :func:`material_law`'s arguments."""
    d = np.asarray(indentation, dtype=float)
    law = dict(law or {})
    if d[-1] <= depth_mm:
        return mech.fe(body, mu, d, mesh_mm=mesh, on_failure=mech.OnFailure.TRUNCATE, probe=probe, **law)
    kept = np.append(d[d < depth_mm - 1e-9], depth_mm)
    curve = mech.fe(body, mu, kept, mesh_mm=mesh, on_failure=mech.OnFailure.TRUNCATE, probe=probe, **law)
    if "failure" not in curve.info:
        curve.info["failure"] = (f"the FE is solved to {depth_mm:g} mm of indentation, the depth the design is used "
                                 "over (calibration.scan_z_mm)")
        curve.info["failed_at_mm"] = float(d[kept.size - 1]) if kept.size - 1 < d.size else math.nan
        curve.info["ends_at"] = SCAN_DEPTH
    return curve


def _curve_end(curve: mech.Curve, indentation: np.ndarray, travel_mm: float = 0.0) -> tuple[str, str]:
    """(label, note) for a curve shorter than ``indentation``: :data:`SCAN_DEPTH` or :data:`MODEL`, and why it ends;
    :data:`MODEL` too for one that runs the whole grid with the magnet short of ``travel_mm`` (d_min's: it lags the
    surface more than :data:`GRID_REACH` allows); ("", "") for a curve that reaches it."""
    if len(curve.force_N) < len(indentation):
        return str(curve.info.get("ends_at", MODEL)), str(curve.info.get("failure", ""))
    moved = float(curve.magnet_displacement_mm[-1])
    if moved < travel_mm - 1e-9:
        return MODEL, (f"the curve was asked to {indentation[-1]:.3g} mm of indentation ({GRID_REACH:g} x the travel "
                       f"to d_min), where the magnet had moved {moved:.3g} mm of its {travel_mm:.3g} mm")
    return "", ""


def normal_curve(design: Design, body: mech.Body, mu: float,
                 indentation: np.ndarray) -> tuple[mech.Curve, ModelUse, mech.ShearResponse | None]:
    """The normal curve at the nominal modulus with the model the spec asks for (see module doc), and for the FE the
    shear response along it (:func:`~.shear_figures.shear_probe_depths`, on the chosen mesh; None for a closed
    form)."""
    p = design.spec.predict
    tol = p.tolerance_pct / 100.0
    name = p.mechanics_model.value
    if name in ("column", "hertz_column"):
        curve = mech.MODELS[mech.MechanicsModel(name)](body, mu, indentation)
        return curve, ModelUse("mechanics", name, math.nan,
                               "closed form; its error against the FE model is charted by bench/mechanics.py",
                               "spec"), None
    chosen = None
    depth = float(design.spec.calibration.scan_z_mm)  # the deepest indentation the design is used over
    depths, rest = shear_probe_depths(design, indentation), design.spec.calibration.scan_step_mm
    meshes = fe_meshes(design)  # coarse to fine; past the last, the model-error warning says so
    # The first mesh is only the reference of the second's error estimate (never chosen, so not probed): it is solved
    # in a forked worker beside the second where two cores allow (magfab.fork; the same numbers either way).
    law = material_law(design)
    with side_branch(_fe_curve, body, mu, indentation, meshes[0], depth, None, law) as first:
        previous = None
        for mesh in meshes[1:]:
            probe = mech.ShearProbe(depths_mm=depths, rest_indentation_mm=rest)
            curve = _fe_curve(body, mu, indentation, mesh, depth, probe, law)
            previous = first.result() if previous is None else previous
            n = min(len(curve.force_N), len(previous.force_N))
            if n < 2:
                raise mech.MechanicsError(f"fe (mesh {mesh:g} mm): {curve.info.get('failure', 'no steps')}")
            ratio = previous.mesh_mm / curve.mesh_mm
            fine, coarse = curve.force_N[:n], previous.force_N[:n]
            diff = float(np.max(np.abs(fine - coarse)) / np.max(np.abs(fine)))
            err = diff / (ratio**FE_ORDER - 1.0)  # Richardson estimate of the finer mesh's error
            chosen = (curve, err, previous.mesh_mm, probe)
            if err <= tol:
                break
            previous = curve
    assert chosen is not None
    curve, err, coarse, probe = chosen
    how = "auto" if name == "auto" else "spec"
    described = mech.MODEL_DESCRIPTION
    if law:
        k2, k3 = law["yeoh_ratios"]
        described = described.replace("neo-Hookean", f"Yeoh (k2 = {k2:.3g}, k3 = {k3:.3g}, recipes/materials.toml)")
    return curve, ModelUse("mechanics", "fe", err,
                           f"{described} Mesh {curve.mesh_mm:g} mm; error estimated against mesh "
                           f"{coarse:g} mm (Richardson, order {FE_ORDER:g})", how), probe.response(mu)


def surrogate_curve(design: Design, body: mech.Body, mu: float,
                    indentation: np.ndarray) -> tuple[mech.Curve, ModelUse, mech.ShearResponse]:
    """:func:`normal_curve`'s result from the elastomer FE's surrogate (:mod:`.mechanics.fe_surrogate`), for the design
    search: the curve to the scan depth and the shear response at the preloads the FE probe would solve. Raises
    :class:`~.mechanics.fe_surrogate.OutsideRegion` for a body outside its validated region."""
    depth = float(design.spec.calibration.scan_z_mm)
    ratios = yeoh_ratios(design)
    yeoh = law_in_force(design) is MaterialLaw.YEOH
    curve, response = fe_surrogate.normal_and_shear(body, mu, indentation, depth,
                                                    shear_probe_depths(design, indentation),
                                                    design.spec.calibration.scan_step_mm, *ratios)
    return curve, ModelUse("mechanics", "surrogate", fe_surrogate.held_out_error(body.tip, yeoh)["force_rms"],
                           fe_surrogate.description(body.tip, yeoh), "search"), response


# ---------------------------------------------------------------------------------------------------
# The prediction: typed values, turned into predictions.json's dict only by :meth:`Prediction.as_json`

MATERIALS = ("soft", "nominal", "stiff")  # the material band, softest first
GRADE_BAND = ("low", "nominal", "high")  # the magnet grade's remanence band, weakest first


@dataclass(frozen=True)
class FieldFigures:
    """The field at the Hall point, G (nominal magnet unless named), and the grade's remanence band, T."""

    Bz_rest_G: float
    dBz_dz_rest_G_per_mm: float
    Bz_d_min_G: float
    Bz_d_min_strongest_G: float
    dBr_dr_rest_G_per_mm: float
    Bz_range_end_strongest_G: float
    remanence_T: Mapping[str, float]  # GRADE_BAND -> T


@dataclass(frozen=True)
class Noise:
    """RMS field noise at the sensor, G: environment, chip, quantisation (LSB / sqrt 12), totals per axis."""

    environment_G: float
    chip_xy_G: float
    chip_z_G: float
    quantisation_xy_G: float
    quantisation_z_G: float
    total_xy_G: float
    total_z_G: float


@dataclass(frozen=True)
class NormalFigures:
    """Normal load over the material band (MATERIALS) and the grade's band; forces N, lengths mm."""

    curves: Mapping[str, mech.Curve]  # force against indentation per material
    magnet_displacement_mm: tuple[float, ...]  # axial magnet travel at each indentation step
    sensitivity_G_per_N: tuple[float, float]  # over the range, every material and grade
    resolution_mN: float  # worst case over the range
    resolution_at_rest_mN: Mapping[str, float]  # per material, weakest magnet
    range_N: float  # the softest material's
    range_by_material_N: Mapping[str, float]
    range_limit: str  # what ends it: d_min, chip full scale, invertibility, stretch, scan depth, material data, model
    range_limits_travel_mm: Mapping[str, float]  # magnet travel at which each limit would bind
    travel_mm: float
    stiffness_at_rest_N_per_mm: Mapping[str, float]
    sensitivity_at_rest_G_per_N: Mapping[str, float]  # per material, nominal magnet grade
    model_limit: str = ""  # why the mechanics model's curve ends before the indentation grid does, if it does

    @property
    def range_is_model_reach(self) -> bool:
        """Whether a model's reach, not the sensor, ends the range (:data:`MODEL_REACH`): the sensor reaches at
        least this far."""
        return self.range_limit in MODEL_REACH

    def range_parts(self, digits: int = 3) -> tuple[str, str]:
        """The range and what ends it, as a person reads them: ("1.573 N", "ends at: d_min"), or for a model's reach
        ("at least 1.573 N", "the model's reach: material data")."""
        value = f"{self.range_N:.{digits}f} N"
        if self.range_is_model_reach:
            return f"at least {value}", f"the model's reach: {self.range_limit}"
        return value, f"ends at: {self.range_limit}"

    def range_text(self, digits: int = 3) -> str:
        """:meth:`range_parts` as one phrase: "at least 1.573 N (the model's reach: material data)"."""
        value, why = self.range_parts(digits)
        return f"{value} ({why})"


@dataclass(frozen=True)
class Prediction:
    """What the sensor will do (module doc), plus the arrays the plots need. Frozen values throughout;
    :meth:`as_json` is the one place they become predictions.json's nested dict."""

    field: FieldFigures
    chip: ChipSetting
    material_mu_kPa: Mapping[str, float]
    normal: NormalFigures
    shear: ShearFigures
    noise: Noise
    models: tuple[ModelUse, ...]  # field, mechanics, shear
    # dataclasses.field by its full name: in this class, `field` is the attribute above
    arrays: Mapping[str, np.ndarray] = dataclasses.field(default_factory=dict)
    timings_s: Mapping[str, float] = dataclasses.field(default_factory=dict)
    drift: Drift | None = None  # the drift budget (magfab.models.drift); None where the curve has no inverse
    reference: Mapping[str, object] | None = None  # the reference chip's site and rejection (magfab.models.reference)

    @property
    def curves(self) -> Mapping[str, mech.Curve]:
        return self.normal.curves

    def model(self, family: str) -> ModelUse:
        return next(m for m in self.models if m.family == family)

    def as_json(self) -> dict[str, object]:
        """predictions.json: plain numbers, lists and dicts."""
        n, s, c = self.normal, self.shear, self.chip
        normal: dict[str, object] = {
            "curve": {k: [[float(d), float(f)] for d, f in zip(cv.indentation_mm, cv.force_N)]
                      for k, cv in n.curves.items()},
            "curve_columns": ["indentation_mm", "force_N"],
            "magnet_displacement_mm": list(n.magnet_displacement_mm),
            "sensitivity_G_per_N": list(n.sensitivity_G_per_N),
            "resolution_mN": n.resolution_mN,
            "resolution_at_rest_mN": dict(n.resolution_at_rest_mN),
            "range_N": n.range_N,
            "range_by_material_N": dict(n.range_by_material_N),
            "range_limit": n.range_limit,
            "range_is_model_reach": n.range_is_model_reach,
            "range_limits_travel_mm": dict(n.range_limits_travel_mm),
            "travel_mm": n.travel_mm,
            "stiffness_at_rest_N_per_mm": dict(n.stiffness_at_rest_N_per_mm),
            "sensitivity_at_rest_G_per_N": dict(n.sensitivity_at_rest_G_per_N),
        }
        if n.model_limit:
            normal["model_limit"] = n.model_limit
        return {
            "field": {**asdict(self.field), "remanence_T": dict(self.field.remanence_T)},
            "chip": {"gain_sel": c.gain_sel, "resolution": c.resolution, "osr": c.osr, "dig_filt": c.dig_filt,
                     "lsb_xy_uT": c.lsb_xy_uT, "lsb_z_uT": c.lsb_z_uT, "full_scale_xy_G": c.full_scale_xy_G,
                     "full_scale_z_G": c.full_scale_z_G, "saturation_onset_G": c.saturation_onset_G,
                     "conversion_ms": c.conversion_ms, "rate_Hz": c.rate_Hz},
            "material_mu_kPa": dict(self.material_mu_kPa),
            "normal": normal,
            "shear": s.as_json(),
            "noise_G": asdict(self.noise),
            "models": {m.family: m.as_dict() for m in self.models},
            **({} if self.drift is None else {"drift": self.drift.as_json()}),
            **({} if self.reference is None else {"reference": self.reference}),
        }


def _derivative(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.gradient(y, x, edge_order=2)


def _band(design: Design) -> dict[str, float]:
    given = design.spec.elastomer.shear_modulus_kPa
    return dict(zip(MATERIALS, given or mech.band(design.material, law_in_force(design).value)))


def yeoh_can_run(design: Design) -> bool:
    """Whether the Yeoh law can model this design: the silicone has a fit (recipes/materials.toml) and the mechanics
    model is the FE (or its surrogate), not a closed form."""
    return design.material.yeoh is not None and MechanicsModel(design.spec.predict.mechanics_model) not in CLOSED_FORMS


def law_in_force(design: Design) -> MaterialLaw:
    """The hyperelastic law the elastomer's models use for the spec's ``predict.material_law``: Yeoh when asked, or
    for "auto" where it can run (:func:`yeoh_can_run`); neo-Hookean otherwise. (An explicit "yeoh" that cannot run
    is refused in :mod:`magfab.plausible` before this runs.)"""
    choice = MaterialLawChoice(design.spec.predict.material_law)
    if design.material.yeoh is not None and (choice is MaterialLawChoice.YEOH
                                             or (choice is MaterialLawChoice.AUTO and yeoh_can_run(design))):
        return MaterialLaw.YEOH
    return MaterialLaw.NEO_HOOKEAN


def material_law(design: Design) -> dict[str, Any]:
    """The FE's material arguments for the law in force (:func:`law_in_force`): none for neo-Hookean (the FE's
    default), or the silicone's Yeoh ratios (recipes/materials.toml)."""
    y = design.material.yeoh
    if y is None or law_in_force(design) is not MaterialLaw.YEOH:
        return {}
    return {"material": "yeoh", "yeoh_ratios": (y.k2, y.k3)}


def yeoh_ratios(design: Design) -> tuple[float, float]:
    """(k2, k3) of the spec's law: the silicone's Yeoh ratios, or (0, 0) for neo-Hookean."""
    return material_law(design).get("yeoh_ratios", (0.0, 0.0))


def data_end_stretch(design: Design) -> float:
    """The stretch where the material law's data end (predict's "material data" limit): 2 for the neo-Hookean bands
    (fitted to 100 % strain), the Yeoh fit's stretch for "yeoh" (recipes/materials.toml)."""
    y = design.material.yeoh
    return y.stretch_max if y is not None and law_in_force(design) is MaterialLaw.YEOH else NEO_HOOKEAN_DATA_END


#: What replaces :func:`normal_curve` in :func:`predict`: (design, body, mu_kPa, indentation) -> (nominal curve, its
#: ModelUse, the shear response along it or None). The design search passes the elastomer surrogate's.
ElastomerModel = Callable[["Design", mech.Body, float, np.ndarray],
                          tuple[mech.Curve, ModelUse, "mech.ShearResponse | None"]]


def predict(design: Design, elastomer: ElastomerModel | None = None) -> Prediction:
    """Sensitivity, resolution and range for ``design`` (module doc). Deterministic. ``elastomer``: the normal curve
    and shear response from another model than the spec's (default :func:`normal_curve`)."""
    t0 = time.perf_counter()
    spec = design.spec
    sen = spec.sensor
    chip = chip_setting(design)
    nz = noise(design, chip)
    magnets = {band: fieldmod.Magnet.from_design(design, band) for band in GRADE_BAND}
    fuse = choose_field(design, magnets["nominal"])
    t_field = time.perf_counter()

    body = mech.Body.from_design(design)
    mus = _band(design)
    indentation = indentation_grid(design)
    nominal, muse, response = (elastomer or normal_curve)(design, body, mus["nominal"], indentation)
    curves = {k: nominal.scaled(mu) if k != "nominal" else nominal for k, mu in mus.items()}
    t_mech = time.perf_counter()

    end = _curve_end(nominal, indentation, travel_to_d_min(design))
    normal, normal_arrays = _normal(design, chip, nz, magnets, fuse.name, curves, end)
    if response is None:
        response = rest_response(design, body, mus["nominal"])
    depth_end = float(np.interp(normal.travel_mm, nominal.magnet_displacement_mm, nominal.indentation_mm))
    shear, shear_arrays = shear_figures(design, nz, magnets, chip.full_scale_xy_G, fuse.name, mus, response, depth_end)
    t_end = time.perf_counter()
    u = normal_arrays["u"]
    field_figures = FieldFigures(
        Bz_rest_G=float(normal_arrays["bz_nominal"][0]),
        dBz_dz_rest_G_per_mm=float(fieldmod.dbz_dz(magnets["nominal"], design.d_rest_mm, 0.0, model=FieldModel.EXACT)),
        Bz_d_min_G=float(fieldmod.bz_br(magnets["nominal"], sen.d_min_mm, 0.0, model=FieldModel.EXACT)[0]),
        Bz_d_min_strongest_G=float(fieldmod.bz_br(magnets["high"], sen.d_min_mm, 0.0, model=FieldModel.EXACT)[0]),
        dBr_dr_rest_G_per_mm=float(shear_arrays["dbr_nominal"][0]),
        Bz_range_end_strongest_G=float(np.interp(normal.travel_mm, u, normal_arrays["bz_high"])),
        remanence_T={b: m.remanence_T for b, m in magnets.items()},
    )
    shear_use = ModelUse("shear", "surface", math.nan, f"{SHEAR_DESCRIPTION}; mesh {response.mesh_mm:g} mm", "auto")
    arrays = {**normal_arrays, "indentation": nominal.indentation_mm, **shear_arrays}
    timings = {"field_choice": t_field - t0, "mechanics": t_mech - t_field, "chain": t_end - t_mech,
               "total": t_end - t0}
    pred = Prediction(field_figures, chip, mus, normal, shear, Noise(**nz), (fuse, muse, shear_use), arrays, timings)
    pred = replace(pred, drift=_drift(design, pred))
    ref = reference_chip(design)
    if pred.drift is not None and ref is not None:
        pred = replace(pred, reference=budget(design, pred, pred.drift, ref))
    return pred


def _drift(design: Design, pred: Prediction) -> Drift | None:
    """The drift budget, or None for a normal curve the calibration could not invert (its field not rising)."""
    try:
        return drift.drift(design, pred)
    except ValueError:
        return None


def indentation_grid(design: Design) -> np.ndarray:
    """The indentations (mm) the normal curve is asked for: a little past the travel to d_min (the magnet lags the
    surface, and the curve must reach d_min), in :data:`N_INDENT` steps graded finer near zero, where a rounded
    tip's force rises as indentation^1.5. The FE solves them up to the scan depth (:func:`_fe_curve`)."""
    return GRID_REACH * travel_to_d_min(design) * np.linspace(0.0, 1.0, N_INDENT) ** 1.5


def travel_to_d_min(design: Design) -> float:
    """How far the magnet travels from rest to d_min, mm."""
    return design.d_rest_mm - design.spec.sensor.d_min_mm


#: How far past the travel to d_min the indentation grid reaches (:func:`indentation_grid`): a magnet that lags the
#: surface by more (deep in a stiff silicone under a small tip) ends its curve short of d_min, and the range then
#: ends there as the model's reach ("model"), not at d_min.
GRID_REACH = 1.25


def normal_on_mesh(design: Design, mesh_mm: float, field_model: str = "exact") -> NormalFigures:
    """The normal figures as :func:`predict` makes them, with the FE on the one mesh ``mesh_mm`` and the given
    field model: what a convergence study of the range compares between meshes."""
    body = mech.Body.from_design(design)
    mus = _band(design)
    indentation = indentation_grid(design)
    nominal = _fe_curve(body, mus["nominal"], indentation, mesh_mm, float(design.spec.calibration.scan_z_mm), None,
                        material_law(design))
    curves = {k: nominal.scaled(mu) if k != "nominal" else nominal for k, mu in mus.items()}
    chip = chip_setting(design)
    magnets = {band: fieldmod.Magnet.from_design(design, band) for band in GRADE_BAND}
    end = _curve_end(nominal, indentation, travel_to_d_min(design))
    return _normal(design, chip, noise(design, chip), magnets, field_model, curves, end)[0]


def _normal(design: Design, chip: ChipSetting, nz: Mapping[str, float], magnets: Mapping[str, fieldmod.Magnet],
            fmodel: str, curves: Mapping[str, mech.Curve],
            end: tuple[str, str]) -> tuple[NormalFigures, dict[str, np.ndarray]]:
    """Normal load: the chain along the nominal curve (the magnet's travel does not depend on mu), over the
    material band and the grade's band, and what ends the range (``end``: :func:`_curve_end` of the nominal
    curve)."""
    sen, p = design.spec.sensor, design.spec.predict
    nominal = curves["nominal"]
    travel = travel_to_d_min(design)
    u = nominal.magnet_displacement_mm  # axial magnet travel, + towards the chip; independent of mu
    gap = design.d_rest_mm - u
    keep = gap >= sen.d_min_mm - 1e-9
    bz = {b: np.asarray(fieldmod.bz_br(m, np.maximum(gap, 1e-3), 0.0, model=fmodel, rtol=None)[0])
          for b, m in magnets.items()}
    s_b = {b: _derivative(u, v) for b, v in bz.items()}  # G per mm of magnet travel
    k_e = {k: _derivative(u, c.force_N) for k, c in curves.items()}  # N per mm of magnet travel
    # Range limits, as magnet travel u: d_min, full scale (strongest magnet), the material law's data end, and the
    # user's own stretch limit if given.
    limits = {"d_min": travel}
    over = np.nonzero(bz["high"] > chip.full_scale_z_G)[0]
    if over.size:
        limits["chip full scale"] = _crossing(u, bz["high"], chip.full_scale_z_G, over[0])
    stretches = {MATERIAL_DATA: data_end_stretch(design)}
    if p.max_stretch is not None:
        stretches[STRETCH] = p.max_stretch
    for label, most in stretches.items():
        stretched = np.nonzero(nominal.max_stretch > most)[0]
        if stretched.size:
            limits[label] = _crossing(u, nominal.max_stretch, most, stretched[0])
    # The field-to-force map stops being one-to-one where the force stops rising with the magnet's travel (the
    # silicone buckles or snaps through) or the field stops rising with it: past there two forces give one field.
    # "Stops" is a slope below FLAT of its largest, so a plateau the derivative leaves at +1e-17 counts; only once it
    # has risen (a rounded tip's stiffness starts at 0: Hertz).
    for slope in (k_e["nominal"], s_b["nominal"]):
        level = FLAT * float(np.max(np.abs(slope)))
        rising = np.nonzero(slope > level)[0]
        flat = np.nonzero(slope[rising[0]:] <= level)[0] if rising.size else rising
        if flat.size:
            k = int(rising[0] + flat[0])
            limits[INVERTIBILITY] = min(limits.get(INVERTIBILITY, math.inf), _crossing(u, slope, level, k))
    end_label, limit_note = end
    if end_label:
        limits[end_label] = float(u[-1])
    binding = min(limits, key=lambda k: limits[k])
    u_max = limits[binding]
    in_range = (u <= u_max + 1e-9) & keep
    f_range = {k: float(np.interp(u_max, u, c.force_N)) for k, c in curves.items()}
    # A travel point with no stiffness (past where the curve turns) or no field slope divides by zero: its figure
    # there is infinite, the same values as before without a warning on the study's workers.
    with np.errstate(divide="ignore"):
        s_f = {(k, b): s_b[b] / k_e[k] for k in curves for b in magnets}
        res_mN = {kb: MN_PER_N * nz["total_z_G"] / v for kb, v in s_f.items()}
    sens_in = np.array([s_f[kb][in_range] for kb in s_f])
    figures = NormalFigures(
        curves=curves,
        magnet_displacement_mm=tuple(float(x) for x in u),
        sensitivity_G_per_N=(float(sens_in.min()), float(sens_in.max())),
        resolution_mN=max(float(np.max(v[in_range])) for v in res_mN.values()),
        resolution_at_rest_mN={k: float(res_mN[(k, "low")][0]) for k in curves},
        range_N=min(f_range.values()),
        range_by_material_N=f_range,
        range_limit=binding,
        range_limits_travel_mm=limits,
        travel_mm=u_max,
        stiffness_at_rest_N_per_mm={k: float(v[0]) for k, v in k_e.items()},
        sensitivity_at_rest_G_per_N={k: float(s_f[(k, "nominal")][0]) for k in curves},
        model_limit=limit_note,
    )
    arrays = {"u": u, "in_range": in_range, **{f"bz_{b}": v for b, v in bz.items()},
              **{f"sb_{b}": v for b, v in s_b.items()}, **{f"ke_{k}": v for k, v in k_e.items()},
              **{f"sf_{k}_{b}": v for (k, b), v in s_f.items()}, **{f"res_{k}_{b}": v for (k, b), v in res_mN.items()}}
    return figures, arrays
