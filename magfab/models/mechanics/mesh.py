"""The triangulation of the body's (r, z) profile for the axisymmetric FE.

Deterministic: boundary points spaced by a size function (the mesh size ``h``, graded down at the magnet's
rounded edges), then Triangle's quality Delaunay mesher (:func:`_graded_mesh`); uniform refinement by scikit-fem,
new boundary points moved onto the cap and the rounded edges. Every vertex carries a bitmask of the boundaries it lies
on (axis, bonded base, outer surface, magnet, the wall of a void under the magnet), which the FE turns into
constraints. Optionally the silicone inside a void's wall is left out (:func:`channel_wall`: the design's open
insertion channel and funnel). Meshes are cached (the studies
clear the caches for cold timings).
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .body import FLAT, Body, MechanicsError

# Imported lazily, inside the functions that use them, for speed: triangle and scikit-fem take a
# noticeable time to import, and importing this module should not.

__all__ = ["BUILD_MESH_FRACTION", "mesh_size", "channel_wall", "Wall"]

#: Default FE mesh size for a build, as a fraction of the elastomer radius (0.5 mm for MagOne).
BUILD_MESH_FRACTION = 1.0 / 12.0


def mesh_size(body: Body, mesh_mm: float | None) -> float:
    """The FE element size in mm: ``mesh_mm``, or the build default ``radius * BUILD_MESH_FRACTION``."""
    return float(mesh_mm) if mesh_mm is not None else body.radius_mm * BUILD_MESH_FRACTION


_AXIS, _BASE, _OUTER, _MAGNET, _VOID = 1, 2, 4, 8, 16

#: A void in the silicone under the magnet (the design's insertion channel and funnel left open): its wall, the
#: (r, z) polyline in mm from the base (z = 0) up to the magnet's lower face; the void is between the axis and the
#: wall. A tuple of points, so it can key the mesh cache.
Wall = tuple[tuple[float, float], ...]


@dataclass(frozen=True, eq=False)
class _Mesh:
    """A triangulation of the body's (r, z) profile in mm, counter-clockwise, with boundary tags per vertex."""

    p: np.ndarray  # (2, n_vertices)
    t: np.ndarray  # (3, n_triangles)
    tags: np.ndarray  # (n_vertices,) bitmask of _AXIS, _BASE, _OUTER, _MAGNET, _VOID
    h: float
    min_angle_deg: float


#: Element size along the magnet's rounded edge, as a fraction of the edge radius (a quarter circle in ~8 arcs).
EDGE_SIZE_FRACTION = 0.07
#: Growth of the element size with distance from the rounded edge (size = edge size + GRADING * distance, capped
#: at the mesh size): a gentle 1:4 slope keeps the minimum angle above Triangle's 30-degree quality bound.
GRADING = 0.25
#: Minimum angle (degrees) asked of Triangle's quality mesher.
MIN_ANGLE_DEG = 30.0


def _magnet_distance(body: Body, r: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Signed distance (mm) from (r, z) to the magnet's rounded-rectangle profile (negative inside)."""
    rm, hm, re = body.magnet_radius_mm, body.magnet_height_mm, body.magnet_edge_radius_mm
    zc = body.magnet_z_mm + 0.5 * hm
    qr, qz = np.abs(r) - (rm - re), np.abs(z - zc) - (0.5 * hm - re)
    outside = np.hypot(np.maximum(qr, 0.0), np.maximum(qz, 0.0))
    return outside + np.minimum(np.maximum(qr, qz), 0.0) - re


def _magnet_normals(body: Body, r: np.ndarray, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Outward normals (2, n) of the magnet's rounded-rectangle profile at points (r, z) on it, and a mask of the
    points that have one (not the corners of a sharp-edged magnet)."""
    rm, hm, re = body.magnet_radius_mm, body.magnet_height_mm, body.magnet_edge_radius_mm
    zc = body.magnet_z_mm + 0.5 * hm
    eps = 1e-9 * max(body.radius_mm, body.height_mm)
    sgn = np.where(z >= zc, 1.0, -1.0)
    qr, qz = r - (rm - re), np.abs(z - zc) - (0.5 * hm - re)
    arc = (qr > eps) & (qz > eps)
    side = ~arc & (qr >= qz)
    length = np.where(arc, np.hypot(qr, qz), 1.0)
    nr = np.where(arc, qr / length, np.where(side, 1.0, 0.0))
    nz = np.where(arc, sgn * qz / length, np.where(side, 0.0, sgn))
    return np.vstack([nr, nz]), ~((np.abs(qr) < eps) & (np.abs(qz) < eps))


def _edge_centres(body: Body) -> np.ndarray:
    """(2, k) centres of the magnet's rounded edges (k = 2), or (2, 0) for a sharp-edged or no magnet."""
    re = body.magnet_edge_radius_mm
    if not body.has_magnet or re <= 0.0:
        return np.zeros((2, 0))
    rc = body.magnet_radius_mm - re
    return np.array([[rc, rc], [body.magnet_z_mm + re, body.magnet_top_mm - re]])


def _size(body: Body, h: float, r: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The wanted element size (mm) at (r, z): ``h``, graded down to the edge size near the rounded edges."""
    c = _edge_centres(body)
    size = np.full(np.shape(r), float(h))
    if c.shape[1]:
        re = body.magnet_edge_radius_mm
        he = min(h, EDGE_SIZE_FRACTION * re)
        for rc, zc in c.T:
            dist = np.maximum(np.hypot(r - rc, z - zc) - re, 0.0)
            size = np.minimum(size, he + GRADING * dist)
    return size


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


def _boundary_pieces(body: Body, void: Wall | None = None) -> list[tuple[str, tuple, int]]:
    """Boundary pieces of the silicone profile: ("seg", (r0, z0, r1, z1), tag) or
    ("arc", (r_centre, z_centre, radius, angle0, angle1), tag). With a ``void`` (:data:`Wall`), the silicone between
    the axis and the wall, below the magnet, is taken away: the axis below the magnet and the base inside the wall
    are no boundary, the wall is a free surface."""
    R, hb, H = body.radius_mm, body.base_height_mm, body.height_mm
    rm, zm, zt = body.magnet_radius_mm, body.magnet_z_mm, body.magnet_top_mm
    mag = body.has_magnet
    pieces: list[tuple[str, tuple, int]] = []
    for z0, z1 in _intervals_minus(0.0, H, 0.0 if void else zm, zt) if mag else [(0.0, H)]:
        pieces.append(("seg", (0.0, z0, 0.0, z1), _AXIS))
    pieces.append(("seg", (void[0][0] if void else 0.0, 0.0, R, 0.0), _BASE))
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
        re = body.magnet_edge_radius_mm
        r_open = void[-1][0] if void else 0.0  # the magnet's lower face is bare out to the wall
        if r_open < rm - re:
            pieces.append(("seg", (r_open, zm, rm - re, zm), _MAGNET))
        pieces.append(("seg", (rm, zm + re, rm, zt - re), _MAGNET))
        pieces.append(("seg", (rm - re, zt, 0.0, zt), _MAGNET))
        if re > 0.0:
            pieces.append(("arc", (rm - re, zm + re, re, -0.5 * math.pi, 0.0), _MAGNET))
            pieces.append(("arc", (rm - re, zt - re, re, 0.0, 0.5 * math.pi), _MAGNET))
    for (r0, z0), (r1, z1) in itertools.pairwise(void) if void else ():
        pieces.append(("seg", (r0, z0, r1, z1), _VOID))
    return pieces


def channel_wall(body: Body, core_profile: list[tuple[float, float]]) -> Wall:
    """The :data:`Wall` of the design's insertion channel and funnel left open: ``core_profile`` is the design's
    (:attr:`magfab.design.Design.core_profile`, elastomer frame: (0, 0), up the channel and funnel to the pocket,
    along its roof back to the axis), cut at the magnet's lower face and kept inside the start of its rounded edge
    (the magnet rests against the pocket's roof; the 0.05 mm clearance under and around it is left out)."""
    pts = np.array(core_profile[1:-1], dtype=float)  # the wall: base, channel, funnel, pocket side up to the roof
    zm, rc = body.magnet_z_mm, body.magnet_radius_mm - body.magnet_edge_radius_mm
    zs = [z for z in pts[:, 1] if z < zm] + [zm]
    for (r0, z0), (r1, z1) in itertools.pairwise(pts):
        if (r0 - rc) * (r1 - rc) < 0.0:  # the wall crosses the edge's start radius: a corner of the clipped wall
            zs.append(z0 + (rc - r0) * (z1 - z0) / (r1 - r0))
    wall: list[tuple[float, float]] = []
    for z in sorted(z for z in zs if z <= zm):
        point = (min(float(np.interp(z, pts[:, 1], pts[:, 0])), rc), float(z))
        if wall and max(abs(point[0] - wall[-1][0]), abs(point[1] - wall[-1][1])) < 1e-9 * zm:
            continue
        if len(wall) >= 2 and _collinear(wall[-2], wall[-1], point, 1e-9 * zm):
            wall[-1] = point
        else:
            wall.append(point)
    return tuple(wall)


def _collinear(a: tuple[float, float], b: tuple[float, float], c: tuple[float, float], tol: float) -> bool:
    """Whether b lies within ``tol`` (mm) of the line through a and c."""
    cross = (c[0] - a[0]) * (b[1] - a[1]) - (c[1] - a[1]) * (b[0] - a[0])
    return abs(cross) <= tol * math.hypot(c[0] - a[0], c[1] - a[1])


def check_void(body: Body, void: Wall | None) -> Wall | None:
    """``void`` as a tuple of (r, z) float pairs, checked: from the base (z = 0, 0 < r < radius) up to the magnet's
    lower face, z non-decreasing, 0 < r <= the start of the magnet's rounded edge at the top. None stays None."""
    if void is None:
        return None
    w = tuple((float(r), float(z)) for r, z in void)
    rz = np.array(w, dtype=float).reshape(-1, 2)
    tol = 1e-9 * max(body.radius_mm, body.height_mm)
    ok = (body.has_magnet and not body.magnet_is_top_plate and rz.shape[0] >= 2 and np.all(np.isfinite(rz))
          and abs(rz[0, 1]) <= tol and abs(rz[-1, 1] - body.magnet_z_mm) <= tol and np.all(np.diff(rz[:, 1]) >= 0)
          and np.all(rz[:, 0] > tol) and np.all(rz[:, 0] < body.radius_mm - tol)
          and rz[-1, 0] <= body.magnet_radius_mm - body.magnet_edge_radius_mm + tol)
    if not ok:
        raise MechanicsError("Input void must be a wall from the base (z = 0) up to the magnet's lower face (z = "
                             f"{body.magnet_z_mm:g} mm), z non-decreasing, 0 < r < {body.radius_mm:g} mm, ending "
                             f"within the magnet's flat lower face; instead received {void!r}")
    return tuple((r, 0.0 if i == 0 else (body.magnet_z_mm if i == len(w) - 1 else z))
                 for i, (r, z) in enumerate(w))


def _sample_piece(body: Body, kind: str, geo: tuple, h: float) -> np.ndarray:
    """Points (2, n) along one boundary piece, both ends exact, spaced by the size function :func:`_size`."""
    s = np.linspace(0.0, 1.0, 513)
    if kind == "seg":
        r0, z0, r1, z1 = geo
        pts = np.vstack([r0 + s * (r1 - r0), z0 + s * (z1 - z0)])
        length = math.hypot(r1 - r0, z1 - z0)
    else:
        rc, zc, rad, a0, a1 = geo
        a = a0 + s * (a1 - a0)
        pts = np.vstack([rc + rad * np.cos(a), zc + rad * np.sin(a)])
        length = rad * (a1 - a0)
    inv = 1.0 / _size(body, h, pts[0], pts[1])
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (inv[1:] + inv[:-1]) * np.diff(s) * length)])
    n = max(1 if kind == "seg" else 2, math.ceil(cum[-1] - 1e-9))
    t = np.interp(np.linspace(0.0, cum[-1], n + 1), cum, s)
    if kind == "seg":
        out = np.vstack([r0 + t * (r1 - r0), z0 + t * (z1 - z0)])
        out[:, 0], out[:, -1] = (r0, z0), (r1, z1)
    else:
        a = a0 + t * (a1 - a0)
        out = np.vstack([rc + rad * np.cos(a), zc + rad * np.sin(a)])
        for i, ang in ((0, a0), (-1, a1)):  # exact ends, so they merge with the neighbouring pieces
            c, sn = math.cos(ang), math.sin(ang)
            out[:, i] = (rc + rad * (round(c) if abs(c - round(c)) < 1e-12 else c),
                         zc + rad * (round(sn) if abs(sn - round(sn)) < 1e-12 else sn))
    return out


def _graded_mesh(body: Body, h: float, void: Wall | None = None) -> _Mesh:
    """Quality mesh of size ~h graded down to :data:`EDGE_SIZE_FRACTION` of the edge radius at the magnet's rounded
    edges: boundary points by the size function, then Triangle (Shewchuk's quality Delaunay mesher, the ``triangle``
    package) with a 30-degree minimum angle, no Steiner points on the boundary, and per-triangle area bounds from the
    size function, refined twice so the interior follows the grading. Deterministic."""
    import triangle

    scale = max(body.radius_mm, body.height_mm)
    key = 1e-9 * scale
    index: dict[tuple[int, int], int] = {}
    verts: list[tuple[float, float]] = []
    segs: list[tuple[int, int]] = []
    for kind, geo, _tag in _boundary_pieces(body, void):
        ids = []
        for r, z in _sample_piece(body, kind, geo, h).T:
            k = (round(r / key), round(z / key))
            if k not in index:
                index[k] = len(verts)
                verts.append((r, z))
            ids.append(index[k])
        segs.extend((a, b) for a, b in itertools.pairwise(ids) if a != b)
    pslg: dict[str, np.ndarray] = {"vertices": np.array(verts), "segments": np.array(segs, dtype=np.int32)}
    if body.has_magnet:
        pslg["holes"] = np.array([[0.5 * body.magnet_radius_mm, body.magnet_z_mm + 0.5 * body.magnet_height_mm]])
    quality = f"pq{MIN_ANGLE_DEG:g}Y"
    tri = triangle.triangulate(pslg, quality + f"a{_area(h):.17g}")
    for _ in range(3):
        p, t = tri["vertices"], tri["triangles"]
        c = p[t].mean(axis=1)
        want = _area(_size(body, h, c[:, 0], c[:, 1]))
        if np.all(_areas(p.T, _orient(p.T, t.T)) <= 1.2 * want):
            break
        tri = triangle.triangulate({**tri, "triangle_max_area": want}, "r" + quality)
    p = np.array(tri["vertices"], dtype=float).T.copy()
    t = _orient(p, np.array(tri["triangles"], dtype=np.int64).T)
    return _finish(body, p, t, h, void)


def _area(size: np.ndarray | float) -> np.ndarray | float:
    """Area (mm^2) of an equilateral triangle of side ``size``."""
    return math.sqrt(3.0) / 4.0 * np.asarray(size) ** 2


def _areas(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    a, b, c = p[:, t[0]], p[:, t[1]], p[:, t[2]]
    return 0.5 * ((b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0]))


def _orient(p: np.ndarray, t: np.ndarray) -> np.ndarray:
    t = t.copy()
    neg = _areas(p, t) < 0
    t[1, neg], t[2, neg] = t[2, neg].copy(), t[1, neg].copy()
    return t


def _finish(body: Body, p: np.ndarray, t: np.ndarray, h: float, void: Wall | None = None) -> _Mesh:
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
    tags = _tag(body, p, on_boundary, void)
    if np.any(on_boundary & (tags == 0)) or bedges.shape[1] != int(on_boundary.sum()):
        raise MechanicsError(f"fe: mesh generation failed for mesh_mm = {h:g} (the triangulation does not follow "
                             "the body's outline); try another mesh size")
    if np.any(_areas(p, t) <= 0):
        raise MechanicsError(f"fe: mesh generation produced an inverted triangle for mesh_mm = {h:g}")
    return _Mesh(p, t, tags, h, _min_angle(p, t))


def _tag(body: Body, p: np.ndarray, on_boundary: np.ndarray, void: Wall | None = None) -> np.ndarray:
    """Boundary tags from geometry; boundary points near the cap are projected onto the sphere first."""
    r, z = p
    R, hb, H = body.radius_mm, body.base_height_mm, body.height_mm
    tol = 1e-7 * max(R, H)
    tags = np.zeros(p.shape[1], dtype=np.int64)
    tags[on_boundary & (r < tol)] |= _AXIS
    tags[on_boundary & (z < tol)] |= _BASE
    if body.has_magnet:
        _project_on_edges(body, p, on_boundary, tol)
        tags[on_boundary & (np.abs(_magnet_distance(body, p[0], p[1])) < tol)] |= _MAGNET
    if void:
        tags[on_boundary & (_wall_distance(void, p[0], p[1]) < tol)] |= _VOID
    outer = on_boundary & (np.abs(r - R) < tol) & (z < hb + tol)
    if body.tip == FLAT:
        outer |= on_boundary & (np.abs(z - H) < tol)
    else:
        cap = on_boundary & (z > hb - tol) & (tags & (_AXIS | _MAGNET | _VOID) == 0) | (
            on_boundary & (r < tol) & (z > H - tol))
        rho = np.hypot(r[cap], z[cap] - hb)
        p[0, cap] = r[cap] * R / rho  # chord midpoints of a refined mesh move onto the sphere
        p[1, cap] = hb + (z[cap] - hb) * R / rho
        outer |= cap
    tags[outer] |= _OUTER
    return tags


def _wall_distance(void: Wall, r: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Distance (mm) from points (r, z) to the void's wall polyline."""
    best = np.full(np.shape(r), np.inf)
    for (r0, z0), (r1, z1) in itertools.pairwise(void):
        dr, dz = r1 - r0, z1 - z0
        s = np.clip(((r - r0) * dr + (z - z0) * dz) / max(dr * dr + dz * dz, 1e-300), 0.0, 1.0)
        best = np.minimum(best, np.hypot(r - r0 - s * dr, z - z0 - s * dz))
    return best


def _project_on_edges(body: Body, p: np.ndarray, on_boundary: np.ndarray, tol: float) -> None:
    """Move boundary points near a rounded magnet edge onto its arc (chord midpoints of a refined mesh), in place."""
    re = body.magnet_edge_radius_mm
    for rc, zc in _edge_centres(body).T:
        dr, dz = p[0] - rc, p[1] - zc
        rho = np.hypot(dr, dz)
        lower = zc < body.magnet_z_mm + 0.5 * body.magnet_height_mm
        sector = (dr > tol) & ((dz < -tol) if lower else (dz > tol))
        near = on_boundary & sector & (np.abs(rho - re) < 0.1 * re)
        p[0, near] = rc + dr[near] * re / rho[near]
        p[1, near] = zc + dz[near] * re / rho[near]


def _min_angle(p: np.ndarray, t: np.ndarray) -> float:
    best = 180.0
    for i in range(3):
        a, b, c = p[:, t[i]], p[:, t[(i + 1) % 3]], p[:, t[(i + 2) % 3]]
        u, v = b - a, c - a
        cos = np.sum(u * v, axis=0) / (np.linalg.norm(u, axis=0) * np.linalg.norm(v, axis=0))
        best = min(best, float(np.degrees(np.arccos(np.clip(cos, -1, 1))).min()))
    return best


@lru_cache(maxsize=16)
def _body_mesh(body: Body, h: float, refine: int = 0, refine_near_apex_mm: float = 0.0,
               void: Wall | None = None) -> _Mesh:
    """The mesh of size h, then ``refine`` rounds of refinement (uniform, or of the triangles within
    ``refine_near_apex_mm`` of the top of the axis), new boundary points moved onto the cap; with a ``void``
    (:data:`Wall`, checked by :func:`check_void`), the silicone inside it taken away.

    Meshes are made for the body scaled to unit radius and then scaled back, so similar bodies get similar meshes
    (exactly, for a scale factor that is a power of two): what the scaling-invariance test relies on."""
    if not (math.isfinite(h) and h > 0.0):
        raise MechanicsError(f"Input mesh_mm must be a finite size > 0; instead received {h!r}")
    if h > 0.5 * min(body.radius_mm, body.height_mm):
        raise MechanicsError(f"Input mesh_mm must be at most half the body's radius and height; "
                             f"instead received {h!r}")
    unit = body.radius_mm
    unit_void = tuple((r / unit, z / unit) for r, z in void) if void else None
    m = _unit_mesh(body.scaled(1.0 / unit), h / unit, refine, refine_near_apex_mm / unit, unit_void)
    return _Mesh(m.p * unit, m.t, m.tags, m.h * unit, m.min_angle_deg)


@lru_cache(maxsize=16)
def _unit_mesh(body: Body, h: float, refine: int, refine_near: float, void: Wall | None = None) -> _Mesh:
    """_body_mesh for a body of unit radius; ``h`` of the result is the size away from any local refinement."""
    mesh = _graded_mesh(body, h, void)
    from skfem import MeshTri

    for _ in range(refine):
        m = MeshTri(mesh.p, np.ascontiguousarray(mesh.t), sort_t=False)
        if refine_near > 0.0:
            c = m.p[:, m.t].mean(axis=1)
            m = m.refined(np.nonzero(np.hypot(c[0], c[1] - body.height_mm) < refine_near)[0])
        else:
            m = m.refined()
        p = np.array(m.p, dtype=float)
        mesh = _finish(body, p, _orient(p, np.array(m.t)), mesh.h if refine_near > 0.0 else mesh.h / 2.0, void)
    return mesh
