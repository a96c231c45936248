"""Pictures of the parts from their meshes: the closed outlines where the axis plane cuts a mesh, and a
shaded orthographic view of each part, whole and cut away, drawn with matplotlib's 3-D axes (a painter's
sort of small, camera-facing triangles) and supersampled to a PNG.

Millimetres throughout; matplotlib, scipy, trimesh and PIL are imported inside the functions that use them.
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import trimesh

# Imported lazily, inside the functions that use them, for speed: scipy, trimesh, matplotlib and Pillow take a
# noticeable time to import, and importing this module should not.

__all__ = ["section_loops", "part_figure", "PART_VIEWS", "CUT_COLOUR", "CUT_OFFSET_MM"]

#: Part pictures: stem -> (title, surface colour). Cut faces are drawn in CUT_COLOUR, as CAD sections are.
PART_VIEWS = {
    "elastomer": ("Elastomer", "#8fbbe0"),
    "mould_cup": ("Mould cup (print pose)", "#b8b8b8"),
    "mould_lid": ("Mould lid (print pose)", "#c9b48a"),
    "pad": ("Mounting pad (print pose, board frame)", "#9e9e9e"),
    "weigh_cap": ("Weight jig's cap (print pose)", "#d8c38f"),
    "weigh_stand_0": ("Weight jig's stand, flat (print pose)", "#a9c4a0"),
    "weigh_stand_20": ("Weight jig's stand, 20 degrees (print pose)", "#a9c4a0"),
    "weigh_stand_40": ("Weight jig's stand, 40 degrees (print pose)", "#a9c4a0"),
}
CUT_COLOUR = "#d9534f"
VIEW_ELEV_DEG, VIEW_AZIM_DEG = 28.0, -58.0  # one fixed view for every part: looking at the y = 0 cut
#: The cut sits this far off the y = 0 plane (mm): revolved parts have their seam vertices on it.
CUT_OFFSET_MM = 1e-3
PART_DPI = 130
SUPERSAMPLE = 3  # part pictures are drawn at this many times PART_DPI and averaged down
#: Part triangles are split until their edges are shorter than the part's size over this.
REFINE_PER_SIZE = 24.0


# ---------------------------------------------------------------------------------------------------
# Sections of a mesh through its axis plane


def _merge_points(points: np.ndarray, tol: float) -> np.ndarray:
    """An id per point; points closer than ``tol`` share one (union-find over KD-tree pairs)."""
    from scipy.spatial import cKDTree

    parent = np.arange(len(points))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for i, j in sorted(cKDTree(points).query_pairs(tol)):
        a, b = root(i), root(j)
        if a != b:
            parent[max(a, b)] = min(a, b)
    return np.array([root(i) for i in range(len(points))])


def section_loops(mesh: trimesh.Trimesh, y_mm: float = CUT_OFFSET_MM) -> list[np.ndarray]:
    """The closed outlines where the plane y = ``y_mm`` cuts the mesh, each an (n, 2) array of (x, z) mm."""
    import trimesh

    segments = trimesh.intersections.mesh_plane(mesh, [0.0, 1.0, 0.0], [0.0, y_mm, 0.0])[:, :, [0, 2]]
    if len(segments) == 0:
        return []
    ids = _merge_points(segments.reshape(-1, 2), 1e-6 * max(1.0, float(np.ptp(mesh.bounds)))).reshape(-1, 2)
    touching: dict[int, list[int]] = {}
    for k, (a, b) in enumerate(ids):
        if a != b:
            touching.setdefault(int(a), []).append(k)
            touching.setdefault(int(b), []).append(k)
    used = np.zeros(len(ids), dtype=bool)
    used[ids[:, 0] == ids[:, 1]] = True
    loops = []
    for start in range(len(ids)):
        if used[start]:
            continue
        used[start] = True
        first, here = int(ids[start, 0]), int(ids[start, 1])
        points = [segments[start, 0], segments[start, 1]]
        while here != first:
            nxt = next((k for k in touching.get(here, ()) if not used[k]), None)
            if nxt is None:
                break
            used[nxt] = True
            end = 1 if ids[nxt, 0] == here else 0
            here = int(ids[nxt, end])
            points.append(segments[nxt, end])
        if here == first and len(points) > 3:
            loops.append(np.array(points[:-1]))
    return loops


def _inside(loops: Sequence[np.ndarray], points: np.ndarray) -> np.ndarray:
    """Even-odd inside test of (n, 2) points against all loops at once."""
    from matplotlib.path import Path

    count = np.zeros(len(points), dtype=int)
    for loop in loops:
        count += Path(loop).contains_points(points)
    return count % 2 == 1


def _cap(loops: Sequence[np.ndarray], spacing: float) -> np.ndarray:
    """Small triangles covering the region the loops enclose, (m, 3, 2): a Delaunay mesh of the densified
    outlines and an inner grid, keeping the triangles whose centroids are inside."""
    from scipy.spatial import Delaunay, cKDTree

    rim = []
    for loop in loops:
        nxt = np.roll(loop, -1, axis=0)
        for p, q in zip(loop, nxt):
            n = max(1, math.ceil(np.hypot(*(q - p)) / (0.5 * spacing)))
            rim.append(p + (q - p) * (np.arange(n)[:, None] / n))
    rim_pts = np.vstack(rim)
    lo, hi = rim_pts.min(axis=0), rim_pts.max(axis=0)
    gx, gz = np.meshgrid(np.arange(lo[0], hi[0], spacing) + spacing / 2, np.arange(lo[1], hi[1], spacing) + spacing / 2)
    grid = np.column_stack([gx.ravel(), gz.ravel()])
    grid = grid[_inside(loops, grid)]
    if len(grid):
        grid = grid[cKDTree(rim_pts).query(grid)[0] > 0.4 * spacing]
    pts = np.vstack([rim_pts, grid])
    tri = pts[Delaunay(pts).simplices]
    return tri[_inside(loops, tri.mean(axis=1))]


# ---------------------------------------------------------------------------------------------------
# Part pictures


def _eye(elev_deg: float, azim_deg: float) -> np.ndarray:
    """Unit vector from the scene towards matplotlib's camera at this elevation and azimuth."""
    e, a = math.radians(elev_deg), math.radians(azim_deg)
    return np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])


def _shade(normals: np.ndarray, colour: str, eye: np.ndarray) -> np.ndarray:
    """Lambert shading under a key light above and to the left of the camera, plus ambient; RGBA."""
    from matplotlib.colors import to_rgb

    right = np.cross(-eye, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, -eye)
    light = eye + 0.6 * up - 0.5 * right
    light /= np.linalg.norm(light)
    k = 0.38 + 0.62 * np.clip(normals @ light, 0.0, 1.0)
    rgb = np.clip(np.outer(k, to_rgb(colour)) + 0.08 * k[:, None] ** 8, 0.0, 1.0)
    return np.column_stack([rgb, np.ones(len(rgb))])


def _facing(triangles: np.ndarray, eye: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The triangles that face the camera and their unit normals (an orthographic view of a closed
    surface never shows a back face, and dropping them halves the painter's sorting errors)."""
    n = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    length = np.linalg.norm(n, axis=1)
    keep = length > 1e-12
    n = n[keep] / length[keep, None]
    triangles = triangles[keep]
    front = n @ eye > 1e-9
    return triangles[front], n[front]


def _cut_away(mesh: trimesh.Trimesh, y_mm: float = CUT_OFFSET_MM) -> tuple[np.ndarray, np.ndarray]:
    """The part behind the plane y = ``y_mm`` as triangles (n, 3, 3), and the cut face as triangles."""
    import trimesh

    v, f = trimesh.intersections.slice_faces_plane(mesh.vertices, mesh.faces, np.array([0.0, 1.0, 0.0]),
                                                   np.array([0.0, y_mm, 0.0]))[:2]
    loops = section_loops(mesh, y_mm)
    if not loops:
        return v[f], np.zeros((0, 3, 3))
    extent = float(np.ptp(np.vstack(loops), axis=0).max())
    cap2 = _cap(loops, extent / 70.0)
    cap = np.stack([cap2[:, :, 0], np.full(cap2.shape[:2], y_mm), cap2[:, :, 1]], axis=-1)
    return v[f], cap


def _refined(triangles: np.ndarray, max_edge: float) -> np.ndarray:
    """The triangles split until no edge is longer than ``max_edge``: the painter's sort sorts whole
    triangles by their centres, which misorders the long slivers a CAD kernel puts on flat faces."""
    from trimesh.remesh import subdivide_to_size

    if len(triangles) == 0:
        return triangles
    v, f = subdivide_to_size(triangles.reshape(-1, 3), np.arange(3 * len(triangles)).reshape(-1, 3), max_edge,
                             max_iter=12)
    return v[f]


def _draw_part(ax, triangles: np.ndarray, cut: np.ndarray, colour: str, bounds: np.ndarray, title: str) -> None:
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    eye = _eye(VIEW_ELEV_DEG, VIEW_AZIM_DEG)
    size = np.ptp(bounds, axis=0)
    tris, normals = _facing(_refined(triangles, float(size.max()) / REFINE_PER_SIZE), eye)
    faces = _shade(normals, colour, eye)
    if len(cut):
        cut_tris, cut_normals = _facing(cut, eye)
        tris = np.concatenate([tris, cut_tris])
        faces = np.concatenate([faces, _shade(cut_normals, CUT_COLOUR, eye)])
    # Antialiased triangles leave hairline seams that let what lies behind bleed through; the figure is
    # drawn without antialiasing, supersampled (part_figure).
    ax.add_collection3d(Poly3DCollection(tris, facecolors=faces, edgecolors="none", linewidths=0.0,
                                         antialiased=False))
    for set_lim, lo, hi in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), bounds[0], bounds[1]):
        set_lim(lo, hi)
    ax.set_proj_type("ortho")
    ax.view_init(elev=VIEW_ELEV_DEG, azim=VIEW_AZIM_DEG)
    _fill_axes(ax, bounds)
    ax.set_axis_off()
    ax.set_title(title, fontsize=9)


def _fill_axes(ax, bounds: np.ndarray, fill: float = 0.97) -> None:
    """Equal scale on the three axes, zoomed so the part's bounding box just fits the panel (matplotlib's
    own fit leaves room for any view of a cube: a wide margin round a long mould)."""
    from mpl_toolkits.mplot3d import proj3d

    size = np.ptp(bounds, axis=0)
    aspect = tuple(np.maximum(size, 1e-3 * size.max()))
    ax.set_box_aspect(aspect, zoom=1.0)
    corners = np.array([[bounds[i, 0], bounds[j, 1], bounds[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    xs, ys, _ = proj3d.proj_transform(corners[:, 0], corners[:, 1], corners[:, 2], ax.get_proj())
    span = np.ptp(ax.transData.transform(np.column_stack([xs, ys])), axis=0)
    box = ax.get_window_extent()
    ax.set_box_aspect(aspect, zoom=fill / max(span[0] / box.width, span[1] / box.height))


def part_figure(stem: str, mesh: trimesh.Trimesh) -> bytes:
    """PNG: the part whole, and cut away at its axis plane (y = 0) with the cut face in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    colour = PART_VIEWS.get(stem, (stem, "#b0b0b0"))[1]
    bounds = np.asarray(mesh.bounds, dtype=float)
    behind, cut = _cut_away(mesh)
    fig = plt.figure(figsize=(8.0, 3.4))
    _draw_part(fig.add_subplot(1, 2, 1, projection="3d"), np.asarray(mesh.triangles), np.zeros((0, 3, 3)),
               colour, bounds, "whole part")
    _draw_part(fig.add_subplot(1, 2, 2, projection="3d"), behind, cut, colour, bounds,
               "cut at the axis plane y = 0 (cut face red)")
    fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.93, wspace=0.0)
    fig.set_dpi(PART_DPI * SUPERSAMPLE)
    canvas = fig.canvas
    if not isinstance(canvas, FigureCanvasAgg):  # only Agg's canvas lends its pixels (the backend chosen above)
        raise TypeError(f"matplotlib drew on a {type(canvas).__name__}, not Agg's canvas")
    canvas.draw()
    pixels = np.asarray(canvas.buffer_rgba())[:, :, :3]  # uint8, a view: no float copy of the big canvas
    plt.close(fig)
    return _png(_squeeze_blank_rows(_downsample(pixels, SUPERSAMPLE)))


def _downsample(pixels: np.ndarray, k: int) -> np.ndarray:
    """Average k x k blocks of an (h, w, 3) uint8 image: antialiasing by supersampling, uint8 out.

    Integer sums rounded half up: the same bytes as rounding the float mean for odd k (a block's mean is
    never exactly half-way), at a fraction of the cost of a float copy of the whole canvas."""
    h, w = (pixels.shape[0] // k) * k, (pixels.shape[1] // k) * k
    image = pixels[:h, :w].astype(np.uint32)
    # strided adds: far faster than a reduce over a reshaped view
    rows = sum((image[i::k] for i in range(1, k)), start=image[0::k])
    sums = sum((rows[:, j::k] for j in range(1, k)), start=rows[:, 0::k])
    return ((2 * sums + k * k) // (2 * k * k)).astype(np.uint8)


def _squeeze_blank_rows(rgb: np.ndarray, keep: int = 12) -> np.ndarray:
    """Shorten every run of all-white rows to ``keep`` rows: flat parts leave wide bands of nothing
    above and below them in a panel whose width the longest part sets."""
    blank = np.all(rgb == 255, axis=(1, 2))
    rows, run = [], 0
    for i, b in enumerate(blank):
        run = run + 1 if b else 0
        if run <= keep:
            rows.append(i)
    return rgb[rows]


def _png(rgb: np.ndarray) -> bytes:
    from PIL import Image

    out = io.BytesIO()
    Image.fromarray(rgb, "RGB").save(out, format="PNG", optimize=True)
    return out.getvalue()
