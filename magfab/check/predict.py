"""The prediction checked: the design constraints as errors and the guidelines as warnings (docs/models.md,
M9, M18); with the drift budget's and the reference chip's findings, what :func:`predict_with_findings` returns
beside the prediction."""

from __future__ import annotations

import math

from ..design import Design
from ..errors import Finding, Severity
from ..models import field as fieldmod
from ..models import mechanics as mech
from ..models.predict import ElastomerModel, NormalFigures, Prediction, law_in_force, predict, yeoh_can_run
from ..spec import MaterialLaw
from .drift import drift_findings
from .reference import reference_findings

__all__ = ["prediction_findings", "predict_with_findings"]

E, W, INFO = Severity.ERROR, Severity.WARNING, Severity.INFO


#: The spec key that moves each normal range limit (predict.py's labels); d_min and the chip's full scale have theirs
#: in their own findings, and "model" (the FE stopped before the scan depth) and "invertibility" (the force or field
#: stops rising) none a user sets; "material data" (the law's data end) the law, where a further one is fitted.
_RANGE_LIMIT_KEYS = {"stretch": "predict.max_stretch", "scan depth": "calibration.scan_z_mm",
                     "material data": "predict.material_law"}


def prediction_findings(design: Design, pred: Prediction) -> list[Finding]:
    """The design constraints as errors and the design guidelines as warnings (docs/models.md, M9 and M18), from a
    :class:`magfab.models.predict.Prediction`; the predicted figures themselves as info."""
    spec = design.spec
    sen, p = spec.sensor, spec.predict
    chip, normal, shear = pred.chip, pred.normal, pred.shear
    out: list[Finding] = []
    # M9: B(d_min) <= B_sat at the configured gain and resolution (strongest magnet of the grade).
    b_dmin = pred.field.Bz_d_min_strongest_G
    if b_dmin > chip.full_scale_z_G:
        strongest = fieldmod.Magnet.from_design(design, "high")
        d_sat = fieldmod.saturation_gap(strongest, chip.full_scale_z_G, sen.d_min_mm, design.d_rest_mm)
        out.append(Finding(E, "chip-saturates",
                           f"Bz at d_min = {sen.d_min_mm:g} mm is {b_dmin:.0f} G with the grade's strongest magnet, "
                           f"above the chip's {chip.full_scale_z_G:.0f} G full scale at GAIN_SEL {chip.gain_sel} / RES "
                           f"{chip.resolution}: raise sensor.d_min_mm to at least {math.ceil(d_sat * 100) / 100:.2f} mm"
                           + (", or lower sensor.gain_sel" if chip.gain_sel > 0 else "")
                           + ", or use a weaker or smaller magnet", "sensor.d_min_mm"))
    # M9: the gradient at d_max must resolve what the user needs (if they said).
    need = p.required_resolution_mN
    if need is not None and normal.resolution_mN > need:
        out.append(Finding(E, "resolution-short",
                           f"worst-case normal resolution {normal.resolution_mN:.2f} mN (stiff material, weakest "
                           f"magnet, over the range) is coarser than the {need:g} mN asked for: dBz/dz at d_max = "
                           f"{pred.field.dBz_dz_rest_G_per_mm:.0f} G/mm is too shallow; reduce sensor.d_max_mm, use a "
                           "softer elastomer.material or a stronger magnet", "predict.required_resolution_mN"))
    if normal.range_limit != "d_min":
        out.append(_range_limit(normal, yeoh_can_run(design) and law_in_force(design) is not MaterialLaw.YEOH))
    # Guidelines (docs/models.md, M18).
    ratio = spec.magnet.height_mm / spec.magnet.diameter_mm
    if not 0.2 <= ratio <= 0.5:
        out.append(Finding(W, "magnet-aspect",
                           f"magnet height/diameter is {ratio:.2f}; the design guideline is 0.2-0.5",
                           "magnet.height_mm"))
    reach = design.d_rest_mm / spec.magnet.diameter_mm
    if not 1.0 <= reach <= 2.0:
        out.append(Finding(W, "rest-distance", f"d_max is {reach:.2f} magnet diameters; the guideline is 1-2 "
                           "(closer saturates sooner, further loses gradient)", "sensor.d_max_mm"))
    b_end = pred.field.Bz_range_end_strongest_G
    if b_end > chip.saturation_onset_G:
        out.append(Finding(W, "imc-saturation",
                           f"the field reaches {b_end:.0f} G at the end of the force range, above the chip's "
                           f"{chip.saturation_onset_G:.0f} G saturation onset: the response is non-linear there, so "
                           "calibrate over the whole range", "sensor.d_min_mm"))
    kn = normal.stiffness_at_rest_N_per_mm["nominal"]
    ks = shear.stiffness_N_per_mm["nominal"]
    if not 0.2 <= kn / ks <= 5.0:
        out.append(Finding(W, "stiffness-balance",
                           f"normal stiffness at rest {kn:.3f} N/mm and shear stiffness {ks:.3f} N/mm differ by "
                           f"{max(kn / ks, ks / kn):.1f}x; the guideline wants them comparable (elastomer.diameter_mm "
                           "sets both)",
                           "elastomer.diameter_mm"))
    slender = design.elastomer_height_mm / (2 * design.elastomer_radius_mm)
    if slender > 1.5:
        out.append(Finding(W, "buckling", f"the elastomer is {slender:.1f} diameters tall: a slender probe may buckle "
                           "under shear and normal load", "elastomer.height_mm"))
    tol = p.tolerance_pct / 100.0
    for m in pred.models:
        family, err = m.family, m.error
        if math.isfinite(err) and err > tol:
            out.append(Finding(W, "model-error",
                               f"the {family} model '{m.name}' has an estimated error of {100 * err:.2g} %, more than "
                               f"predict.tolerance_pct = {p.tolerance_pct:g} %", f"predict.{family}_model"
                               if family in ("field", "mechanics") else "predict.tolerance_pct"))
    # significant digits, never decimals: a very soft or very stiff design's figures must not print as 0
    out.append(Finding(INFO, "prediction",
                       f"normal: {normal.sensitivity_G_per_N[0]:.3g}-{normal.sensitivity_G_per_N[1]:.3g} G/N, "
                       f"resolution {normal.resolution_mN:.3g} mN, range "
                       f"{'at least ' * normal.range_is_model_reach}{normal.range_N:.3g} N; shear: "
                       f"{shear.sensitivity_G_per_N[0]:.3g}-{shear.sensitivity_G_per_N[1]:.3g} G/N, resolution "
                       f"{shear.resolution_mN:.3g} mN, range {shear.range_N:.3g} N (worst case over the material "
                       f"and magnet bands; noise {pred.noise.total_z_G:.3f} G)"))
    return out


def _range_limit(normal: NormalFigures, yeoh_reaches: bool) -> Finding:
    """The note on what ends the normal range before d_min, and whether it is the sensor or a model's reach;
    ``yeoh_reaches``: the silicone has a Yeoh law the spec does not use, which would take the range further."""
    travel = normal.range_limits_travel_mm
    model_reach, key = "", _RANGE_LIMIT_KEYS.get(normal.range_limit, "")
    if normal.range_is_model_reach:
        model_reach = ": a model's reach, not the sensor's, so the sensor reaches at least this far"
        if normal.range_limit == "material data":
            if yeoh_reaches:
                model_reach += " (predict.material_law = 'yeoh' is fitted to a stretch of 4)"
            else:
                key = ""  # no law in the recipes reaches further for this silicone
    return Finding(INFO, "range-limit",
                   f"the normal range ends at {normal.travel_mm:.2f} mm of magnet travel ({normal.range_limit}), "
                   f"before the magnet reaches d_min ({travel['d_min']:.2f} mm of travel){model_reach}", key)


def predict_with_findings(design: Design,
                          elastomer: ElastomerModel | None = None) -> tuple[Prediction | None, list[Finding]]:
    """:func:`predict` and its design checks; a model that cannot give an answer for this design (the FE
    failing at its first step, a field model refusing every point) is an error finding, not a traceback."""
    try:
        pred = predict(design, elastomer)
    except (mech.MechanicsError, fieldmod.FieldModelError) as exc:
        return None, [Finding(Severity.ERROR, "prediction-failed", f"no prediction for this design: {exc}",
                              "predict.mechanics_model" if isinstance(exc, mech.MechanicsError)
                              else "predict.field_model")]
    return pred, (prediction_findings(design, pred) + ([] if pred.drift is None else drift_findings(design, pred.drift))
                  + reference_findings(design, pred.reference))
