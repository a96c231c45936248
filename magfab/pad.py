"""The rigid mounting pad: a disc that drops over the chip and centres the elastomer on it.

Board frame (z = 0 on the PCB's top face, the chip centred on the axis), which is also its print pose:
the chip recess is cut from below, the centring lip stands on the glue face, and two through holes of
different diameters take dowel pins into matching holes in the board, so the pad fits one way round.

Under an array the pad is one part: its outline the taxels' hull grown by the pad radius, a chip recess under each
taxel, and a centring lip round each separate tip or one round a continuous skin's outline.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .design import Design
from .elastomer import outline_prism

if TYPE_CHECKING:
    import cadquery as cq

# Imported lazily, inside the functions that use it, for speed: CadQuery takes a
# noticeable time to import, and importing this module should not.

__all__ = ["pad_solid"]


def pad_solid(design: Design) -> cq.Workplane:
    import cadquery as cq

    if design.array is not None:
        return _array_pad(design)
    t = design.pad_thickness_mm
    pad = cq.Workplane("XY").circle(design.pad_radius_mm).extrude(t)
    if design.lip_height_mm > 0.0:
        lip = (
            cq.Workplane("XY", origin=(0, 0, t))
            .circle(design.lip_outer_radius_mm)
            .circle(design.lip_inner_radius_mm)
            .extrude(design.lip_height_mm)
        )
        pad = pad.union(lip)
    recess = cq.Workplane("XY").rect(design.recess_side_mm, design.recess_side_mm).extrude(design.recess_depth_mm)
    pad = pad.cut(recess)
    for x, y, d in design.alignment_holes:
        hole = cq.Workplane("XY", origin=(x, y, -1.0)).circle(d / 2.0).extrude(t + 2.0)
        pad = pad.cut(hole)
    return pad


def _array_pad(design: Design) -> cq.Workplane:
    import cadquery as cq


    t, lip_h = design.pad_thickness_mm, design.lip_height_mm
    centres = [(tx.x_mm, tx.y_mm) for tx in design.taxels]
    pad = outline_prism(centres, design.pad_radius_mm, 0.0, t)
    if lip_h > 0.0:
        if design.continuous:
            lip = outline_prism(centres, design.lip_outer_radius_mm, t, t + lip_h).cut(
                outline_prism(centres, design.lip_inner_radius_mm, t - 1.0, t + lip_h + 1.0))
        else:
            lip = (cq.Workplane("XY", origin=(0, 0, t)).pushPoints(centres).circle(design.lip_outer_radius_mm)
                   .extrude(lip_h).cut(cq.Workplane("XY", origin=(0, 0, t - 1.0)).pushPoints(centres)
                                       .circle(design.lip_inner_radius_mm).extrude(lip_h + 2.0)))
        pad = pad.union(lip)
    side = design.recess_side_mm
    pad = pad.cut(cq.Workplane("XY", origin=(0, 0, -1.0)).pushPoints(centres).rect(side, side)
                  .extrude(design.recess_depth_mm + 1.0))
    for x, y, d in design.alignment_holes:
        pad = pad.cut(cq.Workplane("XY", origin=(x, y, -1.0)).circle(d / 2.0).extrude(t + 2.0))
    return pad.clean()
