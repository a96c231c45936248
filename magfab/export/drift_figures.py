"""The drift budget's chart (drift/drift.svg, .png): the force error against the chip's temperature without and with
compensation, and bars for turning in the Earth's field and the stray source, each against the resolution. Drawn and
saved as the prediction plots are (:mod:`magfab.export.figures`: fixed SVG salt, no dates), so a rebuild gives the
same bytes."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from .figures import RC, _legend_below, _render

if TYPE_CHECKING:
    from ..models.drift import Drift

# Imported lazily, inside the functions that use it, for speed: matplotlib takes a
# noticeable time to import, and importing this module should not.

__all__ = ["figures", "CAPTIONS", "FOLDER"]

#: Where the chart goes in the build.
FOLDER = "drift/"

CAPTIONS = {
    "drift": "left: the largest force error over the coefficients' bands against the chip's temperature, normal at "
             "rest and at the end of the normal range, without compensation, with the recipes' coefficients and "
             "with fitted ones, the calibration temperature and the normal resolution marked; right: the force "
             "error of turning the sensor over in the least and the strongest Earth field, at the spec's place and "
             "turn, and of the stated stray dipole, normal at rest, normal at the end of the range and shear, "
             "against the normal and shear resolutions",
}

_CASE_STYLE = {"without": "-", "with": "--", "fitted": ":"}
_POINT_COLOUR = {"normal_rest": "#1f77b4", "normal_end": "#d62728"}
_BAR_COLOUR = {"normal at rest": "#1f77b4", "normal at the end": "#d62728", "shear": "#2ca02c"}


def _temperature_panel(ax, d: Drift) -> list:
    from matplotlib.lines import Line2D

    t = d.temperature
    temps = np.asarray(t.temperatures_C)
    for point, colour in _POINT_COLOUR.items():
        for case, style in _CASE_STYLE.items():
            ax.plot(temps, np.abs(np.asarray(t.span[point][case])), style, color=colour, lw=1.3)
    res = d.resolution_mN["normal"]
    ax.axhline(res, color="k", lw=0.8)
    ax.axvline(t.calibration_C, color="0.5", lw=0.8, ls="-.")
    ax.set_xlabel("chip temperature, C")
    ax.set_ylabel("largest force error, mN")
    ax.set_ylim(bottom=0.0)
    ax.set_title("temperature", fontsize=9)
    handles = [Line2D([], [], color=c, label=p.replace("_", " at ").replace("at end", "at the end"))
               for p, c in _POINT_COLOUR.items()]
    handles += [Line2D([], [], color="0.3", ls=s, label={"without": "uncompensated", "with": "recipe coefficients",
                                                          "fitted": "fitted coefficients"}[c])
                for c, s in _CASE_STYLE.items()]
    handles += [Line2D([], [], color="k", lw=0.8, label=f"normal resolution {res:.2f} mN"),
                Line2D([], [], color="0.5", lw=0.8, ls="-.", label=f"calibrated at {t.calibration_C:g} C")]
    return handles


def _bars_panel(ax, d: Drift) -> list:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    rows = [(f"turned over,\n{b.field_G / 2:g} G", b) for b in d.rotation_band]
    stated = d.rotation
    if all(abs(stated.field_G - b.field_G) > 1e-12 for b in d.rotation_band):
        rows.append((f"this place and turn\n({stated.field_G:.2g} G on an axis)", stated))
    if d.stray is not None:
        rows.append((f"stray dipole\n({d.stray.field_G:.2g} G)", d.stray))
    y = np.arange(len(rows))
    h = 0.26
    for k, colour in enumerate(_BAR_COLOUR.values()):
        values = [abs([r.normal_rest_mN, r.normal_end_mN, r.shear_mN][k]) for _, r in rows]
        ax.barh(y + (k - 1) * h, values, height=h, color=colour)
    ax.axvline(d.resolution_mN["normal"], color="k", lw=0.8)
    ax.axvline(d.resolution_mN["shear"], color="k", lw=0.8, ls=":")
    ax.set_yticks(y, [label for label, _ in rows], fontsize=7.5)
    ax.invert_yaxis()
    ax.set_xlabel("force error, mN")
    ax.set_title("Earth's field" + (" and stray source" if d.stray is not None else ""), fontsize=9)
    return [Patch(color=c, label=k) for k, c in _BAR_COLOUR.items()] + [
        Line2D([], [], color="k", lw=0.8, ls=":", label=f"shear resolution {d.resolution_mN['shear']:.2f} mN")]


def _drift(plt, d: Drift):
    fig, (left, right) = plt.subplots(1, 2, figsize=(9.6, 4.4), layout="constrained",
                                      gridspec_kw={"width_ratios": (1.1, 1.0), "wspace": 0.12})
    handles = _temperature_panel(left, d) + _bars_panel(right, d)
    _legend_below(fig, handles, ncol=4, fontsize=7)
    return fig


def figures(d: Drift) -> dict[str, bytes]:
    """{file name: bytes}: the chart as SVG and PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out: dict[str, bytes] = {}
    with matplotlib.rc_context(RC):
        fig = _drift(plt, d)
        out["drift.svg"], out["drift.png"] = _render(fig)
        plt.close(fig)
    return out
