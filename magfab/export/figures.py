"""Prediction plots as SVG and PNG bytes (matplotlib, Agg), byte-identical for the same prediction.

matplotlib is imported inside :func:`figures`, so importing this module is cheap.
"""

from __future__ import annotations

import io
import math
from typing import TYPE_CHECKING, Callable, Mapping, Sequence

import numpy as np

from ..models import field as fieldmod

if TYPE_CHECKING:
    from ..design import Design
    from ..models.predict import Prediction

BAND_COLOURS = {"soft": "#1f77b4", "nominal": "#2ca02c", "stiff": "#d62728"}

#: What each plot shows, by file stem: the report's captions and the file table's descriptions.
CAPTIONS = {"field_axis": "Bz and dBz/dz on the axis, d_min and d_max marked",
            "field_contours": "Bz and Br contours in the z-r plane with the magnet's travel envelope",
            "force": "force and stiffness against indentation, soft / nominal / stiff material",
            "sensitivity": "sensitivity and resolution against deformation, normal and shear",
            "speed_accuracy": "every model's error against its time (bench/models.py figures)"}


def _plain_log_ticks(fig) -> None:
    """Log axes labelled in plain numbers (100, 0.5), not 10^2 or 2x10^0: easier to read, and no mathtext to
    lay out (a quarter of the plots' time). Minor ticks are labelled only on an axis spanning under 1.5 decades,
    where the major ticks alone would leave it bare."""
    from matplotlib import ticker

    plain = ticker.FuncFormatter(lambda v, _pos: f"{v:g}")
    for ax in fig.get_axes():
        for axis, limits in ((ax.xaxis, ax.get_xlim()), (ax.yaxis, ax.get_ylim())):
            if axis.get_scale() != "log":
                continue
            axis.set_major_formatter(plain)
            lo, hi = sorted(limits)
            narrow = lo > 0 and math.log10(hi / lo) < 1.5
            axis.set_minor_formatter(plain if narrow else ticker.NullFormatter())


def _render(fig) -> tuple[bytes, bytes]:
    _plain_log_ticks(fig)
    svg, png = io.BytesIO(), io.BytesIO()
    fig.savefig(svg, format="svg", metadata={"Date": None, "Creator": None})
    fig.savefig(png, format="png", dpi=110, metadata={"Software": None})
    return svg.getvalue(), png.getvalue()


def _axis_field(plt, design: "Design", pred: "Prediction"):
    magnet = fieldmod.Magnet.from_spec(design.spec)
    sen = design.spec.sensor
    d = np.linspace(max(0.3, 0.25 * sen.d_min_mm), 1.5 * design.d_rest_mm, 300)
    bz = fieldmod.bz_br(magnet, d, 0.0, model=fieldmod.FieldModel.EXACT)[0]
    grad = fieldmod.dbz_dz(magnet, d, 0.0, model=fieldmod.FieldModel.EXACT)
    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    ax.plot(d, bz, color="#1f77b4", label="Bz")
    ax.set_xlabel("magnet lower face to sensing point d, mm")
    ax.set_ylabel("Bz on the axis, G", color="#1f77b4")
    ax.set_yscale("log")
    ax2 = ax.twinx()
    ax2.plot(d, grad, color="#ff7f0e", label="dBz/dz")
    ax2.set_ylabel("dBz/dz, G/mm", color="#ff7f0e")
    ax2.set_yscale("log")
    chip = pred.chip
    ax.axhline(chip.full_scale_z_G, color="0.4", lw=0.8, ls=":")
    ax.text(d[-1], chip.full_scale_z_G, " chip full scale (Z)", va="bottom", ha="right", fontsize=8)
    for x, name in ((sen.d_min_mm, "d_min"), (design.d_rest_mm, "d_max")):
        ax.axvline(x, color="k", lw=0.8, ls="--")
        ax.text(x, ax.get_ylim()[1], f" {name} {x:g}", va="top", fontsize=8)
    ax.set_title(f"{design.spec.name}: field on the axis ({design.spec.magnet.grade}, "
                 f"{design.spec.magnet.diameter_mm:g} x {design.spec.magnet.height_mm:g} mm)", fontsize=10)
    fig.tight_layout()
    return fig


def _contours(plt, design: "Design", pred: "Prediction"):
    magnet = fieldmod.Magnet.from_spec(design.spec)
    sen = design.spec.sensor
    rm = design.magnet_radius_mm
    d = np.linspace(0.5 * sen.d_min_mm, 1.3 * design.d_rest_mm, 90)
    r = np.linspace(0.0, 2.5 * rm, 70)
    D, Rr = np.meshgrid(d, r, indexing="ij")
    bz, br = fieldmod.bz_br(magnet, D, Rr, model=fieldmod.FieldModel.EXACT)
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 4.0), sharey=True)
    for ax, values, name in ((axes[0], bz, "Bz"), (axes[1], br, "Br")):
        levels = np.geomspace(max(float(np.abs(values).max()) * 1e-3, 1e-3), float(np.abs(values).max()), 12)
        cs = ax.contour(Rr, D, np.abs(values), levels=levels, cmap="viridis", linewidths=0.8)
        ax.clabel(cs, fmt="%.0f", fontsize=6)
        ax.add_patch(plt.Rectangle((0.0, sen.d_min_mm), rm, design.d_rest_mm - sen.d_min_mm, fill=False,
                                   ec="r", lw=1.2, ls="--"))
        ax.set_xlabel("radial offset r, mm")
        ax.set_title(f"|{name}|, G (dashed: the magnet's travel envelope)", fontsize=9)
        ax.invert_yaxis()
    axes[0].set_ylabel("gap d below the magnet, mm")
    fig.tight_layout()
    return fig


def _force(plt, design: "Design", pred: "Prediction"):
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 4.0))
    for k, c in pred.curves.items():
        axes[0].plot(c.indentation_mm, c.force_N, color=BAND_COLOURS[k], label=f"{k} (mu {c.mu_kPa:g} kPa)")
        axes[1].plot(c.indentation_mm, c.stiffness_N_per_mm, color=BAND_COLOURS[k], label=k)
    u_max = pred.normal.travel_mm
    idx = np.interp(u_max, pred.arrays["u"], pred.arrays["indentation"])
    for ax in axes:
        ax.axvline(idx, color="k", lw=0.8, ls="--")
        ax.set_xlabel("indentation, mm")
    axes[0].text(idx, 0, f" range ends: {pred.normal.range_limit}", fontsize=8, rotation=90, va="bottom")
    axes[0].set_ylabel("normal force, N")
    axes[1].set_ylabel("dF/d(indentation), N/mm")
    axes[0].legend(fontsize=8)
    m = pred.model("mechanics")
    fig.suptitle(f"Elastomer ({design.spec.elastomer.material}): {m.name}, {m.detail}", fontsize=8)
    fig.tight_layout()
    return fig


def _sensitivity(plt, design: "Design", pred: "Prediction"):
    a = pred.arrays
    keep = a["in_range"]
    fig, axes = plt.subplots(1, 2, figsize=(9.0, 4.0))
    for k in BAND_COLOURS:
        axes[0].plot(a["u"][keep], a[f"sf_{k}_nominal"][keep], color=BAND_COLOURS[k], label=f"normal, {k}")
        axes[0].plot(a["u_shear"], a[f"sfs_{k}_nominal"], color=BAND_COLOURS[k], ls="--", marker=".",
                     label=f"shear, {k}")
        axes[1].plot(a["u"][keep], a[f"res_{k}_nominal"][keep], color=BAND_COLOURS[k], label=f"normal, {k}")
    axes[0].set_xlabel("magnet axial travel (shear: small lateral load under that normal preload), mm")
    axes[0].set_ylabel("sensitivity S_F, G/N")
    axes[0].set_yscale("log")
    axes[0].legend(fontsize=7)
    axes[1].set_xlabel("magnet axial travel, mm")
    axes[1].set_ylabel(f"resolution at {pred.noise.total_z_G:.3g} G noise, mN")
    axes[1].set_yscale("log")
    axes[1].legend(fontsize=7)
    fig.suptitle("Sensitivity and resolution against deformation (nominal remanence)", fontsize=9)
    fig.tight_layout()
    return fig


def _speed_accuracy(plt, design: "Design", pred: "Prediction", table: Sequence[Mapping[str, object]]):
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    markers = {"field": "o", "mechanics": "s", "shear": "^"}
    used = {m.family: m for m in pred.models}
    mesh = pred.curves["nominal"].mesh_mm

    def chosen(row: Mapping[str, object]) -> bool:
        m = used.get(str(row["family"]))
        if m is None or m.name != row["model"]:
            return False
        if row["family"] == "mechanics":
            return row.get("mesh_mm") in (None, mesh)
        return row["family"] != "shear" or row.get("mesh_mm") == mesh  # the shear is probed on the chosen mesh

    for row in table:
        err = max(float(row["error"]), 1e-16)
        ax.scatter(float(row["time_s"]), err, marker=markers.get(str(row["family"]), "x"),
                   edgecolors="k" if chosen(row) else "none", linewidths=1.5, s=40)
        ax.annotate(str(row["label"]), (float(row["time_s"]), err), fontsize=6, xytext=(3, 3),
                    textcoords="offset points")
    tol = design.spec.predict.tolerance_pct / 100.0
    ax.axhline(tol, color="r", lw=0.8, ls="--")
    ax.text(ax.get_xlim()[0], tol, " spec tolerance", color="r", fontsize=7, va="bottom")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("time, s (field: per 10^5 points; elastomer: per curve)")
    ax.set_ylabel("max relative error against the reference")
    ax.set_title("Speed against accuracy (bench/models.py on MagOne; ringed: used in this build)", fontsize=9)
    fig.tight_layout()
    return fig


def figures(design: "Design", pred: "Prediction", bench_table: Sequence[Mapping[str, object]] = ()) -> dict[str, bytes]:
    """{file name: bytes} for every prediction plot, SVG and PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    makers: dict[str, Callable] = {"field_axis": _axis_field, "field_contours": _contours, "force": _force,
                                   "sensitivity": _sensitivity}
    out: dict[str, bytes] = {}
    with matplotlib.rc_context({"svg.hashsalt": "magfab", "svg.fonttype": "path", "path.simplify": True}):
        for name, make in makers.items():
            fig = make(plt, design, pred)
            out[f"{name}.svg"], out[f"{name}.png"] = _render(fig)
            plt.close(fig)
        if bench_table:
            fig = _speed_accuracy(plt, design, pred, bench_table)
            out["speed_accuracy.svg"], out["speed_accuracy.png"] = _render(fig)
            plt.close(fig)
    return out
