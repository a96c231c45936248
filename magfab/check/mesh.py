"""The exported meshes checked: each one watertight, consistently oriented, of positive volume and equal to the
exact solid's within what the tessellation tolerance allows; the closed mould measured on its meshes."""

from __future__ import annotations

from typing import TYPE_CHECKING

from ..design import Design
from ..errors import Finding, Severity

if TYPE_CHECKING:
    import trimesh

    from ..fit import MouldFit

__all__ = ["mesh_findings", "mould_fit_findings"]

E, INFO = Severity.ERROR, Severity.INFO


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


def mould_fit_findings(design: Design, fit: MouldFit) -> list[Finding]:
    """The closed mould measured on its meshes (:class:`magfab.fit.MouldFit`): no interference, each cavity
    equal to the cast part, walls no thinner than the printer's minimum."""
    out: list[Finding] = []
    allowed = fit.allowed_mm3
    if fit.cup_lid_interference_mm3 > allowed:
        out.append(Finding(E, "mould-interference",
                           f"the closed lid overlaps the cup by {fit.cup_lid_interference_mm3:.3f} "
                           f"mm^3 (more than the {allowed:.3f} mm^3 tessellation allows): it will not close"))
    for i, (cavity, over, under) in enumerate(zip(fit.cavity_volume_mm3, fit.part_outside_mm3,
                                                  fit.cavity_outside_mm3), start=1):
        if over > allowed:
            out.append(Finding(E, "mould-part-overlap",
                               f"cavity {i}: {over:.3f} mm^3 of the cast part lies outside the "
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
    out.append(Finding(INFO, "mould-fit", f"closed mould checked on the STL meshes: {len(fit.cavity_volume_mm3)} "
                       f"cavit{'y' if len(fit.cavity_volume_mm3) == 1 else 'ies'} equal to the cast part within "
                       f"{worst:.2g} mm^3 (allowed {allowed:.2g}), interference {fit.cup_lid_interference_mm3:.2g} "
                       f"mm^3, thinnest cup wall {fit.cup_wall_mm:.2f} mm{web}"))
    return out
