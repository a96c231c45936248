"""The crosstalk budget's charts (array/*.svg, *.png): the i x j map, the budget against pitch for both polarities,
and for a continuous skin the mechanical coupling against distance. Drawn and saved as the prediction plots are
(:mod:`magfab.export.figures`: fixed SVG salt, no dates), so a rebuild gives the same bytes."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from ..models.mechanics.coupling import boussinesq_ratio
from .figures import RC, _render

if TYPE_CHECKING:
    from ..models.crosstalk import Crosstalk

# Imported lazily, inside the functions that use it, for speed: matplotlib takes a
# noticeable time to import, and importing this module should not.

__all__ = ["figures", "CAPTIONS"]

CAPTIONS = {
    "crosstalk_map": "what taxel i (row) misreads, in mN, when neighbour j (column) is pressed to its normal range or "
                     "slid through its shear range's travel, after the host's compensation, plus what a load on j "
                     "moves i through a continuous skin",
    "crosstalk_pitch": "the worst taxel's misreading against pitch (the layout scaled) without the host's dynamic "
                       "compensation, same and alternating polarity, against the tolerance; the least pitches with "
                       "and without compensation marked",
    "skin_coupling": "a continuous skin: the fraction of a loaded taxel's magnet travel that a magnet at distance r "
                     "makes (bonded layer, axisymmetric FE), with Boussinesq's half-space for comparison",
}


def _map(plt, xt: Crosstalk):
    fig, ax = plt.subplots(figsize=(4.6, 3.8), layout="constrained")
    data = xt.residual_mN + xt.mechanical_mN
    n = len(data)
    im = ax.imshow(data, cmap="viridis", origin="upper")
    for i in range(n):
        for j in range(n):
            if i != j and n <= 8:
                ax.text(j, i, f"{data[i, j]:.1f}", ha="center", va="center", fontsize=7,
                        color="white" if data[i, j] < 0.6 * data.max() else "black")
    ax.set_xticks(range(n))
    ax.set_yticks(range(n))
    ax.set_xlabel("neighbour j (moves)")
    ax.set_ylabel("taxel i (misreads)")
    raw = float((xt.field_mN + xt.mechanical_mN).max())
    ax.set_title(f"misreading after the host's compensation\n(without it: up to {raw:.0f} mN)", fontsize=9)
    fig.colorbar(im, ax=ax, label="mN")
    return fig


def _pitch(plt, xt: Crosstalk):
    fig, ax = plt.subplots(figsize=(5.4, 3.6), layout="constrained")
    for name, style in (("same", "-"), ("alternating", "--")):
        ax.loglog(xt.sweep_mm, np.maximum(xt.sweep_worst_mN[name], 1e-3), style, color="C0" if name == "same" else "C1",
                  label=f"{name} polarity")
        for value, mark in ((xt.min_pitch_mm[name], "o"), (xt.min_pitch_compensated_mm[name], "s")):
            if value is not None:
                ax.plot([value], [xt.tolerance_mN], mark, color="C0" if name == "same" else "C1", ms=5)
    ax.axhline(xt.tolerance_mN, color="k", lw=0.8, label=f"tolerance {xt.tolerance_mN:.2f} mN")
    ax.axvline(xt.pitch_mm, color="grey", lw=0.8, ls=":", label=f"this pitch, {xt.pitch_mm:g} mm")
    ax.axvline(xt.sweep_mm[0], color="grey", lw=0.8, ls="-.", label=f"the parts' minimum, {xt.sweep_mm[0]:.1f} mm")
    ax.set_xlabel("pitch, mm")
    ax.set_ylabel("worst misreading, mN")
    ax.legend(fontsize=7, frameon=False, title="o: least pitch; s: with compensation", title_fontsize=7)
    return fig


def _coupling(plt, xt: Crosstalk):
    if xt.coupling_curve is None:
        raise ValueError("separate skins have no coupling curve to draw")
    r, c = xt.coupling_curve
    depth = xt.coupling_depth_mm
    fig, ax = plt.subplots(figsize=(5.4, 3.4), layout="constrained")
    ax.plot(r, c, color="C0", label="skin bonded to the pad (FE)")
    ax.plot(r, boussinesq_ratio(r, depth), color="C3", ls="--", label="half-space (Boussinesq)")
    ax.axhline(0.0, color="k", lw=0.6)
    ax.axvline(xt.pitch_mm, color="grey", lw=0.8, ls=":", label=f"this pitch, {xt.pitch_mm:g} mm")
    ax.axvline(xt.sweep_mm[0], color="grey", lw=0.8, ls="-.", label=f"the parts' minimum, {xt.sweep_mm[0]:.1f} mm")
    ax.set_xlabel("distance from the loaded taxel, mm")
    ax.set_ylabel("magnet travel / loaded magnet's")
    ax.legend(fontsize=7, frameon=False)
    return fig


def figures(xt: Crosstalk) -> dict[str, bytes]:
    """{file name: bytes}: each chart as SVG and PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    makers = {"crosstalk_map": _map, "crosstalk_pitch": _pitch}
    if xt.coupling_curve is not None:
        makers["skin_coupling"] = _coupling
    out: dict[str, bytes] = {}
    with matplotlib.rc_context(RC):
        for name, make in makers.items():
            fig = make(plt, xt)
            out[f"{name}.svg"], out[f"{name}.png"] = _render(fig)
            plt.close(fig)
    return out
