"""report.html: one self-contained page that ties a build together.

What a researcher opens first: the key figures, pictures of every part (a shaded view and a cut-away at
the axis plane, the assembled stack-up with its distances, the routed board), the predictions and their
plots, the chosen models and the calibration, the design checks by severity, every spec key, and every
file of the build with what it is for, linked by relative paths so the page works from the build folder.

Self-contained: every picture is a ``data:`` URI (PNG or SVG made here, or the build's own plot SVGs), so
the page loads nothing from anywhere; nothing from the spec, the findings or the file list is marked
safe in the template (``templates/report/report.html.j2``, autoescaped). Deterministic: the same inputs
give the same bytes (matplotlib with fixed SVG ids and no dates, no time stamps on the page).

matplotlib and scipy are imported inside the functions that draw, so importing this module is cheap.
"""

from __future__ import annotations

import base64
import io
import json
import math
from dataclasses import dataclass
from pathlib import PurePosixPath
from typing import TYPE_CHECKING, Iterable, Mapping, Sequence
from urllib.parse import quote
from xml.sax.saxutils import escape

import numpy as np

from .. import __version__
from ..errors import Finding, Severity

if TYPE_CHECKING:
    import trimesh

    from ..build import Artifact
    from ..design import Design
    from ..pcb import Board
    from ..models.predict import Prediction
    from ..spec import Spec

__all__ = ["render_report", "Figure", "part_figure", "stackup_figure", "board_svg", "section_loops",
           "REPORT_PATH", "BENCH_FILES"]

REPORT_PATH = "report.html"
#: The bench documents the report links at its top, when the build has them.
BENCH_FILES = (("checklist.html", "printable checklist with tick boxes"),
               ("checklist.md", "the same checklist as Markdown"),
               ("bom.csv", "bill of materials"))
#: Part pictures: stem -> (title, surface colour). Cut faces are drawn in CUT_COLOUR, as CAD sections are.
PART_VIEWS = {
    "elastomer": ("Elastomer", "#8fbbe0"),
    "mould_cup": ("Mould cup (print pose)", "#b8b8b8"),
    "mould_lid": ("Mould lid (print pose)", "#c9b48a"),
    "pad": ("Mounting pad (print pose, board frame)", "#9e9e9e"),
}
CUT_COLOUR = "#d9534f"
VIEW_ELEV_DEG, VIEW_AZIM_DEG = 28.0, -58.0  # one fixed view for every part: looking at the y = 0 cut
#: The cut sits this far off the y = 0 plane (mm): revolved parts have their seam vertices on it.
CUT_OFFSET_MM = 1e-3
PART_DPI = 130
SUPERSAMPLE = 3  # part pictures are drawn at this many times PART_DPI and averaged down
#: Part triangles are split until their edges are shorter than the part's size over this.
REFINE_PER_SIZE = 24.0
_SEVERITY_ORDER = (Severity.ERROR, Severity.WARNING, Severity.INFO)
FORCE_NAMES = {"Fz_N": "Fz (normal)", "Fr_N": "Fr (shear)"}


@dataclass(frozen=True)
class Figure:
    """A picture on the page: ``src`` is a data: URI; ``links`` are (relative href, label) pairs."""

    id: str
    title: str
    caption: str
    src: str
    links: tuple[tuple[str, str], ...] = ()


def _data_uri(data: bytes, mime: str) -> str:
    return f"data:{mime};base64,{base64.b64encode(data).decode('ascii')}"


def _svg_uri(data: bytes, where: str) -> str:
    """An SVG of our own (a plot) as a data: URI, after checking that it is an SVG document."""
    head = data.lstrip()[:200]
    if not (head.startswith(b"<?xml") or head.startswith(b"<svg")) or b"<svg" not in data[:2000]:
        raise ValueError(f"{where} is not an SVG document (it must start with '<?xml' or '<svg')")
    return _data_uri(data, "image/svg+xml")


def _href(path: str) -> str:
    return quote(path, safe="/")


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


def section_loops(mesh: "trimesh.Trimesh", y_mm: float = CUT_OFFSET_MM) -> list[np.ndarray]:
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
            n = max(1, int(math.ceil(np.hypot(*(q - p)) / (0.5 * spacing))))
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


def _cut_away(mesh: "trimesh.Trimesh", y_mm: float = CUT_OFFSET_MM) -> tuple[np.ndarray, np.ndarray]:
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


def part_figure(stem: str, mesh: "trimesh.Trimesh") -> bytes:
    """PNG: the part whole, and cut away at its axis plane (y = 0) with the cut face in red."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

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
    fig.canvas.draw()
    pixels = np.asarray(fig.canvas.buffer_rgba(), dtype=np.float64)[:, :, :3]
    plt.close(fig)
    return _png(_squeeze_blank_rows(_downsample(pixels, SUPERSAMPLE)))


def _downsample(pixels: np.ndarray, k: int) -> np.ndarray:
    """Average k x k blocks of an (h, w, 3) image: antialiasing by supersampling, uint8 out."""
    h, w = (pixels.shape[0] // k) * k, (pixels.shape[1] // k) * k
    blocks = pixels[:h, :w].reshape(h // k, k, w // k, k, 3).mean(axis=(1, 3))
    return np.round(blocks).astype(np.uint8)


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


# ---------------------------------------------------------------------------------------------------
# The assembled stack-up, in section


def _fill_loops(ax, loops: Sequence[np.ndarray], dz: float, **style) -> None:
    """Fill the region the loops enclose (even-odd), shifted up by ``dz``."""
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path

    if not loops:
        return
    verts, codes = [], []
    for loop in loops:
        pts = np.vstack([loop, loop[:1]]) + [0.0, dz]
        verts.append(pts)
        codes += [Path.MOVETO] + [Path.LINETO] * (len(loop) - 1) + [Path.CLOSEPOLY]
    ax.add_patch(PathPatch(Path(np.vstack(verts), codes), **style))


def _dimension(ax, x: float, z0: float, z1: float, text: str, left: bool = False) -> None:
    """A vertical dimension from z0 to z1 at x, with dotted extension lines from the axis."""
    ax.annotate("", xy=(x, z0), xytext=(x, z1),
                arrowprops={"arrowstyle": "<|-|>", "lw": 0.7, "color": "k", "shrinkA": 0, "shrinkB": 0,
                            "mutation_scale": 6})
    for z in (z0, z1):
        ax.plot([0.0, x], [z, z], color="0.35", lw=0.5, ls=":")
    ax.text(x + (-0.3 if left else 0.3), 0.5 * (z0 + z1), text, fontsize=7, va="center",
            ha="right" if left else "left")


#: Stack-up colours: (face, edge, hatch) per layer, shared by the drawing and its legend.
STACK_STYLE = {
    "board": ("#9ccc9c", "#2e7d32", None), "chip": ("#424242", "k", None), "pad": ("#cfcfcf", "#555555", "////"),
    "glue": ("#f6c344", "none", None), "elastomer": ("#cfe2f3", "#3b6f9e", None), "north": ("#d9534f", "k", None),
    "south": ("#4a78c2", "k", None),
}


def _style(layer: str) -> dict[str, object]:
    fc, ec, hatch = STACK_STYLE[layer]
    return {"fc": fc, "ec": ec, "hatch": hatch, "lw": 0.7}


def _draw_stack(ax, design: "Design", meshes: Mapping[str, "trimesh.Trimesh"]) -> None:
    """The layers in section: board, chip, pad (mesh section), glue, elastomer (mesh section), magnet."""
    from matplotlib.patches import Rectangle

    d = design
    half = d.pad_radius_mm + 1.5
    t = d.spec.pcb.thickness_mm
    ax.add_patch(Rectangle((-half, -t), 2 * half, t, **_style("board")))
    ax.add_patch(Rectangle((-d.chip_body_max_mm / 2, 0.0), d.chip_body_max_mm, d.chip_height_nominal_mm,
                           **_style("chip")))
    _fill_loops(ax, section_loops(meshes["pad"]), 0.0, **_style("pad"))
    ax.add_patch(Rectangle((-d.elastomer_radius_mm, d.z_pad_top_mm), 2 * d.elastomer_radius_mm,
                           d.z_elastomer_base_mm - d.z_pad_top_mm, **_style("glue")))
    _fill_loops(ax, section_loops(meshes["elastomer"]), d.z_elastomer_base_mm, **_style("elastomer"))
    rm, mid = d.magnet_radius_mm, 0.5 * (d.z_magnet_low_mm + d.z_magnet_top_mm)
    for z0, z1, layer, pole in ((mid, d.z_magnet_top_mm, "north", "N"), (d.z_magnet_low_mm, mid, "south", "S")):
        ax.add_patch(Rectangle((-rm, z0), 2 * rm, z1 - z0, **_style(layer)))
        ax.text(0.0, 0.5 * (z0 + z1), pole, color="w", fontsize=7, ha="center", va="center", weight="bold")
    ax.plot([0.0], [d.z_sense_mm], marker="x", color="#f57c00", ms=6, mew=1.5)
    ax.axvline(0.0, color="0.5", lw=0.4, ls="-.")


def _dimension_stack(ax, design: "Design") -> None:
    """d_rest and cover on the right, d_min (and where the magnet's lower face gets to) on the left, skin."""
    d = design
    top = d.z_elastomer_base_mm + d.elastomer_height_mm
    z_full = d.z_sense_mm + d.spec.sensor.d_min_mm
    ax.plot([-d.magnet_radius_mm, d.magnet_radius_mm], [z_full, z_full], color=STACK_STYLE["south"][0], lw=0.8, ls="--")
    x = d.pad_radius_mm + 1.0
    _dimension(ax, x, d.z_sense_mm, d.z_magnet_low_mm, f"d_rest {d.d_rest_mm:.2f} mm")
    _dimension(ax, x, d.z_magnet_top_mm, top, f"cover {d.cover_mm:.2f} mm")
    _dimension(ax, -x, d.z_sense_mm, z_full, f"d_min {d.spec.sensor.d_min_mm:.2f} mm\n(lower face at full load)",
               left=True)
    rim = (d.pocket_radius_mm, d.z_elastomer_base_mm + d.pocket_roof_z_mm)  # where the skin is thinnest
    ax.annotate(f"skin {d.skin_mm:.2f} mm\n(thinnest silicone)", xy=rim,
                xytext=(d.elastomer_radius_mm + 0.8, top + 0.3), fontsize=7,
                arrowprops={"arrowstyle": "->", "lw": 0.6, "color": "k"})


def stackup_figure(design: "Design", meshes: Mapping[str, "trimesh.Trimesh"]) -> bytes:
    """SVG: the sensor assembled on its board, cut through the axis, with d_rest, d_min, cover and skin.

    Board frame (z = 0 on the board's top face); the pad and elastomer outlines are sections of the
    meshes the build exports, the chip, glue and magnet are drawn from the design's numbers."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    spec = design.spec
    labels = {"elastomer": f"elastomer ({spec.elastomer.material})", "north": f"magnet {spec.magnet.grade}, N up",
              "glue": "glue", "pad": "pad", "chip": f"{design.chip.key} (x: sensing point)", "board": "board"}
    half = design.pad_radius_mm + 1.5
    with matplotlib.rc_context({"svg.hashsalt": "magfab-report", "svg.fonttype": "path"}):
        fig, ax = plt.subplots(figsize=(8.0, 4.2))
        _draw_stack(ax, design, meshes)
        _dimension_stack(ax, design)
        ax.legend(handles=[Patch(**_style(k), label=v) for k, v in labels.items()], fontsize=7, loc="upper left",
                  bbox_to_anchor=(1.0, 1.0), frameon=False)
        ax.set_aspect("equal")
        ax.set_xlim(-half - 5.5, half + 5.5)
        ax.set_ylim(-spec.pcb.thickness_mm - 0.5, design.z_elastomer_base_mm + design.elastomer_height_mm + 1.5)
        ax.set_xlabel("x, mm (section through the axis)", fontsize=8)
        ax.set_ylabel("z above the board, mm", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.set_title(f"{spec.name}: the stack-up at rest", fontsize=9)
        out = io.BytesIO()
        fig.savefig(out, format="svg", bbox_inches="tight", pad_inches=0.05, metadata={"Date": None, "Creator": None})
        plt.close(fig)
    return out.getvalue()


# ---------------------------------------------------------------------------------------------------
# The board, drawn from the routed Board (KiCad frame: mm, y down, as SVG's)


_LAYER_FILL = {"F.Cu": ("#c83434", 0.85), "B.Cu": ("#4d7fc4", 0.7)}


def _copper_svg(c, layer: str) -> str:
    colour, alpha = _LAYER_FILL[layer]
    if c.kind == "rect":
        (x0, y0), (x1, y1) = c.a, c.b
        return (f'<rect x="{x0:.4f}" y="{y0:.4f}" width="{x1 - x0:.4f}" height="{y1 - y0:.4f}" '
                f'fill="{colour}" fill-opacity="{alpha}"/>')
    if c.kind == "seg":
        return (f'<line x1="{c.a[0]:.4f}" y1="{c.a[1]:.4f}" x2="{c.b[0]:.4f}" y2="{c.b[1]:.4f}" stroke="{colour}" '
                f'stroke-opacity="{alpha}" stroke-width="{2 * c.r:.4f}" stroke-linecap="round"/>')
    return f'<circle cx="{c.a[0]:.4f}" cy="{c.a[1]:.4f}" r="{c.r:.4f}" fill="{colour}" fill-opacity="{alpha}"/>'


def board_svg(board: "Board", via_drill_mm: float) -> bytes:
    """SVG of the routed board from above: bottom copper (blue) under top copper (red), vias, drilled
    holes, the mounting pad's disc (dashed), references and the silk label."""
    x0, y0, x1, y1 = board.outline
    m = 1.0
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="{x0 - m:.3f} {y0 - m:.3f} {x1 - x0 + 2 * m:.3f} '
           f'{y1 - y0 + 2 * m:.3f}" width="{(x1 - x0 + 2 * m) * 16:.0f}" height="{(y1 - y0 + 2 * m) * 16:.0f}" '
           'font-family="DejaVu Sans, Arial, sans-serif">',
           f'<rect x="{x0}" y="{y0}" width="{x1 - x0}" height="{y1 - y0}" fill="#1f4d2b" stroke="#c8c800" '
           'stroke-width="0.1"/>']
    copper = board.copper()
    holes = [c for c in copper if c.hole]
    vias = [c for c in copper if not c.hole and c.kind == "point" and len(c.layers) == 2]
    for layer in ("B.Cu", "F.Cu"):
        out += [_copper_svg(c, layer) for c in copper if not c.hole and c not in vias and layer in c.layers]
    out += [f'<circle cx="{v.a[0]:.4f}" cy="{v.a[1]:.4f}" r="{v.r:.4f}" fill="#d9b64c"/>'
            f'<circle cx="{v.a[0]:.4f}" cy="{v.a[1]:.4f}" r="{via_drill_mm / 2:.4f}" fill="#111"/>' for v in vias]
    out += [f'<circle cx="{h.a[0]:.4f}" cy="{h.a[1]:.4f}" r="{h.r:.4f}" fill="#fff" stroke="#000" '
            'stroke-width="0.08"/>' for h in holes]
    cx, cy, r = board.pad_circle
    out.append(f'<circle cx="{cx}" cy="{cy}" r="{r}" fill="none" stroke="#fff" stroke-width="0.12" '
               'stroke-dasharray="0.6 0.4"/>')
    for p in board.parts:
        if p.ref.startswith("H"):
            continue
        colour = "#ffd0d0" if not p.bottom else "#cfe0ff"
        out.append(f'<text x="{p.x:.3f}" y="{p.y:.3f}" font-size="0.9" text-anchor="middle" '
                   f'dominant-baseline="central" fill="{colour}">{escape(p.ref)}</text>')
    for t in board.label:
        out.append(f'<text x="{t.x:.3f}" y="{t.y:.3f}" font-size="{t.size:.3f}" text-anchor="middle" '
                   f'dominant-baseline="central" fill="#f0f0f0">{escape(t.text)}</text>')
    out.append("</svg>\n")
    return "\n".join(out).encode("utf-8")


# ---------------------------------------------------------------------------------------------------
# Tables


def _num(x: object, fmt: str = ".3g") -> str:
    return "—" if x is None else format(float(x), fmt)  # type: ignore[arg-type]


def _spec_value(value: object, key: str) -> str:
    """A spec value as it would be written in TOML (None: omitted, derived or taken from a recipe)."""
    if value is None:
        return "(omitted)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int) and key.endswith("address"):
        return f"{value} (0x{value:02X})"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_spec_value(v, "") for v in value) + "]"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    return repr(value)


def _spec_sections(spec: "Spec") -> list[dict[str, object]]:
    """Every section and key of the spec with its value, meaning and whether it differs from the default."""
    from ..spec import Spec

    values, defaults = spec.model_dump(mode="json"), Spec().model_dump(mode="json")
    general = {"title": "general", "doc": "", "rows": []}
    sections = [general]
    for name, info in type(spec).model_fields.items():
        value = values[name]
        if not isinstance(value, dict):
            general["rows"].append({"key": name, "value": _spec_value(value, name), "doc": info.description or "",
                                    "changed": value != defaults[name]})
            continue
        model = type(getattr(spec, name))
        rows = [{"key": k, "value": _spec_value(v, k), "doc": model.model_fields[k].description or "",
                 "changed": v != defaults[name].get(k)} for k, v in value.items()]
        sections.append({"title": name, "doc": (model.__doc__ or "").strip(), "rows": rows})
    return sections


def _stack_rows(design: "Design") -> list[tuple[str, str]]:
    d, sen = design, design.spec.sensor
    return [
        ("rest distance d_rest, magnet lower face to sensing point", f"{d.d_rest_mm:.3f} mm"),
        ("closest under load d_min (spec)", f"{sen.d_min_mm:.3f} mm"),
        ("magnet travel to d_min", f"{d.d_rest_mm - sen.d_min_mm:.3f} mm"),
        ("cover: silicone above the magnet on the axis", f"{d.cover_mm:.3f} mm"),
        ("skin: thinnest silicone around the pocket",
         f"{d.skin_mm:.3f} mm (spec minimum {design.spec.elastomer.min_skin_mm:g})"),
        ("d_rest this elastomer, pad and chip allow", f"{d.d_rest_range_mm[0]:.3f} to {d.d_rest_range_mm[1]:.3f} mm"),
        ("magnet, diameter x height", f"{2 * d.magnet_radius_mm:g} x {d.magnet_height_mm:g} mm"),
        ("pocket, diameter x height", f"{2 * d.pocket_radius_mm:.3f} x {d.pocket_height_mm:.3f} mm"),
        ("silicone per cast part", f"{d.elastomer_volume_mm3 / 1000:.3f} mL"),
    ]


def _heights(design: "Design") -> list[tuple[str, str]]:
    d = design
    return [(name, f"{z:.3f}") for name, z in sorted([
        ("board top face", 0.0), ("Hall sensing point", d.z_sense_mm), ("chip package top", d.chip_height_nominal_mm),
        ("pad top (glue face)", d.z_pad_top_mm), ("elastomer base", d.z_elastomer_base_mm),
        ("magnet lower face", d.z_magnet_low_mm), ("magnet top = pocket roof", d.z_magnet_top_mm),
        ("elastomer top", d.z_elastomer_base_mm + d.elastomer_height_mm)], key=lambda r: r[1])]


def _prediction_tables(data: Mapping[str, object]) -> dict[str, list[tuple[str, str]]]:
    n, s, f, c, nz = data["normal"], data["shear"], data["field"], data["chip"], data["noise_G"]
    band = lambda m, fmt: ", ".join(f"{k} {format(v, fmt)}" for k, v in m.items())  # noqa: E731
    return {
        "normal": [
            ("sensitivity over the range", f"{n['sensitivity_G_per_N'][0]:.1f} – {n['sensitivity_G_per_N'][1]:.1f} G/N"),
            ("resolution, worst case", f"{n['resolution_mN']:.2f} mN"),
            ("resolution at rest (weakest magnet)", band(n["resolution_at_rest_mN"], ".2f") + " mN"),
            ("range, worst case", f"{n['range_N']:.3f} N (ends at: {n['range_limit']})"),
            ("range by material", band(n["range_by_material_N"], ".3f") + " N"),
            ("magnet travel over the range", f"{n['travel_mm']:.3f} mm"),
            ("stiffness at rest", band(n["stiffness_at_rest_N_per_mm"], ".3f") + " N/mm"),
        ] + ([("where the mechanics model stopped", str(n["model_limit"]))] if "model_limit" in n else []),
        "shear": [
            ("sensitivity", f"{s['sensitivity_G_per_N'][0]:.1f} – {s['sensitivity_G_per_N'][1]:.1f} G/N"),
            ("resolution, worst case", f"{s['resolution_mN']:.2f} mN"),
            ("range, worst case", f"{s['range_N']:.3f} N (ends at: {s['range_limit']})"),
            ("range by material", band(s["range_by_material_N"], ".3f") + " N"),
            ("stiffness", band(s["stiffness_N_per_mm"], ".3f") + " N/mm"),
        ],
        "field": [
            ("Bz at rest (nominal magnet)", f"{f['Bz_rest_G']:.1f} G"),
            ("dBz/dz at rest", f"{f['dBz_dz_rest_G_per_mm']:.1f} G/mm"),
            ("dBr/dr at rest", f"{f['dBr_dr_rest_G_per_mm']:.1f} G/mm"),
            ("Bz at d_min (nominal / strongest magnet)", f"{f['Bz_d_min_G']:.1f} / {f['Bz_d_min_strongest_G']:.1f} G"),
            ("Bz where the range ends (strongest magnet)", f"{f['Bz_range_end_strongest_G']:.1f} G"),
            ("remanence band", band(f["remanence_T"], ".3f") + " T"),
            ("elastomer shear modulus band", band(data["material_mu_kPa"], "g") + " kPa"),
        ],
        "chip": [
            ("GAIN_SEL / RES / OSR / DIG_FILT", f"{c['gain_sel']} / {c['resolution']} / {c['osr']} / {c['dig_filt']}"),
            ("LSB, xy / z", f"{c['lsb_xy_uT']:.3f} / {c['lsb_z_uT']:.3f} µT"),
            ("full scale, xy / z", f"{c['full_scale_xy_G']:.1f} / {c['full_scale_z_G']:.1f} G"),
            ("saturation onset", f"{c['saturation_onset_G']:.0f} G"),
            ("conversion (T+X+Y+Z)", f"{c['conversion_ms']:.3f} ms ({c['rate_Hz']:.0f} Hz)"),
        ],
        "noise": [
            ("environment", f"{nz['environment_G']:.3f} G"),
            ("chip, xy / z", f"{nz['chip_xy_G']:.3f} / {nz['chip_z_G']:.3f} G"),
            ("quantisation, xy / z", f"{nz['quantisation_xy_G']:.4f} / {nz['quantisation_z_G']:.4f} G"),
            ("total, xy / z", f"{nz['total_xy_G']:.3f} / {nz['total_z_G']:.3f} G"),
        ],
    }


def _key_figures(design: "Design", data: Mapping[str, object], calibration: Mapping[str, object] | None,
                 findings: Sequence[Finding]) -> list[tuple[str, str, str]]:
    n, s = data["normal"], data["shear"]
    out = [
        ("d_rest", f"{design.d_rest_mm:.2f} mm", f"cover {design.cover_mm:.2f} mm, skin {design.skin_mm:.2f} mm"),
        ("Bz at rest", f"{data['field']['Bz_rest_G']:.1f} G", f"noise {data['noise_G']['total_z_G']:.3f} G RMS (z)"),
        ("normal sensitivity", f"{n['sensitivity_G_per_N'][0]:.1f} – {n['sensitivity_G_per_N'][1]:.1f} G/N",
         f"resolution {n['resolution_mN']:.2f} mN"),
        ("normal range", f"{n['range_N']:.3f} N", f"ends at: {n['range_limit']}"),
        ("shear sensitivity", f"{s['sensitivity_G_per_N'][0]:.1f} – {s['sensitivity_G_per_N'][1]:.1f} G/N",
         f"resolution {s['resolution_mN']:.2f} mN"),
        ("shear range", f"{s['range_N']:.3f} N", f"ends at: {s['range_limit']}"),
        ("silicone per part", f"{design.elastomer_volume_mm3 / 1000:.3f} mL",
         f"{design.spec.mould.cavities} cavit{'y' if design.spec.mould.cavities == 1 else 'ies'} per mould"),
    ]
    if calibration is not None:
        err = calibration["errors"]
        out.append(("calibration, held-out RMS", f"{1000 * err['Fz_N']['rms_holdout']:.2f} mN (Fz)",
                    f"{1000 * err['Fr_N']['rms_holdout']:.2f} mN (Fr), {calibration['scan']['source']} scan"))
    counts = {sev: sum(f.severity is sev for f in findings) for sev in _SEVERITY_ORDER}
    out.append(("design checks", f"{counts[Severity.ERROR]} errors, {counts[Severity.WARNING]} warnings",
                f"{counts[Severity.INFO]} notes"))
    return out


def _models(data: Mapping[str, object]) -> list[dict[str, str]]:
    rows = []
    for family, m in data["models"].items():
        err = m.get("relative_error")
        rows.append({"family": family, "model": str(m["model"]), "chosen_by": str(m["chosen_by"]),
                     "error": "not measured here" if err is None else f"{100 * float(err):.2g} %",
                     "detail": str(m["detail"])})
    return rows


def _calibration(calibration: Mapping[str, object] | None, tolerance_mN: float) -> dict[str, object] | None:
    if calibration is None:
        return None
    err = calibration["errors"]
    rows = [(FORCE_NAMES[k], *(f"{1000 * err[k][what]:.2f}" for what in ("rms_fit", "rms_holdout", "max_holdout")))
            for k in ("Fz_N", "Fr_N")]
    worst = max(1000 * err[k]["rms_holdout"] for k in ("Fz_N", "Fr_N"))
    scan = calibration["scan"]
    return {"method": str(calibration["method"]), "order": calibration["order"], "folds": err["folds"],
            "source": str(scan["source"]), "rows": scan["rows"], "sha": str(scan["sha256"]), "errors": rows,
            "tolerance_mN": f"{tolerance_mN:g}", "meets": worst <= tolerance_mN,
            "provisional": scan["source"] == "simulated"}


def _findings(findings: Sequence[Finding]) -> list[dict[str, object]]:
    return [{"severity": sev.value, "items": [f for f in findings if f.severity is sev]} for sev in _SEVERITY_ORDER]


def _size(n: int | None) -> str:
    if n is None:
        return ""
    return f"{n} B" if n < 1000 else f"{n / 1000:.1f} kB" if n < 1_000_000 else f"{n / 1e6:.2f} MB"


def _files(artifacts: Sequence["Artifact"], extra: Sequence[tuple[str, str]]) -> list[dict[str, object]]:
    """The file table grouped by top folder (the build's root first), each row linked relatively."""
    rows = [(a.path, a.description, len(a.data)) for a in artifacts] + [(p, d, None) for p, d in extra]
    seen: set[str] = set()
    for path, _, _ in rows:
        if path in seen:
            raise ValueError(f"file {path!r} is listed twice (in the artifacts and in extra_files?)")
        if path.startswith("/") or any(part in {"", ".", ".."} for part in path.split("/")) or "\\" in path:
            raise ValueError(f"file {path!r} must be a relative POSIX path inside the build folder")
        seen.add(path)
    groups: dict[str, list[dict[str, object]]] = {}
    for path, description, size in sorted(rows, key=lambda r: ("/" in r[0], r[0])):
        folder = path.split("/", 1)[0] + "/" if "/" in path else ""
        groups.setdefault(folder, []).append({"path": path, "href": _href(path), "description": description,
                                              "size": _size(size)})
    return [{"folder": k, "rows": v} for k, v in groups.items()]


# ---------------------------------------------------------------------------------------------------
# Figures from the build


def _plot_figures(artifacts: Sequence["Artifact"], folder: str) -> list[Figure]:
    """The build's SVG plots under ``folder``, each linked to its SVG and PNG files."""
    paths = {a.path for a in artifacts}
    out = []
    for a in artifacts:
        if a.path.startswith(folder) and a.path.endswith(".svg"):
            stem = a.path[:-4]
            links = ((_href(a.path), "SVG"),) + (((_href(stem + ".png"), "PNG"),) if stem + ".png" in paths else ())
            caption = a.description.removesuffix(", SVG")
            out.append(Figure("fig-" + stem.replace("/", "-"), PurePosixPath(stem).name.replace("_", " "), caption,
                              _svg_uri(a.data, a.path), links))
    return out


def _part_figures(meshes: Mapping[str, "trimesh.Trimesh"], artifacts: Sequence["Artifact"]) -> list[Figure]:
    by_path = {a.path: a for a in artifacts}
    out = []
    for stem in [s for s in PART_VIEWS if s in meshes] + sorted(set(meshes) - set(PART_VIEWS)):
        mesh = meshes[stem]
        size = np.ptp(np.asarray(mesh.bounds), axis=0)
        stl = by_path.get(f"{stem}.stl")
        what = stl.description.removesuffix(", STL") if stl else stem
        caption = (f"{what}. Bounding box {size[0]:.2f} x {size[1]:.2f} x {size[2]:.2f} mm, "
                   f"volume {abs(float(mesh.volume)) / 1000:.3f} mL, {len(mesh.faces)} triangles"
                   f"{'' if mesh.is_watertight else ', NOT watertight'}.")
        links = tuple((_href(p), p.rsplit('.', 1)[1].upper()) for p in (f"{stem}.stl", f"{stem}.step") if p in by_path)
        out.append(Figure(f"part-{stem}", PART_VIEWS.get(stem, (stem, ""))[0], caption,
                          _data_uri(part_figure(stem, mesh), "image/png"), links))
    return out


def _board_parts(board: "Board") -> list[dict[str, str]]:
    """What stands on the board: reference, value, side and footprint, in reference order."""
    return [{"ref": p.ref, "value": p.value, "side": "bottom" if p.bottom else "top", "footprint": p.footprint.name}
            for p in sorted(board.parts, key=lambda p: (p.ref[0], int("0" + "".join(filter(str.isdigit, p.ref)))))]


def _board_figure(design: "Design", board: "Board", artifacts: Sequence["Artifact"]) -> Figure:
    pcb_spec = design.spec.pcb
    pcb = f"pcb/{design.spec.name}.kicad_pcb"
    files = ((pcb, "KiCad board"), (f"pcb/{design.spec.name}.kicad_pro", "project"))
    links = tuple((_href(p), label) for p, label in files if p in {a.path for a in artifacts})
    unrouted = f" Unrouted: {', '.join(board.unrouted)}." if board.unrouted else ""
    caption = (f"{pcb_spec.width_mm:g} x {pcb_spec.height_mm:g} mm, {board.thickness_mm:g} mm thick, I2C address "
               f"0x{board.address:02X}; top copper red, bottom copper blue (seen through the board), vias gold, "
               f"drilled holes white, the mounting pad's disc dashed (nothing but the chip stands inside it on top)."
               + unrouted)
    svg = board_svg(board, pcb_spec.via_drill_mm)
    return Figure("board", "Breakout board", caption, _data_uri(svg, "image/svg+xml"), links)


# ---------------------------------------------------------------------------------------------------
# The page


def render_report(spec: "Spec", design: "Design", findings: Sequence[Finding], artifacts: Sequence["Artifact"],
                  prediction: "Prediction", calibration: Mapping[str, object] | None,
                  meshes: Mapping[str, "trimesh.Trimesh"], extra_files: Iterable[tuple[str, str]] = (),
                  board: "Board | None" = None) -> bytes:
    """report.html as UTF-8 bytes: one self-contained page for the build (module doc).

    ``artifacts``: what the build writes besides the report (``magfab.build.Artifact``: path, data,
    description); ``extra_files``: (path, description) of files written with or after the report (the
    report itself, the checklists, the BOM, the manifest), listed and linked too. ``calibration`` is the
    calibration.json content (or None); ``meshes`` the tessellated parts by file stem, at least
    ``elastomer`` and ``pad`` (the stack-up is drawn from their sections). ``board`` defaults to
    ``magfab.pcb.board(design)``."""
    from .templating import render

    missing = {"elastomer", "pad"} - set(meshes)
    if missing:
        raise ValueError(f"render_report needs the meshes of {', '.join(sorted(missing))} "
                         "(the stack-up is cut from them)")
    extra = [(str(p), str(d)) for p, d in extra_files]
    files = _files(artifacts, extra)
    listed = {a.path for a in artifacts} | {p for p, _ in extra}
    if board is None:
        from ..pcb import board as make_board

        board = make_board(design)
    data = prediction.data
    stack = Figure("stackup", "Stack-up", "The assembled sensor at rest, cut through its axis (board frame). The "
                   "magnet rests against the pocket roof, north pole up; the dashed line is where its lower face "
                   "sits at d_min.", _data_uri(stackup_figure(design, meshes), "image/svg+xml"))
    html = render(
        "report/report.html.j2",
        spec=spec, version=__version__, sha256=spec.sha256(), design=design,
        bench=[{"href": _href(p), "path": p, "what": w} for p, w in BENCH_FILES if p in listed],
        key_figures=_key_figures(design, data, calibration, findings),
        stack=stack, stack_rows=_stack_rows(design), heights=_heights(design),
        parts=_part_figures(meshes, artifacts), board=_board_figure(design, board, artifacts),
        board_parts=_board_parts(board),
        tables=_prediction_tables(data), plots=_plot_figures(artifacts, "plots/"),
        models=_models(data), calibration=_calibration(calibration, spec.calibration.tolerance_mN),
        calibration_plots=_plot_figures(artifacts, "calibration/"),
        findings=_findings(findings), spec_sections=_spec_sections(spec), files=files,
        file_count=sum(len(g["rows"]) for g in files), spec_json="spec.json" if "spec.json" in listed else "",
    )
    return html.encode("utf-8")
