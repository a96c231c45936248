"""Design rules and printability checks, returned as findings with a severity.

Two kinds:

* :func:`design_findings` holds the derived geometry to the printer recipe's minimums and reports the
  fits (pocket on magnet, recess on chip) and the cavity volume. Cheap: no CAD kernel needed.
* :func:`mesh_findings` checks each exported mesh: watertight, consistently oriented, positive
  volume, and its volume equal to the exact solid's within what the tessellation tolerance allows.

Error-level findings stop a build (:class:`~magfab.errors.BuildError`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .design import Design
from .errors import Finding, Severity

if TYPE_CHECKING:
    import trimesh

__all__ = ["design_findings", "mesh_findings", "errors_in"]

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
    rim = design.pad_radius_mm - (design.alignment_holes[-1][0] + design.alignment_holes[-1][2] / 2)
    need(rim, min_wall, E, "pad-rim", "the pad's wall outside the larger alignment hole", "pad.alignment_hole_spacing_mm")
    web = (design.alignment_holes[0][0] * -1 - design.alignment_holes[0][2] / 2) - design.lip_outer_radius_mm
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
                       f"part, {design.spec.mould.cavities} cavit{'y' if design.spec.mould.cavities == 1 else 'ies'} "
                       "per mould"))
    return out


def mesh_findings(name: str, mesh: "trimesh.Trimesh", solid_volume_mm3: float, tolerance_mm: float) -> list[Finding]:
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


def errors_in(findings: list[Finding], strict: bool = False) -> list[Finding]:
    """The findings that stop a build (warnings too when ``strict``)."""
    stop = {Severity.ERROR, Severity.WARNING} if strict else {Severity.ERROR}
    return [f for f in findings if f.severity in stop]
