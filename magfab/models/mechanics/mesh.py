"""The triangulation of the body's (r, z) profile for the axisymmetric FE.

Deterministic: boundary points every <= h along the outline, an equilateral lattice inside, Delaunay, a few
Laplacian smoothing sweeps; refinement by scikit-fem. Every vertex carries a bitmask of the boundaries it lies
on (axis, bonded base, outer surface, magnet), which the FE turns into constraints. Meshes are cached (the studies
clear the caches for cold timings).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .body import FLAT, Body, MechanicsError

__all__ = ["BUILD_MESH_FRACTION", "mesh_size"]

#: Default FE mesh size for a build, as a fraction of the elastomer radius (0.5 mm for MagOne).
BUILD_MESH_FRACTION = 1.0 / 12.0


def mesh_size(body: Body, mesh_mm: float | None) -> float:
    """The FE element size in mm: ``mesh_mm``, or the build default ``radius * BUILD_MESH_FRACTION``."""
    return float(mesh_mm) if mesh_mm is not None else body.radius_mm * BUILD_MESH_FRACTION


_AXIS, _BASE, _OUTER, _MAGNET = 1, 2, 4, 8


@dataclass(frozen=True, eq=False)
class _Mesh:
    """A triangulation of the body's (r, z) profile in mm, counter-clockwise, with boundary tags per vertex."""

    p: np.ndarray  # (2, n_vertices)
    t: np.ndarray  # (3, n_triangles)
    tags: np.ndarray  # (n_vertices,) bitmask of _AXIS, _BASE, _OUTER, _MAGNET
    h: float
    min_angle_deg: float


def _inside(body: Body, r: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Strictly inside the silicone (outside the magnet)."""
    R, hb, H = body.radius_mm, body.base_height_mm, body.height_mm
    if body.tip == FLAT:
        outer = (r > 0) & (r < R) & (z > 0) & (z < H)
    else:
        outer = (r > 0) & (z > 0) & (((r < R) & (z <= hb)) | ((z > hb) & (r * r + (z - hb) ** 2 < R * R)))
    if body.has_magnet:
        outer &= ~((r < body.magnet_radius_mm) & (z > body.magnet_z_mm) & (z < body.magnet_top_mm))
    return outer


def _intervals_minus(a: float, b: float, c: float, d: float) -> list[tuple[float, float]]:
    """[a, b] without the open interval (c, d)."""
    if d <= a or c >= b:
        return [(a, b)]
    out = []
    if c > a:
        out.append((a, c))
    if d < b:
        out.append((d, b))
    return out


def _boundary_pieces(body: Body) -> list[tuple[str, tuple, int]]:
    """Boundary pieces of the silicone profile: ("seg", (r0, z0, r1, z1), tag) or
    ("arc", (r_centre, z_centre, radius, angle0, angle1), tag)."""
    R, hb, H = body.radius_mm, body.base_height_mm, body.height_mm
    rm, zm, zt = body.magnet_radius_mm, body.magnet_z_mm, body.magnet_top_mm
    mag = body.has_magnet
    pieces: list[tuple[str, tuple, int]] = []
    for z0, z1 in _intervals_minus(0.0, H, zm, zt) if mag else [(0.0, H)]:
        pieces.append(("seg", (0.0, z0, 0.0, z1), _AXIS))
    pieces.append(("seg", (0.0, 0.0, R, 0.0), _BASE))
    side_cut = mag and rm >= R * (1 - 1e-12)
    for z0, z1 in _intervals_minus(0.0, hb, zm, zt) if side_cut else [(0.0, hb)]:
        pieces.append(("seg", (R, z0, R, z1), _OUTER))
    if body.tip == FLAT:
        top_cut = mag and zt >= H * (1 - 1e-12)
        for r0, r1 in _intervals_minus(0.0, R, 0.0, rm) if top_cut else [(0.0, R)]:
            pieces.append(("seg", (r1, H, r0, H), _OUTER))
    else:
        pieces.append(("arc", (0.0, hb, R, 0.0, 0.5 * math.pi), _OUTER))
    if mag:
        pieces.append(("seg", (0.0, zm, rm, zm), _MAGNET))
        pieces.append(("seg", (rm, zm, rm, zt), _MAGNET))
        pieces.append(("seg", (rm, zt, 0.0, zt), _MAGNET))
    return pieces


def _sample_piece(kind: str, geo: tuple, h: float) -> np.ndarray:
    """Points (2, n) along one boundary piece, both ends included, spacing at most h."""
    if kind == "seg":
        r0, z0, r1, z1 = geo
        n = max(1, math.ceil(math.hypot(r1 - r0, z1 - z0) / h - 1e-9))
        s = np.linspace(0.0, 1.0, n + 1)
        return np.vstack([r0 + s * (r1 - r0), z0 + s * (z1 - z0)])
    rc, zc, rad, a0, a1 = geo
    n = max(2, math.ceil(rad * (a1 - a0) / h - 1e-9))
    a = np.linspace(a0, a1, n + 1)
    pts = np.vstack([rc + rad * np.cos(a), zc + rad * np.sin(a)])
    for i, ang in ((0, a0), (-1, a1)):  # exact ends, so they merge with the neighbouring pieces
        pts[:, i] = (rc + rad * round(math.cos(ang)), zc + rad * round(math.sin(ang)))
    return pts


def _lattice_mesh(body: Body, h: float) -> _Mesh:
    """Deterministic mesh of size ~h: boundary points every <= h, an equilateral lattice inside (kept >= h/2 from
    the boundary), Delaunay, a few Laplacian smoothing sweeps of the interior points, and checks."""
    from scipy.spatial import Delaunay, cKDTree

    scale = max(body.radius_mm, body.height_mm)
    key = 1e-9 * scale
    merged: dict[tuple[int, int], list] = {}
    dense = []
    for kind, geo, tag in _boundary_pieces(body):
        for r, z in _sample_piece(kind, geo, h).T:
            k = (round(r / key), round(z / key))
            if k in merged:
                merged[k][2] |= tag
            else:
                merged[k] = [r, z, tag]
        dense.append(_sample_piece(kind, geo, h / 8.0))
    bnd = np.array([(v[0], v[1]) for v in merged.values()]).T
    btag = np.array([v[2] for v in merged.values()], dtype=np.int64)

    dz = h * math.sqrt(3.0) / 2.0
    rows = np.arange(1, int(body.height_mm / dz) + 2)
    cols = np.arange(0, int(body.radius_mm / h) + 2)
    rr = (cols[None, :] + 0.5 * (rows[:, None] % 2)) * h
    zz = np.broadcast_to(rows[:, None] * dz, rr.shape)
    r, z = rr.ravel(), zz.ravel()
    keep = _inside(body, r, z)
    r, z = r[keep], z[keep]
    dist, _ = cKDTree(np.hstack(dense).T).query(np.vstack([r, z]).T)
    keep = dist > 0.5 * h
    p = np.hstack([bnd, np.vstack([r[keep], z[keep]])])
    tags = np.concatenate([btag, np.zeros(int(keep.sum()), dtype=np.int64)])

    t = Delaunay(p.T, qhull_options="Qbb Qc Qz Q12").simplices.T
    t = _orient(p, t)
    cr, cz = p[:, t].mean(axis=1)
    area = _areas(p, t)
    t = t[:, _inside(body, cr, cz) & (area > 1e-10 * h * h)]
    t = _smooth(p, t, tags == 0, sweeps=4)
    return _finish(body, p, t, h)


def _areas(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    a, b, c = p[:, t[0]], p[:, t[1]], p[:, t[2]]
    return 0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def _orient(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    t = t.copy()
    neg = _areas(p, t) < 0
    t[1, neg], t[2, neg] = t[2, neg].copy(), t[1, neg].copy()
    return t


def _smooth(p: np.ndarray, t: np.ndarray, movable: np.ndarray, sweeps: int) -> np.ndarray:
    """Laplacian smoothing of the movable points in place (kept only while every triangle stays positive)."""
    n = p.shape[1]
    edges = np.hstack([t[[0, 1]], t[[1, 2]], t[[2, 0]]])
    edges = np.unique(np.sort(edges, axis=0), axis=1)
    deg = np.bincount(edges.ravel(), minlength=n).astype(float)
    used = deg > 0
    for _ in range(sweeps):
        acc = np.zeros_like(p)
        for a, b in ((0, 1), (1, 0)):
            np.add.at(acc, (slice(None), edges[a]), p[:, edges[b]])
        new = p.copy()
        m = movable & used
        new[:, m] = acc[:, m] / deg[m]
        if np.all(_areas(new, t) > 0):
            p[:, :] = new
        else:
            break
    return t


def _finish(body: Body, p: np.ndarray, t: np.ndarray, h: float) -> _Mesh:
    """Drop unused points, project boundary points onto the cap, tag the boundary geometrically, and check."""
    used = np.zeros(p.shape[1], dtype=bool)
    used[t.ravel()] = True
    renum = np.cumsum(used) - 1
    p, t = p[:, used].copy(), renum[t]
    edges = np.sort(np.hstack([t[[0, 1]], t[[1, 2]], t[[2, 0]]]), axis=0)
    uniq, counts = np.unique(edges, axis=1, return_counts=True)
    bedges = uniq[:, counts == 1]
    on_boundary = np.zeros(p.shape[1], dtype=bool)
    on_boundary[bedges.ravel()] = True
    tags = _tag(body, p, on_boundary)
    if np.any(on_boundary & (tags == 0)) or bedges.shape[1] != int(on_boundary.sum()):
        raise MechanicsError(f"fe: mesh generation failed for mesh_mm = {h:g} (the triangulation does not follow "
                             "the body's outline); try another mesh size")
    if np.any(_areas(p, t) <= 0):
        raise MechanicsError(f"fe: mesh generation produced an inverted triangle for mesh_mm = {h:g}")
    return _Mesh(p, t, tags, h, _min_angle(p, t))


def _tag(body: Body, p: np.ndarray, on_boundary: np.ndarray) -> np.ndarray:
    """Boundary tags from geometry; boundary points near the cap are projected onto the sphere first."""
    r, z = p
    R, hb, H = body.radius_mm, body.base_height_mm, body.height_mm
    tol = 1e-7 * max(R, H)
    tags = np.zeros(p.shape[1], dtype=np.int64)
    tags[on_boundary & (r < tol)] |= _AXIS
    tags[on_boundary & (z < tol)] |= _BASE
    if body.has_magnet:
        rm, zm, zt = body.magnet_radius_mm, body.magnet_z_mm, body.magnet_top_mm
        on_side = (np.abs(r - rm) < tol) & (z > zm - tol) & (z < zt + tol)
        on_face = ((np.abs(z - zm) < tol) | (np.abs(z - zt) < tol)) & (r < rm + tol)
        tags[on_boundary & (on_side | on_face)] |= _MAGNET
    outer = on_boundary & (np.abs(r - R) < tol) & (z < hb + tol)
    if body.tip == FLAT:
        outer |= on_boundary & (np.abs(z - H) < tol)
    else:
        cap = on_boundary & (z > hb - tol) & (tags & (_AXIS | _MAGNET) == 0) | (
            on_boundary & (r < tol) & (z > H - tol))
        rho = np.hypot(r[cap], z[cap] - hb)
        p[0, cap] = r[cap] * R / rho  # chord midpoints of a refined mesh move onto the sphere
        p[1, cap] = hb + (z[cap] - hb) * R / rho
        outer |= cap
    tags[outer] |= _OUTER
    return tags


def _min_angle(p: np.ndarray, t: np.ndarray) -> float:
    best = 180.0
    for i in range(3):
        a, b, c = p[:, t[i]], p[:, t[(i + 1) % 3]], p[:, t[(i + 2) % 3]]
        u, v = b - a, c - a
        cos = np.sum(u * v, axis=0) / (np.linalg.norm(u, axis=0) * np.linalg.norm(v, axis=0))
        best = min(best, float(np.degrees(np.arccos(np.clip(cos, -1, 1))).min()))
    return best


@lru_cache(maxsize=16)
def _body_mesh(body: Body, h: float, refine: int = 0, refine_near_apex_mm: float = 0.0) -> _Mesh:
    """The mesh of size h, then ``refine`` rounds of refinement (uniform, or of the triangles within
    ``refine_near_apex_mm`` of the top of the axis), new boundary points moved onto the cap.

    Meshes are made for the body scaled to unit radius and then scaled back, so similar bodies get similar meshes
    (exactly, for a scale factor that is a power of two): what the scaling-invariance test relies on."""
    if not (math.isfinite(h) and h > 0.0):
        raise MechanicsError(f"Input mesh_mm must be a finite size > 0; instead received {h!r}")
    if h > 0.5 * min(body.radius_mm, body.height_mm):
        raise MechanicsError(f"Input mesh_mm must be at most half the body's radius and height; "
                             f"instead received {h!r}")
    unit = body.radius_mm
    m = _unit_mesh(body.scaled(1.0 / unit), h / unit, refine, refine_near_apex_mm / unit)
    return _Mesh(m.p * unit, m.t, m.tags, m.h * unit, m.min_angle_deg)


@lru_cache(maxsize=16)
def _unit_mesh(body: Body, h: float, refine: int, refine_near: float) -> _Mesh:
    """_body_mesh for a body of unit radius; ``h`` of the result is the size away from any local refinement."""
    mesh = _lattice_mesh(body, h)
    from skfem import MeshTri

    for _ in range(refine):
        m = MeshTri(mesh.p, np.ascontiguousarray(mesh.t), sort_t=False)
        if refine_near > 0.0:
            c = m.p[:, m.t].mean(axis=1)
            m = m.refined(np.nonzero(np.hypot(c[0], c[1] - body.height_mm) < refine_near)[0])
        else:
            m = m.refined()
        p = np.array(m.p, dtype=float)
        mesh = _finish(body, p, _orient(p, np.array(m.t)), mesh.h if refine_near > 0.0 else mesh.h / 2.0)
    return mesh
