"""The weight calibration's chart in the report of every build that has a weight plan (calibration/weights_study.svg,
.png): how a calibration from the jig's weighings compared with a full-scan calibration of the same simulated sensor,
on the reference designs, as bench/weights.py last measured it (magfab/weights_bench.json, shipped with the package;
docs/models.md M25). Drawn and saved as the prediction plots are (:mod:`magfab.export.figures`), so a rebuild gives
the same bytes."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .figures import RC, _render, packaged_rows

# Imported lazily, inside the functions that use it, for speed: matplotlib takes a noticeable time to import, and
# importing this module should not.

__all__ = ["bench_rows", "figures", "CAPTIONS", "FOLDER"]

FOLDER = "calibration/"
#: The goal the ratios are held to (docs/models.md M25): within twice the full scan's error.
GOAL = 2.0

CAPTIONS = {
    "weights_study": "calibration from the weight jig against a full scan with a force sensor, on simulated sensors "
                     "of the reference designs drawn across the material, magnet and assembly bands, whose response is "
                     "the other hyperelastic law than the fit's, with the Earth's field turning on the stand and the "
                     "chip's noise: each dot is one sensor's held-out Fz RMS from the twelve weighings over its full "
                     "scan's (circles) and a new skin's from three weighings over its own full scan's (crosses); bars "
                     "mark the median and the 90th percentile, the dashed line the goal of 2; rows name the design, "
                     "whether the magnet was drawn tilted and offset or centred, and the plan: the build's plan for "
                     "the softest skin walked in one stage, or the two-stage bench's plan for the stiffness the first "
                     "two weighings give (bench/weights.py; the command is in magfab/weights_bench.json)",
}


def bench_rows() -> list[dict[str, Any]]:
    """The rows bench/weights.py saved into the package (magfab/weights_bench.json), or []."""
    return packaged_rows("weights_bench.json")


def figures(rows: Sequence[Mapping[str, Any]]) -> dict[str, bytes]:
    """{file name: bytes} of the chart (SVG and PNG); nothing without rows."""
    if not rows:
        return {}
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import matplotlib.ticker

    with matplotlib.rc_context(RC):
        fig, ax = plt.subplots(figsize=(7.5, 0.55 * len(rows) + 1.2))
        labels = []
        for k, row in enumerate(rows):
            y = len(rows) - 1 - k
            for values, dy, marker in ((row["ratios"], 0.12, "o"), (row["reskin_ratios"], -0.12, "x")):
                v = np.asarray(values, float)
                jitter = np.linspace(-0.06, 0.06, v.size)  # spread, deterministic
                ax.scatter(v, y + dy + jitter, s=9, marker=marker, color="#1f77b4" if marker == "o" else "#d62728",
                           alpha=0.6, linewidths=0.8)
                for q in (0.5, 0.9):
                    ax.plot([np.quantile(v, q)] * 2, [y + dy - 0.1, y + dy + 0.1], color="k", lw=1.4 if q == 0.5
                            else 0.8)
            where = "centred" if row["centred"] else "tilted and offset"
            plan = "two-stage plan" if row.get("adaptive") else "softest skin's plan"
            labels.append(f"{row['design']}, magnet {where}, {plan} ({row['sensors']})")
        ax.axvline(GOAL, ls="--", color="k", lw=0.8)
        ax.set_xscale("log")
        top = max(max(r["ratios"] + r["reskin_ratios"]) for r in rows)
        ticks = [t for t in (0.5, 1.0, 2.0, 4.0, 8.0) if t <= 2 * top]
        ax.set_xticks(ticks, [f"{t:g}" for t in ticks])
        ax.xaxis.set_minor_locator(matplotlib.ticker.NullLocator())
        ax.set_yticks(range(len(rows)), labels[::-1])
        ax.set_xlabel("held-out Fz RMS: weight calibration over full scan")
        ax.set_ylim(-0.6, len(rows) - 0.4)
        fig.tight_layout()
        svg, png = _render(fig)
        plt.close(fig)
    return {"weights_study.svg": svg, "weights_study.png": png}
