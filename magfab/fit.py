"""How the printed mould closes on its cavity, measured on the exported meshes with manifold3d.

The STL files are what a user prints, so the fit is checked on them, not on the exact solids: the cup and
the lid are put into their casting pose (the lid turned over onto the cup's pins), and mesh booleans
measure

* interference: the volume the cup and the closed lid share (a core too fat for its cavity, a pin
  that hits the lid);
* the cavity: the space the closed mould leaves in each cavity, compared with the cast part
  (``elastomer.stl`` put where it is cast, upside down): the part outside the cavity (where it would
  overlap the mould) and the cavity outside the part (silicone the design does not expect);
* the walls: the thinnest cup wall between a cavity and the outside, and between neighbouring cavities
  (manifold3d's ``min_gap``), against the printer's minimum.

Mesh booleans on two independently tessellated surfaces agree only to about (area x tessellation
tolerance), so every comparison uses that bound. ``bench/fit.py`` measures the same checks done with
OCCT booleans on the exact solids, for time and result.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from . import outline
from .design import Design

if TYPE_CHECKING:
    import manifold3d
    import trimesh

# manifold3d is imported lazily, inside the functions that use it: an optional mesh-boolean library only the CAD branch
# needs.

__all__ = ["MouldFit", "mould_fit", "to_manifold", "lid_to_cast_pose", "part_to_cavity"]


@dataclass(frozen=True)
class MouldFit:
    """Volumes in mm^3, lengths in mm, one entry per cavity where a tuple."""

    cup_lid_interference_mm3: float
    cavity_volume_mm3: tuple[float, ...]
    part_volume_mm3: float
    part_outside_mm3: tuple[float, ...]  # cast part outside cavity i: it would overlap the mould there
    cavity_outside_mm3: tuple[float, ...]  # cavity i outside the cast part: silicone where none is designed
    allowed_mm3: float  # what two tessellations of one surface may disagree by
    cup_wall_mm: float  # thinnest wall between a cavity and the outside (sides and bottom)
    cavity_web_mm: float | None  # thinnest wall between neighbouring cavities (None for one cavity)


def to_manifold(mesh: trimesh.Trimesh, matrix: np.ndarray | None = None) -> manifold3d.Manifold:
    """A trimesh (optionally moved by a 4x4 ``matrix``) as a manifold3d solid; raises if it is not a manifold."""
    import manifold3d

    verts = np.asarray(mesh.vertices, dtype=np.float64)
    if matrix is not None:
        verts = verts @ matrix[:3, :3].T + matrix[:3, 3]
    solid = manifold3d.Manifold(manifold3d.Mesh(vert_properties=verts.astype(np.float32),
                                                tri_verts=np.asarray(mesh.faces, dtype=np.uint32)))
    if solid.status() != manifold3d.Error.NoError:
        raise ValueError(f"not a manifold mesh: {solid.status()}")
    return solid


def lid_to_cast_pose(design: Design) -> np.ndarray:
    """4x4 matrix from the lid's print pose to its place on the cup (undoes mould.lid_solid's turn-over)."""
    top = design.cup_size_mm[2] + design.lid_thickness_mm
    return np.array([[1, 0, 0, 0], [0, -1, 0, 0], [0, 0, -1, top], [0, 0, 0, 1]], dtype=float)


def part_to_cavity(design: Design, x_mm: float) -> np.ndarray:
    """4x4 matrix from the elastomer frame (base at z = 0) to the part as cast in the cavity at ``x_mm``."""
    h = design.cup_size_mm[2]
    return np.array([[1, 0, 0, x_mm], [0, -1, 0, 0], [0, 0, -1, h], [0, 0, 0, 1]], dtype=float)


#: The wall check's cylinder stops this far inside the cup's outer faces: a boolean against a coplanar
#: face leaves a zero-thickness sliver there, which would read as a thin wall.
TOP_GAP_MM = 0.01


def _region(design: Design, x_mm: float, radius_mm: float, bottom_mm: float, top_gap_mm: float = 0.0):
    """A cylinder round cavity ``x_mm`` from ``bottom_mm`` up to ``top_gap_mm`` below the cup's top face (for a
    continuous skin, the prism of its taxels' hull grown by ``radius_mm``)."""
    import manifold3d

    top = design.cup_size_mm[2] - top_gap_mm
    if design.continuous:
        h = outline.hull([(x, -y) for x, y in design.part_centres_mm])
        section = manifold3d.CrossSection([outline.polygon(h, radius_mm)])
        return manifold3d.Manifold.extrude(section, top - bottom_mm).translate((x_mm, 0.0, bottom_mm))
    return manifold3d.Manifold.cylinder(top - bottom_mm, radius_mm, radius_mm, 128).translate((x_mm, 0.0, bottom_mm))


def mould_fit(design: Design, meshes: Mapping[str, trimesh.Trimesh], tolerance_mm: float) -> MouldFit:
    """Measure the closed mould from the exported meshes (``mould_cup``, ``mould_lid``, ``elastomer``)."""
    import manifold3d

    cup = to_manifold(meshes["mould_cup"])
    lid = to_manifold(meshes["mould_lid"], lid_to_cast_pose(design))
    part_mesh = meshes["elastomer"]
    allowed = 2.0 * float(part_mesh.area) * tolerance_mm
    mould = cup + lid
    lx, ly, h = design.cup_size_mm
    R, wall = design.elastomer_radius_mm, design.wall_mm
    bottom = h - design.elastomer_height_mm - 0.5 * wall
    cavities, part_out, cavity_out, hollows = [], [], [], []
    for x in design.cavity_centres_x_mm:
        part = to_manifold(part_mesh, part_to_cavity(design, x))
        cavity = _region(design, x, R + 0.5 * wall, bottom) - mould
        cavities.append(cavity.volume())
        # part - cavity holds any overlap of the part with the mould, so no separate intersection is needed
        part_out.append((part - cavity).volume())
        cavity_out.append((cavity - part).volume())
        # Reaching almost to the cup's outer faces, so an off-centre or oversized cavity is seen whole.
        hollows.append(_region(design, x, R + wall - TOP_GAP_MM, TOP_GAP_MM, TOP_GAP_MM) - cup)
    # The outside of the cup below its top face: a frame round the cup's box and a slab under it.
    big = manifold3d.Manifold.cube((lx + 20.0, ly + 20.0, h + 10.0), True).translate((0.0, 0.0, (h - 10.0) / 2.0))
    outside = big - manifold3d.Manifold.cube((lx, ly, h + 10.0), True).translate((0.0, 0.0, (h + 10.0) / 2.0))
    search = 4.0 * max(wall, 1.0)
    wall_gap = min(hollow.min_gap(outside, search) for hollow in hollows)
    web = min((hollows[i].min_gap(hollows[i + 1], search) for i in range(len(hollows) - 1)), default=None)
    return MouldFit(
        cup_lid_interference_mm3=(cup ^ lid).volume(),
        cavity_volume_mm3=tuple(cavities),
        part_volume_mm3=float(part_mesh.volume),
        part_outside_mm3=tuple(part_out),
        cavity_outside_mm3=tuple(cavity_out),
        allowed_mm3=allowed,
        cup_wall_mm=float(wall_gap),
        cavity_web_mm=None if web is None else float(web),
    )
