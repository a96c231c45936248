"""Drawings in section and plan: the assembled stack-up cut through its axis (matplotlib, SVG) and the
routed board from above (SVG written here), both in millimetres."""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, TypedDict
from xml.sax.saxutils import escape

import numpy as np

from ... import outline
from .render3d import section_loops

if TYPE_CHECKING:
    import trimesh

    from ...board.layout import Board
    from ...design import Design

# Imported lazily, inside the functions that use it, for speed: matplotlib takes a
# noticeable time to import, and importing this module should not.

__all__ = ["stackup_figure", "board_svg", "board_half_width", "STACK_STYLE"]


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
        pts = np.vstack([loop, loop[:1]]) + np.array([0.0, dz])
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


class _PatchStyle(TypedDict):
    """A layer's matplotlib patch keywords: face and edge colours, hatch, line width."""

    fc: str
    ec: str
    hatch: str | None
    lw: float


def _style(layer: str) -> _PatchStyle:
    fc, ec, hatch = STACK_STYLE[layer]
    return {"fc": fc, "ec": ec, "hatch": hatch, "lw": 0.7}


#: A board wider than the pad by more than this each side is drawn broken off (the drawing stays readable).
BOARD_MARGIN_SHOWN_MM = 8.0


def board_half_width(design: Design) -> tuple[float, bool]:
    """Half the width the board is drawn at, mm, and whether it is broken off: its true half-width
    (``pcb.width_mm`` / 2; the pad is centred on the board) unless that is more than
    ``BOARD_MARGIN_SHOWN_MM`` beyond the pad."""
    true = design.spec.pcb.width_mm / 2.0
    shown = design.pad_radius_mm + BOARD_MARGIN_SHOWN_MM
    return (true, False) if true <= shown else (shown, True)


def _dimension_board(ax, design: Design, half: float, broken: bool) -> None:
    """The board's width as a horizontal dimension under it (its true width, also when broken off)."""
    pcb = design.spec.pcb
    z = -pcb.thickness_mm - 0.7
    ax.annotate("", xy=(-half, z), xytext=(half, z),
                arrowprops={"arrowstyle": "<|-|>", "lw": 0.7, "color": "k", "shrinkA": 0, "shrinkB": 0,
                            "mutation_scale": 6})
    note = ", broken off" if broken else ""
    ax.text(0.0, z - 0.25, f"board {pcb.width_mm:g} mm wide{note} ({pcb.width_mm:g} x {pcb.height_mm:g} x "
            f"{pcb.thickness_mm:g} mm)", fontsize=7, ha="center", va="top", bbox={"fc": "w", "ec": "none", "pad": 0.5})


def _draw_stack(ax, design: Design, meshes: Mapping[str, trimesh.Trimesh]) -> None:
    """The layers in section: board, chip, pad (mesh section), glue, elastomer (mesh section), magnet."""
    from matplotlib.patches import Rectangle

    d = design
    half, broken = board_half_width(design)
    t = d.spec.pcb.thickness_mm
    ax.add_patch(Rectangle((-half, -t), 2 * half, t, **_style("board")))
    if broken:  # break marks: a zigzag across each cut end
        zig = np.array([-t - 0.25, -0.75 * t, -0.5 * t, -0.25 * t, 0.25])
        for side in (-1.0, 1.0):
            xs = side * half + 0.25 * np.array([0.0, 1.0, -1.0, 1.0, 0.0])
            ax.fill_betweenx(zig, xs, side * (half + 0.6), color="w", lw=0, zorder=3)
            ax.plot(xs, zig, color=STACK_STYLE["board"][1], lw=0.8, zorder=4)
    _dimension_board(ax, design, half, broken)
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


def _dimension_stack(ax, design: Design) -> None:
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


def stackup_figure(design: Design, meshes: Mapping[str, trimesh.Trimesh]) -> bytes:
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
    half = board_half_width(design)[0] + 0.6
    left = max(half, design.pad_radius_mm + 7.0)  # room for the d_min dimension's two lines of text
    with matplotlib.rc_context({"svg.hashsalt": "magfab-report", "svg.fonttype": "path"}):
        fig, ax = plt.subplots(figsize=(8.0, 4.2))
        _draw_stack(ax, design, meshes)
        _dimension_stack(ax, design)
        ax.legend(handles=[Patch(**_style(k), label=v) for k, v in labels.items()], fontsize=7, loc="upper left",
                  bbox_to_anchor=(1.0, 1.0), frameon=False)
        ax.set_aspect("equal")
        ax.set_xlim(-left, half)
        ax.set_ylim(-spec.pcb.thickness_mm - 1.8, design.z_elastomer_base_mm + design.elastomer_height_mm + 1.5)
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


def board_svg(board: Board, via_drill_mm: float) -> bytes:
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
    if board.pad_hull:  # an array's pad: the taxels' hull grown by the pad radius

        pts = " ".join(f"{x:.4f},{y:.4f}" for x, y in outline.polygon(list(board.pad_hull), r, 72))
        out.append(f'<polygon points="{pts}" fill="none" stroke="#fff" stroke-width="0.12" '
                   'stroke-dasharray="0.6 0.4"/>')
    else:
        out.append(f'<circle cx="{cx}" cy="{cy}" r="{r}" fill="none" stroke="#fff" stroke-width="0.12" '
                   'stroke-dasharray="0.6 0.4"/>')
    for p in board.parts:
        if p.ref.startswith("H"):
            continue
        colour = "#ffd0d0" if not p.bottom else "#cfe0ff"
        out.append(f'<text x="{p.x:.3f}" y="{p.y:.3f}" font-size="0.9" text-anchor="middle" '
                   f'dominant-baseline="central" fill="{colour}">{escape(p.ref)}</text>')
    for t in board.label + board.marks:
        out.append(f'<text x="{t.x:.3f}" y="{t.y:.3f}" font-size="{t.size:.3f}" text-anchor="middle" '
                   f'dominant-baseline="central" fill="#f0f0f0">{escape(t.text)}</text>')
    out.append("</svg>\n")
    return "\n".join(out).encode("utf-8")
