"""Prediction plots as SVG and PNG bytes (matplotlib, Agg), byte-identical for the same prediction.

matplotlib is imported inside :func:`figures`, so importing this module is cheap.
"""

from __future__ import annotations

import io
import json
import math
import re
import textwrap
from collections.abc import Callable, Collection, Mapping, Sequence
from importlib.resources import files
from typing import TYPE_CHECKING, Any

import numpy as np

from ..models import field as fieldmod
from ..models.predict import MODEL_REACH

if TYPE_CHECKING:
    from matplotlib.figure import Figure
    from matplotlib.typing import RcKeyType

    from ..design import Design
    from ..models.predict import Prediction

# Imported lazily, inside the functions that use it, for speed: matplotlib takes a
# noticeable time to import, and importing this module should not.

BAND_COLOURS = {"soft": "#1f77b4", "nominal": "#2ca02c", "stiff": "#d62728"}
#: The range limits that do not end the range, marked on the force plot (the one that ends it is black).
LIMIT_COLOURS = ("#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22")

#: What each plot shows, by file stem: the report's captions and the file table's descriptions. Each says what
#: is drawn, no more (tests/export/test_figures.py checks the figures against these claims).
CAPTIONS = {
    "field_axis": "Bz and |dBz/dz| on the axis against the gap d, the chip's Z full scale, d_min and d_max marked",
    "field_contours": "|Bz| and |Br| in the z-r plane, filled log contours each with its colour bar, where Bz "
                      "changes sign dotted and the magnet's travel envelope dashed",
    "force": "force and stiffness against indentation, soft / nominal / stiff material, where the normal range "
             "ends and why marked, and where each other limit (d_min, the chip's full scale, invertibility, the scan "
             "depth, a stretch, the material law's data end, the FE stopping) would bind",
    "sensitivity": "sensitivity and resolution against the magnet's axial travel, normal (at the Z noise) and shear "
                   "(at the XY noise), soft / nominal / stiff material, where the normal range ends marked",
    "speed_accuracy": "each model's error against its time (bench/models.py figures), one panel per model family and "
                      "cost unit, with its Pareto front, the spec's tolerance and the reference (error 0 by "
                      "definition) on a strip of its own",
}


def _plain_log_ticks(fig) -> None:
    """Log axes labelled in plain numbers (100, 0.5), not 10^2 or 2x10^0: easier to read, and no mathtext to
    lay out (a quarter of the plots' time). Minor ticks are labelled on an axis spanning under 1.5 decades, and
    only at 2 and 5 under 3 decades, where the major ticks alone would leave it bare."""
    from matplotlib import ticker

    plain = ticker.FuncFormatter(lambda v, _pos: f"{v:g}")

    def two_five(v: float, _pos) -> str:
        return f"{v:g}" if v > 0 and round(v / 10 ** math.floor(math.log10(v) + 1e-9)) in (2, 5) else ""

    for ax in fig.get_axes():
        for axis, limits in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
            if axis.get_scale() != "log":
                continue
            axis.set_major_formatter(plain)
            lo, hi = sorted(limits)
            decades = math.log10(hi / lo) if lo > 0 else math.inf
            minor = plain if decades < 1.5 else ticker.FuncFormatter(two_five) if decades < 3 else None
            axis.set_minor_formatter(minor or ticker.NullFormatter())


#: matplotlib settings every plot is drawn and saved under: the SVG's ids from a fixed salt (byte-identical
#: rebuilds), text as paths (no font needed to view it).
RC: dict[RcKeyType, object] = {"svg.hashsalt": "magfab", "svg.fonttype": "path", "path.simplify": True}


def _legend_below(fig, handles: Sequence, ncol: int, fontsize: float = 7.5) -> None:
    """The figure's one legend, below the panels (constrained layout makes room): never over the data."""
    fig.legend(handles=handles, loc="outside lower center", ncol=ncol, fontsize=fontsize, frameon=False)


def _freeze_layout(fig) -> None:
    """Lay the figure out once (constrained layout, plain log ticks first: their widths count), then fix it: the
    SVG and PNG saves then skip the layout, which is most of a plot's time, and labels placed against it stay put."""
    _plain_log_ticks(fig)
    engine = fig.get_layout_engine()
    if engine is not None:
        engine.execute(fig)
        fig.set_layout_engine("none")


def _render(fig) -> tuple[bytes, bytes]:
    _freeze_layout(fig)
    svg, png = io.BytesIO(), io.BytesIO()
    fig.savefig(svg, format="svg", metadata={"Date": None, "Creator": None})
    fig.savefig(png, format="png", dpi=110, metadata={"Software": None})
    return svg.getvalue(), png.getvalue()


def _axis_field(plt, design: Design, pred: Prediction):
    from matplotlib.lines import Line2D

    magnet = fieldmod.Magnet.from_design(design)
    sen = design.spec.sensor
    d = np.linspace(max(0.3, 0.25 * sen.d_min_mm), 1.5 * design.d_rest_mm, 300)
    bz = fieldmod.bz_br(magnet, d, 0.0, model=fieldmod.FieldModel.EXACT)[0]
    grad = fieldmod.dbz_dz(magnet, d, 0.0, model=fieldmod.FieldModel.EXACT)
    fig, ax = plt.subplots(figsize=(6.4, 4.3), layout="constrained")
    ax.plot(d, bz, color="#1f77b4")
    ax.set_xlabel("magnet lower face to sensing point d, mm")
    ax.set_ylabel("Bz on the axis, G", color="#1f77b4")
    ax.set_yscale("log")
    ax2 = ax.twinx()
    ax2.plot(d, np.abs(grad), color="#ff7f0e")
    ax2.set_ylabel("|dBz/dz|, G/mm", color="#ff7f0e")
    ax2.set_yscale("log")
    chip = pred.chip
    ax.axhline(chip.full_scale_z_G, color="0.4", lw=0.8, ls=":")
    for x, name in ((sen.d_min_mm, "d_min"), (design.d_rest_mm, "d_max")):
        ax.axvline(x, color="k", lw=0.8, ls="--")
        ax.text(x, ax.get_ylim()[1], f" {name} {x:g}", va="top", fontsize=8)
    ax.set_title(f"{design.spec.name}: field on the axis ({design.spec.magnet.grade}, "
                 f"{design.spec.magnet.diameter_mm:g} x {design.spec.magnet.height_mm:g} mm)", fontsize=10)
    _legend_below(fig, [Line2D([], [], color="#1f77b4", label="Bz (left axis)"),
                        Line2D([], [], color="#ff7f0e", label="|dBz/dz| (right axis)"),
                        Line2D([], [], color="0.4", lw=0.8, ls=":",
                               label=f"chip Z full scale {chip.full_scale_z_G:g} G"),
                        Line2D([], [], color="k", lw=0.8, ls="--", label="d_min, d_max (spec, design)")], ncol=2)
    return fig


def _nice_log_levels(lo: float, hi: float) -> np.ndarray:
    """Contour levels on the 1-2-5 sequence from the last at or below ``lo`` to the first at or above ``hi``, so
    the colour bar reads in round numbers."""
    decades = range(math.floor(math.log10(lo)) - 1, math.ceil(math.log10(hi)) + 1)
    steps = np.array([m * 10.0 ** e for e in decades for m in (1.0, 2.0, 5.0)])
    first = max(0, np.searchsorted(steps, lo * (1 + 1e-12), "right") - 1)
    return steps[first:np.searchsorted(steps, hi * (1 - 1e-12)) + 1]


def _contours(plt, design: Design, pred: Prediction):
    """|Bz| and |Br| filled on log levels over three decades, each panel with its colour bar; no inline labels
    (they piled up where Bz changes sign), the sign change drawn as its own dotted line."""
    from matplotlib import ticker
    from matplotlib.colors import LogNorm
    from matplotlib.lines import Line2D

    magnet = fieldmod.Magnet.from_design(design)
    sen = design.spec.sensor
    rm = design.magnet_radius_mm
    d = np.linspace(0.5 * sen.d_min_mm, 1.3 * design.d_rest_mm, 90)
    r = np.linspace(0.0, 2.5 * rm, 70)
    D, Rr = np.meshgrid(d, r, indexing="ij")
    bz, br = fieldmod.bz_br(magnet, D, Rr, model=fieldmod.FieldModel.EXACT)
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 4.4), sharey=True, layout="constrained")
    for ax, values, name in ((axes[0], bz, "Bz"), (axes[1], br, "Br")):
        levels = _nice_log_levels(1e-3 * float(np.abs(values).max()), float(np.abs(values).max()))
        cs = ax.contourf(Rr, D, np.maximum(np.abs(values), 0.1 * levels[0]), levels=levels, norm=LogNorm(),
                         cmap="viridis", extend="min")
        bar = fig.colorbar(cs, ax=ax, shrink=0.95, pad=0.02, ticks=levels)
        bar.set_label(f"|{name}|, G (the triangle: below {levels[0]:g} G)", fontsize=8)
        bar.ax.tick_params(labelsize=7)
        bar.ax.yaxis.set_major_formatter(ticker.FuncFormatter(lambda v, _pos: f"{v:g}"))
        bar.ax.yaxis.set_minor_formatter(ticker.NullFormatter())
        ax.add_patch(plt.Rectangle((0.0, sen.d_min_mm), rm, design.d_rest_mm - sen.d_min_mm, fill=False,
                                   ec="r", lw=1.2, ls="--"))
        ax.set_xlabel("radial offset r, mm")
        ax.set_title(f"|{name}|", fontsize=9)
    axes[0].contour(Rr, D, bz, levels=[0.0], colors="w", linewidths=1.0, linestyles=":")
    axes[0].set_ylabel("gap d below the magnet, mm")
    axes[0].invert_yaxis()  # shared: once inverts both
    _legend_below(fig, [Line2D([], [], color="r", lw=1.2, ls="--", label="the magnet's travel envelope "
                               "(r up to its radius, d from d_min to d_max)"),
                        Line2D([], [], color="0.3", lw=1.0, ls=":",
                               label="Bz = 0 (Bz changes sign; white in the panel)")],
                  ncol=1)
    return fig


def _force(plt, design: Design, pred: Prediction):
    from matplotlib.lines import Line2D

    fig, axes = plt.subplots(1, 2, figsize=(9.0, 4.6), layout="constrained")
    for k, c in pred.curves.items():
        axes[0].plot(c.indentation_mm, c.force_N, color=BAND_COLOURS[k])
        axes[1].plot(c.indentation_mm, c.stiffness_N_per_mm, color=BAND_COLOURS[k])
    u, indentation = pred.arrays["u"], pred.arrays["indentation"]
    for ax in axes:
        ax.set_xlabel("indentation, mm")
    axes[0].set_ylabel("normal force, N")
    axes[1].set_ylabel("dF/d(indentation), N/mm")
    m = pred.model("mechanics")
    fig.suptitle(textwrap.fill(f"Elastomer ({design.spec.elastomer.material}): {m.name}, {m.detail}", 150), fontsize=7)
    handles = [Line2D([], [], color=BAND_COLOURS[k], label=f"{k} (mu {c.mu_kPa:g} kPa)")
               for k, c in pred.curves.items()]
    # Every limit of the range, each where it would bind (the first ends the range; a model's reach is marked so)
    n = pred.normal
    for i, (label, travel) in enumerate(sorted(n.range_limits_travel_mm.items(), key=lambda kv: kv[1])):
        binding = label == n.range_limit
        colour, lw, ls = ("k", 1.0, "--") if binding else (LIMIT_COLOURS[i % len(LIMIT_COLOURS)], 0.8, ":")
        what = f"{label}{' (model reach)' if label in MODEL_REACH else ''}"
        if travel <= float(u[-1]) + 1e-9:
            at = float(np.interp(travel, u, indentation))
            for ax in axes:
                ax.axvline(at, color=colour, lw=lw, ls=ls)
            text = f"{'range ends: ' if binding else ''}{what}, {at:.2f} mm"
        else:
            text = f"{what}: past the curve ({travel:.2f} mm of magnet travel)"
        handles.append(Line2D([], [], color=colour, lw=lw, ls=ls, label=text))
    _legend_below(fig, handles, ncol=3)
    return fig


def _sensitivity(plt, design: Design, pred: Prediction):
    """Normal (solid) and shear (dashed, dots where solved) against the magnet's axial travel, both panels; the
    resolution is the noise over the sensitivity: Z noise for the normal force, XY noise for the shear."""
    from matplotlib.lines import Line2D

    a, noise = pred.arrays, pred.noise
    keep = a["in_range"]
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 4.6), layout="constrained")
    for k, colour in BAND_COLOURS.items():
        shear = np.abs(a[f"sfs_{k}_nominal"])
        axes[0].plot(a["u"][keep], a[f"sf_{k}_nominal"][keep], color=colour)
        axes[0].plot(a["u_shear"], shear, color=colour, ls="--", marker=".")
        axes[1].plot(a["u"][keep], a[f"res_{k}_nominal"][keep], color=colour)
        axes[1].plot(a["u_shear"], 1000.0 * noise.total_xy_G / shear, color=colour, ls="--", marker=".")
    for ax in axes:
        ax.axvline(pred.normal.travel_mm, color="k", lw=0.8, ls=":")
        ax.set_xlabel("magnet axial travel, mm")
        ax.set_yscale("log")
    axes[0].set_ylabel("sensitivity, G/N")
    axes[1].set_ylabel("resolution (noise / sensitivity), mN")
    fig.suptitle("Sensitivity and resolution against deformation (nominal remanence)", fontsize=9)
    handles = [Line2D([], [], color=c, label=f"{k} material") for k, c in BAND_COLOURS.items()]
    handles += [Line2D([], [], color="0.3", label=f"normal: dBz/dFz, Z noise {noise.total_z_G:.3g} G"),
                Line2D([], [], color="0.3", ls="--", marker=".", label="shear under that normal preload: dBr/dFx, "
                       f"XY noise {noise.total_xy_G:.3g} G"),
                Line2D([], [], color="k", lw=0.8, ls=":", label=f"normal range ends ({pred.normal.range_parts()[1]})")]
    _legend_below(fig, handles, ncol=3)
    return fig


#: Speed-accuracy panels: the family's title and colour; FE-type models (a mesh in the label) get squares.
FAMILY_STYLE = {"field": ("Magnetic field", "#1f77b4"), "mechanics": ("Elastomer, normal force curve", "#2ca02c"),
                "shear": ("Shear", "#9467bd")}
MESH_MODELS = ("fe", "surface")


def bench_panels(table: Sequence[Mapping[str, object]]) -> list[tuple[str, str, str, list[Mapping[str, object]]]]:
    """The bench table split into panels, in its order: (family, reference, cost unit, rows) per family, reference
    and unit, so no panel's time axis mixes units (the shear family has a stiffness and a surface-sensitivity
    reference, each with its own unit)."""
    panels: dict[tuple[str, str, str], list[Mapping[str, object]]] = {}
    for row in table:
        key = (str(row["family"]), str(row.get("reference", "")), str(row.get("unit", "")))
        panels.setdefault(key, []).append(row)
    return [(*key, rows) for key, rows in panels.items()]


def is_reference(row: Mapping[str, Any]) -> bool:
    """A reference row: its error is 0 by definition (it is what the others are measured against)."""
    return float(row["error"]) == 0.0


def pareto_front(points: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    """The (time, error) points no other point beats on both: sorted by time, each more accurate than all faster."""
    front: list[tuple[float, float]] = []
    for t, e in sorted(points):
        if not front or e < front[-1][1]:
            front.append((t, e))
    return front


def _plain_unit(unit: str) -> str:
    """'per 10^5 points' -> 'per 100,000 points' (no mathtext)."""
    return re.sub(r"10\^(\d+)", lambda m: f"{10 ** int(m[1]):,}", unit)


def _place_labels(fig, ax, items: Sequence[tuple[float, float, str]]) -> None:
    """Label each (x, y) point with its text where the text overlaps no other label and no marker and stays in
    the axes and, beside the point, nearer it than any other point: the first of a ring of offsets that fits, farther
    rings with a leader line to the point, else the least overlapping. Deterministic; needs the final layout
    (:func:`_freeze_layout`)."""
    from matplotlib.text import Text

    renderer = fig.canvas.get_renderer()
    frame = ax.get_window_extent(renderer)
    pts = ax.transData.transform([(x, y) for x, y, _ in items])
    px = fig.dpi / 72.0
    markers = [(x - 5 * px, y - 5 * px, x + 5 * px, y + 5 * px) for x, y in pts]
    placed: list[tuple[float, float, float, float]] = []
    ring = [(1, 1, "left", "bottom"), (1, -1, "left", "top"), (-1, 1, "right", "bottom"), (-1, -1, "right", "top"),
            (0, 1.4, "center", "bottom"), (0, -1.4, "center", "top"), (1.4, 0, "left", "center"),
            (-1.4, 0, "right", "center")]

    def overlap(a, b) -> float:
        w, h = min(a[2], b[2]) - max(a[0], b[0]), min(a[3], b[3]) - max(a[1], b[1])
        return w * h if w > 0 and h > 0 else 0.0

    def gap(box, q) -> float:
        return math.hypot(max(box[0] - q[0], 0.0, q[0] - box[2]), max(box[1] - q[1], 0.0, q[1] - box[3]))

    for i in sorted(range(len(items)), key=lambda j: (pts[j][0], pts[j][1])):
        x, y, text = items[i]
        best = None
        for scale in (4.0, 10.0, 16.0):
            for dx, dy, ha, va in ring:
                lead = {"arrowstyle": "-", "lw": 0.5, "color": "0.4", "shrinkA": 0, "shrinkB": 4}
                ann = ax.annotate(text, (x, y), xytext=(dx * scale, dy * scale), textcoords="offset points",
                                  ha=ha, va=va, fontsize=6.5, arrowprops=lead if scale > 4.0 else None)
                ann.update_positions(renderer)
                e = Text.get_window_extent(ann, renderer)  # the text alone, not its leader line
                box = (e.x0, e.y0, e.x1, e.y1)
                outside = overlap(box, (frame.x0, frame.y0, frame.x1, frame.y1)) < e.width * e.height - 1e-6
                cost = sum(overlap(box, b) for b in placed + markers[:i] + markers[i + 1:]) + (1e9 if outside else 0)
                crowded = any(gap(box, q) < 2.0 * gap(box, pts[i]) + 6 * px for j, q in enumerate(pts) if j != i)
                if scale == 4.0 and crowded:
                    cost += 1e6  # without a leader line the text would read as another point's
                if best is None or cost < best[0]:
                    if best is not None:
                        best[1].remove()
                    best = (cost, ann, box)
                else:
                    ann.remove()
                if best[0] == 0.0:
                    break
            assert best is not None  # the ring's first place is always taken
            if best[0] == 0.0:
                break
        assert best is not None
        placed.append(best[2])


def _speed_panel(ax, strip, design, family, reference, unit, rows, chosen) -> list[tuple[float, float, str]]:
    """One family's panel: measured models (shape by kind, ringed if used), their Pareto front, the tolerance; the
    reference on the strip below. Returns the points to label."""
    title, colour = FAMILY_STYLE.get(family, (family, "0.3"))
    measured = [r for r in rows if not is_reference(r)]
    for r in measured:
        ax.scatter(float(r["time_s"]), float(r["error"]), marker="s" if r["model"] in MESH_MODELS else "o", s=36,
                   color=colour, edgecolors="k" if chosen(r) else "none", linewidths=1.6, zorder=3)
    front = pareto_front([(float(r["time_s"]), float(r["error"])) for r in measured])
    if front:
        ax.plot(*zip(*front), color=colour, lw=0.9, alpha=0.6, drawstyle="steps-post", zorder=2)
    tol = design.spec.predict.tolerance_pct / 100.0
    errors = [float(r["error"]) for r in measured] + [tol]
    ax.set_yscale("log")
    ax.set_ylim(min(errors) / 5.0, max(errors) * 5.0)
    ax.axhline(tol, color="r", lw=0.8, ls="--", zorder=1)
    ax.annotate(f"{design.spec.predict.tolerance_pct:g} %", (1.0, tol), xycoords=("axes fraction", "data"),
                xytext=(2, 0), textcoords="offset points", color="r", fontsize=6.5, va="center")
    ax.set_title(f"{title} (reference: {reference})", fontsize=8.5)
    ax.set_ylabel("max relative error", fontsize=8)
    ax.tick_params(which="both", labelsize=7, labelbottom=False)
    times = [float(r["time_s"]) for r in rows]
    ax.set_xscale("log")
    ax.set_xlim(min(times) / 3.0, max(times) * 3.0)
    for r in rows:
        if is_reference(r):
            t = float(r["time_s"])
            strip.scatter(t, 0.5, marker="*", s=70, color="#e6a800", edgecolors="k", linewidths=0.5, zorder=3)
            right = math.log(t / ax.get_xlim()[0]) < 0.6 * math.log(ax.get_xlim()[1] / ax.get_xlim()[0])
            strip.annotate(f"{r['label']}: {t:.3g} s", (t, 0.5), xytext=(7 if right else -7, 0),
                           textcoords="offset points", ha="left" if right else "right", va="center", fontsize=6.5)
    strip.set_ylim(0.0, 1.0)
    strip.set_yticks([])
    strip.set_ylabel("ref.", fontsize=7, rotation=0, ha="right", va="center")
    strip.set_xlabel(f"time {_plain_unit(unit)}, s", fontsize=8)
    strip.tick_params(which="both", labelsize=7)
    ax.set_label(f"speed:{family}:{reference}")
    strip.set_label(f"reference:{family}:{reference}")
    prefix = family + " "
    return [(float(r["time_s"]), float(r["error"]), str(r["label"]).removeprefix(prefix)) for r in measured]


def _speed_legend(fig, design: Design) -> None:
    from matplotlib.lines import Line2D

    _legend_below(fig, [
        Line2D([], [], marker="o", label="closed form or surrogate, measured", color="0.45", ls="none", ms=6),
        Line2D([], [], marker="s", label="finite element (its mesh in the label), measured", color="0.45", ls="none",
               ms=6),
        Line2D([], [], marker="o", mfc="none", mec="k", mew=1.6, ls="none", ms=7, label="ringed: used in this build"),
        Line2D([], [], marker="*", color="#e6a800", mec="k", mew=0.5, ls="none", ms=9,
               label="the reference: error 0 by definition, its time only"),
        Line2D([], [], color="0.45", lw=0.9, drawstyle="steps-post", label="Pareto front of the measured models"),
        Line2D([], [], color="r", lw=0.8, ls="--",
               label=f"spec tolerance, predict.tolerance_pct = {design.spec.predict.tolerance_pct:g} %"),
    ], ncol=2)


def _speed_accuracy(plt, design: Design, pred: Prediction, table: Sequence[Mapping[str, object]]):
    used = {m.family: m for m in pred.models}
    mesh = pred.curves["nominal"].mesh_mm

    def chosen(row: Mapping[str, object]) -> bool:
        m = used.get(str(row["family"]))
        if m is None or m.name != row["model"]:
            return False
        if row["family"] == "mechanics":
            return row.get("mesh_mm") in (None, mesh)
        return row["family"] != "shear" or row.get("mesh_mm") == mesh  # the shear is probed on the chosen mesh

    panels = bench_panels(table)
    ncols = 1 if len(panels) == 1 else 2
    nrows = -(-len(panels) // ncols)
    fig = plt.figure(figsize=(10.0, 1.0 + 3.4 * nrows), layout="constrained")
    grid = fig.add_gridspec(2 * nrows, ncols, height_ratios=[5.0, 0.7] * nrows)
    labels = []
    for i, (family, reference, unit, rows) in enumerate(panels):
        row, col = divmod(i, ncols)
        ax = fig.add_subplot(grid[2 * row, col])
        strip = fig.add_subplot(grid[2 * row + 1, col], sharex=ax)
        labels.append((ax, _speed_panel(ax, strip, design, family, reference, unit, rows, chosen)))
    fig.suptitle("Speed against accuracy, measured by bench/models.py on MagOne: one panel per model family and "
                 "cost unit", fontsize=9)
    _speed_legend(fig, design)
    _freeze_layout(fig)  # final before the labels are placed against it
    for ax, items in labels:
        _place_labels(fig, ax, items)
    return fig


#: The plots a build makes from its prediction, by file stem (speed_accuracy also needs the bench table).
MAKERS: dict[str, Callable] = {"field_axis": _axis_field, "field_contours": _contours, "force": _force,
                               "sensitivity": _sensitivity}


def draw(design: Design, pred: Prediction, bench_table: Sequence[Mapping[str, object]] = (),
         names: Collection[str] | None = None) -> dict[str, Figure]:
    """{file stem: matplotlib Figure} (``names``: those stems only), open (the caller closes them); for
    :func:`figures` and the tests."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = {name: make(plt, design, pred) for name, make in MAKERS.items() if names is None or name in names}
    if bench_table and (names is None or "speed_accuracy" in names):
        out["speed_accuracy"] = _speed_accuracy(plt, design, pred, bench_table)
    return out


def packaged_rows(name: str) -> list[dict[str, Any]]:
    """The ``rows`` of a bench's table shipped in the package (magfab/NAME: bench/models.py's, bench/weights.py's),
    or [] where it is not there."""
    try:
        text = files("magfab").joinpath(name).read_text()
    except FileNotFoundError:
        return []
    return list(json.loads(text)["rows"])


def figures(design: Design, pred: Prediction, bench_table: Sequence[Mapping[str, object]] = (),
            names: Collection[str] | None = None) -> dict[str, bytes]:
    """{file name: bytes} for every prediction plot (``names``: those file stems only), SVG and PNG. Each plot's bytes
    are the same whichever others are drawn with it, so a build draws them in two processes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out: dict[str, bytes] = {}
    with matplotlib.rc_context(RC):
        for name, fig in draw(design, pred, bench_table, names).items():
            out[f"{name}.svg"], out[f"{name}.png"] = _render(fig)
            plt.close(fig)
    return out
