"""The derived geometry held to the printer recipe's minimums, and the fits (pocket on magnet, recess on chip) and
the cavity volume reported. Cheap: no CAD kernel needed."""

from __future__ import annotations

import math

from .. import outline
from ..board.placement import SIZE_STEP_MM
from ..design import Design
from ..errors import Finding, Severity
from ..spec import Pcb

__all__ = ["design_findings"]

E, W, INFO = Severity.ERROR, Severity.WARNING, Severity.INFO


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
    need(rim, min_wall, E, "pad-rim", "the pad's wall outside the larger alignment hole",
         "pad.alignment_hole_spacing_mm")
    need(web, min_wall, W, "pad-web", "the pad's web between lip and alignment hole", "pad.alignment_hole_spacing_mm")
    if design.lip_height_mm > 0:
        need(design.lip_outer_radius_mm - design.lip_inner_radius_mm, min_wall, W, "pad-lip", "the centring lip",
             "pad.lip_width_mm")
    need(design.alignment_holes[0][2], min_hole, W, "pad-hole", "the smaller alignment hole",
         "pad.alignment_hole_diameter_mm", "it will print undersized: ream it with a drill of its nominal size")
    if design.skin_mm < 2 * design.spec.elastomer.min_skin_mm:
        out.append(Finding(W, "thin-skin", f"only {_f(design.skin_mm)} mm of silicone between the pocket's rim and the "
                           "surface; thin skins tear when the magnet is pushed in", "elastomer.min_skin_mm"))

    out.append(Finding(INFO, "pocket-fit", f"pocket {_f(2 * design.pocket_radius_mm)} x {_f(design.pocket_height_mm)} "
                       f"mm holds the {_f(2 * design.magnet_radius_mm)} x {_f(design.magnet_height_mm)} mm magnet with "
                       f"{_f(design.spec.elastomer.pocket_clearance_mm)} mm clearance; "
                       f"{_f(design.skin_mm)} mm skin at its rim, {_f(design.cover_mm)} mm cover on the axis"))
    out.append(Finding(INFO, "recess-fit", f"chip recess {_f(design.recess_side_mm)} x {_f(design.recess_side_mm)} x "
                       f"{_f(design.recess_depth_mm)} mm holds the package (max {_f(design.chip_body_max_mm)} x "
                       f"{_f(design.chip_body_max_mm)} x {_f(design.chip_height_max_mm)} mm)"))
    out.append(Finding(INFO, "stack", f"magnet lower face {_f(design.d_rest_mm)} mm above the sensing point "
                       f"(which is {_f(design.sensing_depth_mm)} mm below the package top)"))
    out.append(Finding(INFO, "cavity-volume", f"cavity volume {design.elastomer_volume_mm3 / 1000:.3f} mL of silicone "
                       f"per part, {design.cavities} cavit{'y' if design.cavities == 1 else 'ies'} per mould"))
    if design.array is not None:
        arr = design.array
        out.append(Finding(INFO, "array", f"{len(arr.taxels)} taxels {_f(arr.pitch_mm)} mm apart ({arr.skin.value} "
                           f"{'skin' if design.continuous else 'tips'}; the parts allow {_f(arr.min_pitch_mm)} mm): "
                           f"{_f(arr.pitch_mm - design.recess_side_mm)} mm of pad between chip recesses" +
                           (f", {_f(arr.pitch_mm - 2 * design.pocket_radius_mm)} mm of silicone between pockets"
                            if design.continuous else "")))
    if design.pcb_sized:
        out.append(_board_sized(design))
    return out


def _board_sized(design: Design) -> Finding:
    """The board's size, where the spec left a side unstated and the default did not hold the parts."""
    pcb = design.spec.pcb
    keys = " and ".join(f"pcb.{k}" for k in design.pcb_sized)
    default = " x ".join(f"{Pcb.model_fields[k].default:g}" for k in design.pcb_sized)
    return Finding(INFO, "pcb-sized", f"board sized to fit, {pcb.width_mm:g} x {pcb.height_mm:g} mm: {keys} not "
                   f"stated, and the default {default} mm does not hold the parts; the least that does, in "
                   f"{SIZE_STEP_MM:g} mm steps (state the size to choose another)", "pcb")


def _array_pad_walls(design: Design) -> tuple[float, float]:
    """An array pad's thinnest wall outside an alignment hole (to the pad's outline, the taxels' hull grown by the
    pad radius) and web between a hole and a centring lip (round each tip, or round the skin)."""
    assert design.array is not None  # called for an array only
    hull = list(design.array.hull_mm)
    rim = web = math.inf
    for x, y, d in design.alignment_holes:
        rim = min(rim, design.pad_radius_mm - outline.distance((x, y), hull) - d / 2)
        to_lip = outline.distance((x, y), hull) if design.continuous else \
            min(math.dist((x, y), (t.x_mm, t.y_mm)) for t in design.taxels)
        web = min(web, to_lip - d / 2 - design.lip_outer_radius_mm)
    return rim, web
