"""The rigid mounting pad: a disc that drops over the chip and centres the elastomer on it.

Board frame (z = 0 on the PCB's top face, the chip centred on the axis), which is also its print pose:
the chip recess is cut from below, the centring lip stands on the glue face, and two through holes of
different diameters take dowel pins into matching holes in the board, so the pad fits one way round.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .design import Design

if TYPE_CHECKING:
    import cadquery as cq

__all__ = ["pad_solid"]


def pad_solid(design: Design) -> "cq.Workplane":
    import cadquery as cq

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
