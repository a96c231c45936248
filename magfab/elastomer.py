"""The elastomer solid: a cylindrical base with a hemispherical or flat tip, and the magnet pocket.

Built in the elastomer frame of :mod:`magfab.design` (base on z = 0, axis on z) by revolving the
design's (r, z) profiles, so the solid and the closed-form volumes come from the same numbers.

A continuous skin (an array cast as one part) is the same tip over every taxel on a common base: a slab whose
outline is the taxels' hull grown by the tip's radius (:mod:`magfab.outline`), of the tip's base height, with
the tip's dome over each taxel, and the tip's pocket, funnel and channel under each.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from . import outline
from .design import Design

if TYPE_CHECKING:
    import cadquery as cq

# Imported lazily, inside the functions that use it, for speed: CadQuery takes a
# noticeable time to import, and importing this module should not.

__all__ = ["revolve_profile", "outline_prism", "envelope_solid", "core_solid", "elastomer_solid"]


def revolve_profile(profile: list[tuple[float, float]], arc_at: int | None = None) -> cq.Workplane:
    """Revolve a closed (r, z) profile about the z axis.

    ``arc_at``: index i such that points i-1, i, i+1 form a circular arc (through point i) instead of
    two straight segments.
    """
    import cadquery as cq

    wp = cq.Workplane("XZ").moveTo(*profile[0])
    i = 1
    while i < len(profile):
        if arc_at is not None and i == arc_at:
            wp = wp.threePointArc(profile[i], profile[i + 1])
            i += 2
        else:
            wp = wp.lineTo(*profile[i])
            i += 1
    # On the XZ workplane, local y is global z: revolve about it.
    return wp.close().revolve(360.0, (0, 0, 0), (0, 1, 0))


def outline_prism(centres: list[tuple[float, float]], radius: float, z0: float, z1: float) -> cq.Workplane:
    """The centres' hull grown by ``radius`` (:func:`magfab.outline.segments`), from z0 up to z1."""
    import cadquery as cq

    h = outline.hull(centres)
    wp = cq.Workplane("XY", origin=(0, 0, z0))
    if len(h) == 1:
        return wp.center(*h[0]).circle(radius).extrude(z1 - z0)
    chain = outline.segments(h, radius)
    wp = wp.moveTo(*chain[0][0])
    for seg in chain:
        wp = wp.lineTo(*seg[1]) if len(seg) == 2 else wp.threePointArc(seg[1], seg[2])
    return wp.close().extrude(z1 - z0)


def envelope_solid(design: Design, below_mm: float = 0.0) -> cq.Workplane:
    """The elastomer's outer shape without the pocket: what a mould cavity is (``below_mm``: its base extended
    that far below z = 0, for a cutting tool)."""
    profile = design.envelope_profile
    if design.continuous:
        return _skin_envelope(design, below_mm)
    if below_mm > 0.0:
        profile = [(r, -below_mm if i < 2 else z) for i, (r, z) in enumerate(profile)]
    return revolve_profile(profile, arc_at=3 if len(profile) == 5 else None)


def _skin_envelope(design: Design, below_mm: float) -> cq.Workplane:
    """A continuous skin's outer shape: the slab and a dome over each taxel (fused on the slab's top face)."""
    centres = list(design.part_centres_mm)
    R, hb = design.elastomer_radius_mm, design.base_height_mm
    skin = outline_prism(centres, R, -below_mm, hb)
    if len(design.envelope_profile) == 5:
        dome = revolve_profile([(0.0, hb), *design.envelope_profile[2:]], arc_at=2)
        for x, y in centres:
            skin = skin.union(dome.translate((x, y, 0.0)))
    return skin.clean()


def core_solid(design: Design, extend_below_mm: float = 0.0) -> cq.Workplane:
    """Pocket + funnel + insertion channel, optionally extended below the base (to fuse into a lid)."""
    profile = list(design.core_profile)
    if extend_below_mm > 0.0:
        r0 = profile[1][0]
        profile = [(0.0, -extend_below_mm), (r0, -extend_below_mm), *profile[1:]]
    return revolve_profile(profile)


def elastomer_solid(design: Design) -> cq.Workplane:
    """The cast part: envelope less the core (less each taxel's core, for a continuous skin)."""
    part = envelope_solid(design)
    core = core_solid(design)
    for x, y in design.part_centres_mm:
        part = part.cut(core.translate((x, y, 0.0)) if (x, y) != (0.0, 0.0) else core)
    return part
