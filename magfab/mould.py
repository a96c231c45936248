"""The inverse casting mould: a cup with the cavities and a lid that carries the pocket cores.

A cavity holds one tip, or one continuous skin (an array cast as one part: a core under each of its taxels, a
fill hole beside each core, the vents shared where two would meet).

How it is used (the fabrication checklist says the same): spray release agent, fill each cavity of the
cup to the brim, lower the lid onto the registration pins so each core sinks into its cavity; the excess
silicone and the air escape through the fill (sprue) and vent holes. After curing, lever the lid off at
its overhanging ends: each core's pocket is wider than its channel, so the part comes out of the cup on
the lid, and is then peeled off the core (the silicone stretches over it).

The elastomer is cast upside down (tip at the bottom of the cup), so its flat, glued base is moulded
against the lid and the only trapped air collects under the lid, where the vents are.

Print poses: the cup stands on its bottom; the lid lies on its top face with the cores pointing up, so
the cores' 45-degree funnels print without support.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .design import Design
from .elastomer import core_solid, envelope_solid

if TYPE_CHECKING:
    import cadquery as cq

# Imported lazily, inside the functions that use it, for speed: CadQuery takes a
# noticeable time to import, and importing this module should not.

__all__ = ["cup_solid", "lid_solid", "COUNTERSINK_MM", "OVERLAP_MM"]

#: Depth of the pouring countersink on top of each sprue.
COUNTERSINK_MM = 1.0
#: Cutting tools reach this far past a face they open, so no faces are coplanar.
OVERLAP_MM = 0.5


def _cavity_tool(design: Design) -> cq.Workplane:
    """The envelope, extended past its base so the cut opens cleanly through the cup's top face."""
    return envelope_solid(design, below_mm=OVERLAP_MM)


def _flip_to(solid: cq.Workplane, x: float, z: float) -> cq.Workplane:
    """Turn an elastomer-frame solid upside down and put its base plane at height z over (x, 0)."""
    return solid.rotate((0, 0, 0), (1, 0, 0), 180).translate((x, 0, z))


def cup_solid(design: Design) -> cq.Workplane:
    import cadquery as cq

    lx, ly, h = design.cup_size_mm
    cup = cq.Workplane("XY").box(lx, ly, h, centered=(True, True, False))
    tool = _cavity_tool(design)
    for x in design.cavity_centres_x_mm:
        cup = cup.cut(_flip_to(tool, x, h))
    pin_h = design.pin_height_mm
    for x in design.pin_positions_x_mm:
        pin = (cq.Workplane("XY", origin=(x, 0, h - OVERLAP_MM)).circle(design.pin_diameter_mm / 2)
               .extrude(pin_h + OVERLAP_MM))
        cup = cup.union(pin)
    return cup


def lid_solid(design: Design) -> cq.Workplane:
    """The lid in its print pose (top face on the bed, cores up)."""
    import cadquery as cq

    h = design.cup_size_mm[2]
    t = design.lid_thickness_mm
    lx, ly, _ = design.lid_size_mm
    lid = cq.Workplane("XY", origin=(0, 0, h)).box(lx, ly, t, centered=(True, True, False))
    core = core_solid(design, extend_below_mm=design.core_root_mm)
    for x, y in design.core_centres_mm:
        lid = lid.union(_flip_to(core, x, h).translate((0, y, 0)) if y else _flip_to(core, x, h))
    for x, y, d in design.lid_holes:
        lid = lid.cut(cq.Workplane("XY", origin=(x, y, h - OVERLAP_MM)).circle(d / 2).extrude(t + 2 * OVERLAP_MM))
    r = design.sprue_diameter_mm / 2.0
    for x, y in design.core_centres_mm:
        cone = cq.Solid.makeCone(r, r + COUNTERSINK_MM + OVERLAP_MM, COUNTERSINK_MM + OVERLAP_MM,
                                 pnt=cq.Vector(x, y + design.sprue_offset_mm, h + t - COUNTERSINK_MM))
        lid = lid.cut(cq.Workplane("XY").add(cone))
    return lid.rotate((0, 0, 0), (1, 0, 0), 180).translate((0, 0, h + t))
