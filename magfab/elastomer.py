"""The elastomer solid: a cylindrical base with a hemispherical or flat tip, and the magnet pocket.

Built in the elastomer frame of :mod:`magfab.design` (base on z = 0, axis on z) by revolving the
design's (r, z) profiles, so the solid and the closed-form volumes come from the same numbers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .design import Design

if TYPE_CHECKING:
    import cadquery as cq

__all__ = ["revolve_profile", "envelope_solid", "core_solid", "elastomer_solid"]


def revolve_profile(profile: list[tuple[float, float]], arc_at: int | None = None) -> "cq.Workplane":
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


def envelope_solid(design: Design) -> "cq.Workplane":
    """The elastomer's outer shape without the pocket: what a mould cavity is."""
    profile = design.envelope_profile
    return revolve_profile(profile, arc_at=3 if len(profile) == 5 else None)


def core_solid(design: Design, extend_below_mm: float = 0.0) -> "cq.Workplane":
    """Pocket + funnel + insertion channel, optionally extended below the base (to fuse into a lid)."""
    profile = list(design.core_profile)
    if extend_below_mm > 0.0:
        r0 = profile[1][0]
        profile = [(0.0, -extend_below_mm), (r0, -extend_below_mm)] + profile[1:]
    return revolve_profile(profile)


def elastomer_solid(design: Design) -> "cq.Workplane":
    """The cast part: envelope less the core."""
    return envelope_solid(design).cut(core_solid(design))
