"""Design rules and printability checks, returned as findings with a severity.

Two kinds:

* :func:`design_findings` holds the derived geometry to the printer recipe's minimums and reports the
  fits (pocket on magnet, recess on chip) and the cavity volume. Cheap: no CAD kernel needed.
* :func:`mesh_findings` checks each exported mesh: watertight, consistently oriented, positive
  volume, and its volume equal to the exact solid's within what the tessellation tolerance allows.

Error-level findings stop a build (:class:`~magfab.errors.BuildError`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from . import outline
from .design import Design
from .errors import Finding, Severity
from .spec import FieldModel

if TYPE_CHECKING:
    import trimesh

__all__ = ["design_findings", "mesh_findings", "mould_fit_findings", "prediction_findings", "errors_in"]

E, W, I = Severity.ERROR, Severity.WARNING, Severity.INFO


def _f(x: float) -> str:
    return f"{x:.2f}"


def design_findings(design: Design) -> list[Finding]:
    """Printer minimums, fits and quantities for a derived design."""
    p = design.printer
    min_wall = p["min_wall_mm"].nominal
    min_hole = p["min_hole_mm"].nominal
    min_pin = p["min_pin_mm"].nominal
    kind = p.key
    out: list[Finding] = []

    def need(value: float, minimum: float, severity: Severity, code: str, what: str, key: str, fix: str = "") -> None:
        if value + 1e-9 < minimum:
            text = f"{what} is {_f(value)} mm, below the {kind} printer's minimum of {_f(minimum)} mm"
            out.append(Finding(severity, code, text + (f"; {fix}" if fix else ""), key))

    need(design.wall_mm, min_wall, E, "mould-wall", "mould wall", "mould.wall_mm")
    need(design.lid_thickness_mm, min_wall, E, "lid-wall", "mould lid", "mould.wall_mm")
    need(2 * design.channel_radius_mm, min_pin, E, "core-stem", "the core's stem (insert channel diameter)",
         "elastomer.insert_channel_diameter_mm")
    need(design.sprue_diameter_mm, min_hole, E, "sprue", "the fill hole", "elastomer.diameter_mm",
         "the annulus between channel and cavity wall is too narrow")
    need(design.pad_roof_mm, min_wall, E, "pad-roof", "the pad's roof over the chip recess", "pad.thickness_mm")
    if design.array is None:
        rim = design.pad_radius_mm - (design.alignment_holes[-1][0] + design.alignment_holes[-1][2] / 2)
        web = (design.alignment_holes[0][0] * -1 - design.alignment_holes[0][2] / 2) - design.lip_outer_radius_mm
    else:
        rim, web = _array_pad_walls(design)
    need(rim, min_wall, E, "pad-rim", "the pad's wall outside the larger alignment hole", "pad.alignment_hole_spacing_mm")
    need(web, min_wall, W, "pad-web", "the pad's web between lip and alignment hole", "pad.alignment_hole_spacing_mm")
    if design.lip_height_mm > 0:
        need(design.lip_outer_radius_mm - design.lip_inner_radius_mm, min_wall, W, "pad-lip", "the centring lip",
             "pad.lip_width_mm")
    need(design.alignment_holes[0][2], min_hole, W, "pad-hole", "the smaller alignment hole",
         "pad.alignment_hole_diameter_mm", "it will print undersized: ream it with a drill of its nominal size")
    if design.skin_mm < 2 * design.spec.elastomer.min_skin_mm:
        out.append(Finding(W, "thin-skin", f"only {_f(design.skin_mm)} mm of silicone between the pocket's rim and the "
                           "surface; thin skins tear when the magnet is pushed in", "elastomer.min_skin_mm"))

    out.append(Finding(I, "pocket-fit", f"pocket {_f(2 * design.pocket_radius_mm)} x {_f(design.pocket_height_mm)} mm "
                       f"holds the {_f(2 * design.magnet_radius_mm)} x {_f(design.magnet_height_mm)} mm magnet with "
                       f"{_f(design.spec.elastomer.pocket_clearance_mm)} mm clearance; "
                       f"{_f(design.skin_mm)} mm skin at its rim, {_f(design.cover_mm)} mm cover on the axis"))
    out.append(Finding(I, "recess-fit", f"chip recess {_f(design.recess_side_mm)} x {_f(design.recess_side_mm)} x "
                       f"{_f(design.recess_depth_mm)} mm holds the package (max {_f(design.chip_body_max_mm)} x "
                       f"{_f(design.chip_body_max_mm)} x {_f(design.chip_height_max_mm)} mm)"))
    out.append(Finding(I, "stack", f"magnet lower face {_f(design.d_rest_mm)} mm above the sensing point "
                       f"(which is {_f(design.sensing_depth_mm)} mm below the package top)"))
    out.append(Finding(I, "cavity-volume", f"cavity volume {design.elastomer_volume_mm3 / 1000:.3f} mL of silicone per "
                       f"part, {design.cavities} cavit{'y' if design.cavities == 1 else 'ies'} per mould"))
    if design.array is not None:
        arr = design.array
        out.append(Finding(I, "array", f"{len(arr.taxels)} taxels {_f(arr.pitch_mm)} mm apart ({arr.skin.value} "
                           f"{'skin' if design.continuous else 'tips'}; the parts allow {_f(arr.min_pitch_mm)} mm): "
                           f"{_f(arr.pitch_mm - design.recess_side_mm)} mm of pad between chip recesses" +
                           (f", {_f(arr.pitch_mm - 2 * design.pocket_radius_mm)} mm of silicone between pockets"
                            if design.continuous else "")))
    return out


def _array_pad_walls(design: Design) -> tuple[float, float]:
    """An array pad's thinnest wall outside an alignment hole (to the pad's outline, the taxels' hull grown by the
    pad radius) and web between a hole and a centring lip (round each tip, or round the skin)."""
    hull = list(design.array.hull_mm)
    rim = web = math.inf
    for x, y, d in design.alignment_holes:
        rim = min(rim, design.pad_radius_mm - outline.distance((x, y), hull) - d / 2)
        to_lip = outline.distance((x, y), hull) if design.continuous else \
            min(math.dist((x, y), (t.x_mm, t.y_mm)) for t in design.taxels)
        web = min(web, to_lip - d / 2 - design.lip_outer_radius_mm)
    return rim, web


def mesh_findings(name: str, mesh: trimesh.Trimesh, solid_volume_mm3: float, tolerance_mm: float) -> list[Finding]:
    """Integrity of one exported mesh against the exact solid it was made from."""
    out: list[Finding] = []
    if not mesh.is_watertight:
        out.append(Finding(E, "mesh-watertight", f"{name}.stl is not watertight"))
    if not mesh.is_winding_consistent:
        out.append(Finding(E, "mesh-winding", f"{name}.stl has inconsistently oriented faces"))
    volume = float(mesh.volume)
    if not volume > 0.0:
        out.append(Finding(E, "mesh-volume", f"{name}.stl has non-positive volume {volume:.3f} mm^3 (inside out?)"))
    # Every facet lies within the tolerance of the exact surface, so the volumes may differ by at most
    # about area x tolerance.
    allowed = float(mesh.area) * tolerance_mm
    diff = abs(volume - solid_volume_mm3)
    if diff > allowed:
        out.append(Finding(E, "mesh-deviation", f"{name}.stl volume {volume:.3f} mm^3 differs from the solid's "
                           f"{solid_volume_mm3:.3f} mm^3 by more than area x tolerance ({allowed:.3f} mm^3)"))
    return out


def mould_fit_findings(design: Design, fit) -> list[Finding]:
    """The closed mould measured on its meshes (:class:`magfab.fit.MouldFit`): no interference, each cavity
    equal to the cast part, walls no thinner than the printer's minimum."""
    out: list[Finding] = []
    allowed = fit.allowed_mm3
    if fit.cup_lid_interference_mm3 > allowed:
        out.append(Finding(E, "mould-interference", f"the closed lid overlaps the cup by {fit.cup_lid_interference_mm3:.3f} "
                           f"mm^3 (more than the {allowed:.3f} mm^3 tessellation allows): it will not close"))
    for i, (cavity, over, under) in enumerate(zip(fit.cavity_volume_mm3, fit.part_outside_mm3,
                                                  fit.cavity_outside_mm3), start=1):
        if over > allowed:
            out.append(Finding(E, "mould-part-overlap", f"cavity {i}: {over:.3f} mm^3 of the cast part lies outside the "
                               "closed mould's cavity (the cores or the cup overlap the part)"))
        if under > allowed:
            out.append(Finding(E, "mould-cavity", f"cavity {i} of the closed mould holds {cavity:.3f} mm^3, "
                               f"{under:.3f} mm^3 more than the cast part ({fit.part_volume_mm3:.3f} mm^3)"))
    min_wall = design.printer["min_wall_mm"].nominal
    tol = design.spec.mould.tessellation_tolerance_mm
    for what, value, key in (("cup wall round a cavity", fit.cup_wall_mm, "mould.wall_mm"),
                             ("web between cavities", fit.cavity_web_mm, "mould.wall_mm")):
        if value is not None and value + tol < min_wall:
            out.append(Finding(E, "mould-wall-mesh", f"the printed {what} is {value:.2f} mm on the mesh, below the "
                               f"{design.printer.key} printer's minimum of {min_wall:.2f} mm", key))
    worst = max(a + b for a, b in zip(fit.part_outside_mm3, fit.cavity_outside_mm3))
    web = "" if fit.cavity_web_mm is None else f", {fit.cavity_web_mm:.2f} mm between cavities"
    out.append(Finding(I, "mould-fit", f"closed mould checked on the STL meshes: {len(fit.cavity_volume_mm3)} "
                       f"cavit{'y' if len(fit.cavity_volume_mm3) == 1 else 'ies'} equal to the cast part within "
                       f"{worst:.2g} mm^3 (allowed {allowed:.2g}), interference {fit.cup_lid_interference_mm3:.2g} mm^3, "
                       f"thinnest cup wall {fit.cup_wall_mm:.2f} mm{web}"))
    return out


def errors_in(findings: list[Finding], strict: bool = False) -> list[Finding]:
    """The findings that stop a build (warnings too when ``strict``)."""
    stop = {Severity.ERROR, Severity.WARNING} if strict else {Severity.ERROR}
    return [f for f in findings if f.severity in stop]


#: The spec key that moves each normal range limit (predict.py's labels); d_min and the chip's full scale have theirs
#: in their own findings, and "model" (the FE stopped before the scan depth) none a user sets.
_RANGE_LIMIT_KEYS = {"stretch": "predict.max_stretch", "scan depth": "calibration.scan_z_mm"}


def prediction_findings(design: Design, pred) -> list[Finding]:
    """The design constraints as errors and the design guidelines as warnings (docs/models.md, M9 and M18), from a
    :class:`magfab.models.predict.Prediction`; the predicted figures themselves as info."""
    from .models import field as fieldmod

    spec = design.spec
    sen, p = spec.sensor, spec.predict
    chip, normal, shear = pred.chip, pred.normal, pred.shear
    out: list[Finding] = []
    # M9: B(d_min) <= B_sat at the configured gain and resolution (strongest magnet of the grade).
    b_dmin = pred.field.Bz_d_min_strongest_G
    if b_dmin > chip.full_scale_z_G:
        strongest = fieldmod.Magnet.from_design(design, "high")
        d_sat = _saturation_gap(strongest, chip.full_scale_z_G, sen.d_min_mm, design.d_rest_mm)
        out.append(Finding(E, "chip-saturates",
                           f"Bz at d_min = {sen.d_min_mm:g} mm is {b_dmin:.0f} G with the grade's strongest magnet, above "
                           f"the chip's {chip.full_scale_z_G:.0f} G full scale at GAIN_SEL {chip.gain_sel} / RES "
                           f"{chip.resolution}: raise sensor.d_min_mm to at least {math.ceil(d_sat * 100) / 100:.2f} mm"
                           + (", or lower sensor.gain_sel" if chip.gain_sel > 0 else "")
                           + ", or use a weaker or smaller magnet", "sensor.d_min_mm"))
    # M9: the gradient at d_max must resolve what the user needs (if they said).
    need = p.required_resolution_mN
    if need is not None and normal.resolution_mN > need:
        out.append(Finding(E, "resolution-short",
                           f"worst-case normal resolution {normal.resolution_mN:.2f} mN (stiff material, weakest magnet, "
                           f"at rest) is coarser than the {need:g} mN asked for: dBz/dz at d_max = "
                           f"{pred.field.dBz_dz_rest_G_per_mm:.0f} G/mm is too shallow; reduce sensor.d_max_mm, use a "
                           "softer elastomer.material or a stronger magnet", "predict.required_resolution_mN"))
    if normal.range_limit != "d_min":
        travel = normal.range_limits_travel_mm
        out.append(Finding(I, "range-limit",
                           f"the normal range ends at {normal.travel_mm:.2f} mm of magnet travel ({normal.range_limit}), "
                           f"before the magnet reaches d_min ({travel['d_min']:.2f} mm of travel)",
                           _RANGE_LIMIT_KEYS.get(normal.range_limit, "")))
    # Guidelines (docs/models.md, M18).
    ratio = spec.magnet.height_mm / spec.magnet.diameter_mm
    if not 0.2 <= ratio <= 0.5:
        out.append(Finding(W, "magnet-aspect", f"magnet height/diameter is {ratio:.2f}; the design guideline is 0.2-0.5",
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
                           f"{max(kn / ks, ks / kn):.1f}x; the guideline wants them comparable (elastomer.diameter_mm sets both)",
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
    out.append(Finding(I, "prediction",
                       f"normal: {normal.sensitivity_G_per_N[0]:.0f}-{normal.sensitivity_G_per_N[1]:.0f} G/N, "
                       f"resolution {normal.resolution_mN:.1f} mN, range {normal.range_N:.2f} N; shear: "
                       f"{shear.sensitivity_G_per_N[0]:.0f}-{shear.sensitivity_G_per_N[1]:.0f} G/N, resolution "
                       f"{shear.resolution_mN:.1f} mN, range {shear.range_N:.2f} N (worst case over the material "
                       f"and magnet bands; noise {pred.noise.total_z_G:.3f} G)"))
    return out


def _saturation_gap(magnet, full_scale_G: float, lo: float, hi: float) -> float:
    """The gap d (mm) at which Bz on the axis equals ``full_scale_G`` (bisection; Bz falls with d)."""
    from .models import field as fieldmod

    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if fieldmod.bz_br(magnet, mid, 0.0, model=FieldModel.EXACT)[0] > full_scale_G:
            lo = mid
        else:
            hi = mid
    return hi
