"""Exporters, kept apart from modelling: STEP bytes, tessellated meshes, binary STL bytes.

Everything returns bytes or values and is deterministic: the STEP header's timestamp is pinned and its
name set to the part's, STL headers carry only the part's name.
"""

from __future__ import annotations

import math
import re
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import cadquery as cq
    import trimesh

# Imported lazily, inside the functions that use them, for speed: CadQuery, trimesh and OCP take a
# noticeable time to import, and importing this module should not.

__all__ = ["step_bytes", "tessellate", "stl_bytes", "FIXED_STEP_TIME"]

#: STEP requires a time stamp; ours is fixed so the same spec gives the same bytes.
FIXED_STEP_TIME = "2000-01-01T00:00:00"
_FILE_NAME = re.compile(rb"FILE_NAME\('[^']*','[^']*'")
# The kernel names the product with a per-process counter ("... translator 7.9 5"): name it after the part.
_PRODUCT = re.compile(rb"PRODUCT\('[^']*',\s*'[^']*'")


def step_bytes(solid: cq.Workplane, name: str) -> bytes:
    """The solid as an AP214 STEP file whose header names the part and carries a fixed time stamp."""
    import cadquery as cq

    if not re.fullmatch(r"[A-Za-z0-9_.-]+", name):
        raise ValueError(f"STEP part name must be plain ASCII letters, digits, '.', '_' or '-'; got {name!r}")
    with tempfile.TemporaryDirectory(prefix="magfab-step-") as tmp:
        path = Path(tmp) / "part.step"
        cq.exporters.export(solid, str(path), exportType="STEP")
        data = path.read_bytes()
    data, n_file = _FILE_NAME.subn(f"FILE_NAME('{name}','{FIXED_STEP_TIME}'".encode(), data, count=1)
    data, n_product = _PRODUCT.subn(f"PRODUCT('{name}','{name}'".encode(), data, count=1)
    if (n_file, n_product) != (1, 1):
        raise RuntimeError("unexpected STEP from the CAD kernel: FILE_NAME or PRODUCT not found")
    return data


def tessellate(solid: cq.Workplane, tolerance_mm: float, angular_tolerance_deg: float) -> trimesh.Trimesh:
    """Triangulate a solid within ``tolerance_mm`` of its exact surface, merging shared vertices.

    The deflection is absolute (mm). CadQuery's own ``tessellate`` asks the kernel for a deflection
    *relative* to each edge's size, which on a 12 mm cavity let facets stray ~2x further than asked.
    """
    import cadquery as cq
    import trimesh
    from OCP.BRep import BRep_Tool
    from OCP.BRepMesh import BRepMesh_IncrementalMesh
    from OCP.TopAbs import TopAbs_FACE, TopAbs_REVERSED
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopLoc import TopLoc_Location
    from OCP.TopoDS import TopoDS

    value = solid.val()
    if not isinstance(value, cq.Shape):  # val() may be any CadQuery object; only a shape can be meshed
        raise TypeError(f"tessellate needs a solid, not a workplane holding a {type(value).__name__}")
    shape = value.wrapped
    BRepMesh_IncrementalMesh(shape, tolerance_mm, False, math.radians(angular_tolerance_deg), False)
    vertices: list[np.ndarray] = []
    faces: list[np.ndarray] = []
    offset = 0
    explorer = TopExp_Explorer(shape, TopAbs_FACE)
    while explorer.More():
        face = TopoDS.Face_s(explorer.Current())
        explorer.Next()
        loc = TopLoc_Location()
        tri = BRep_Tool.Triangulation_s(face, loc)
        if tri is None:
            raise RuntimeError("the CAD kernel left a face untriangulated")
        trsf = loc.Transformation()
        pts = [tri.Node(i).Transformed(trsf) for i in range(1, tri.NbNodes() + 1)]
        vertices.append(np.array([(p.X(), p.Y(), p.Z()) for p in pts], dtype=np.float64))
        idx = np.array([tri.Triangle(i).Get() for i in range(1, tri.NbTriangles() + 1)], dtype=np.int64) - 1
        if face.Orientation() == TopAbs_REVERSED:
            idx = idx[:, ::-1]
        faces.append(idx + offset)
        offset += len(pts)
    mesh = trimesh.Trimesh(vertices=np.vstack(vertices), faces=np.vstack(faces), process=True, validate=False)
    # Revolved surfaces close at a pole where the kernel emits zero-area triangles; after merging their
    # repeated vertex they are edges, not faces, and would break the watertight check and the slicer.
    mesh.update_faces(mesh.nondegenerate_faces(height=1e-9))
    mesh.remove_unreferenced_vertices()
    return mesh


def stl_bytes(mesh: trimesh.Trimesh, name: str) -> bytes:
    """Binary STL: 80-byte header with the part's name, then one 50-byte record per triangle."""
    header = f"magfab {name}".encode("ascii", "replace")[:80].ljust(80, b" ")
    tri = mesh.triangles.astype("<f4")
    normals = mesh.face_normals.astype("<f4")
    record = np.zeros(len(tri), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    record["n"] = normals
    record["v"] = tri
    return header + np.uint32(len(tri)).astype("<u4").tobytes() + record.tobytes()
