"""The calibration chart: held-out force error against evaluation cost, one point per fit tried."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from ..models.calibration import FitResult

__all__ = ["chart"]



def chart(result: "FitResult") -> dict[str, bytes]:
    """{"calibration_fit.svg": bytes, "calibration_fit.png": bytes}: held-out RMS error (mN) against
    evaluation cost (operations per evaluation), one point per polynomial order and one for MLS, per force;
    the chosen fit ringed. Byte-identical for the same fit (operation counts, not timings)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from .figures import _render

    with matplotlib.rc_context({"svg.hashsalt": "magfab", "svg.fonttype": "path", "path.simplify": True}):
        fig, ax = plt.subplots(figsize=(6.4, 4.2))
        for f, marker, colour in (("Fz_N", "o", "#1f77b4"), ("Fr_N", "s", "#ff7f0e")):
            for method, style in (("poly", "-"), ("mls", "none")):
                cs = [c for c in result.candidates if c.method == method]
                if not cs:
                    continue
                x = [c.cost_ops for c in cs]
                e = [1000.0 * c.rms_holdout_N[f] for c in cs]
                label = f"{f[:2]}, {'polynomial' if method == 'poly' else 'moving least squares'}"
                ax.plot(x, e, marker=marker if method == "poly" else "*", ms=6 if method == "poly" else 11,
                        ls=style, color=colour, lw=0.8, label=label)
                for c, xc, ec in zip(cs, x, e):
                    if f == "Fz_N":
                        ax.annotate(str(c.order) if method == "poly" else "MLS", (xc, ec), textcoords="offset points",
                                    xytext=(0, 6), ha="center", fontsize=7)
                    if c.label == result.chosen:
                        ax.plot([xc], [ec], marker="o", ms=14, mfc="none", mec="k", ls="none")
        cost = np.array([c.cost_ops for c in result.candidates], dtype=float)
        ax.axhline(result.tolerance_mN, color="r", lw=0.8, ls="--")
        ax.text(cost.min(), result.tolerance_mN, " tolerance", color="r", fontsize=7, va="bottom")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("evaluation cost, flops per reading (numbers: polynomial order)")
        ax.set_ylabel(f"held-out RMS error ({result.calibration.errors.get('folds')}-fold), mN")
        scan = result.calibration.scan
        ax.set_title(f"Calibration fits on {scan.get('source')} ({scan.get('rows')} rows); ringed: {result.chosen}",
                     fontsize=9)
        ax.legend(fontsize=8)
        fig.tight_layout()
        svg, png = _render(fig)
        plt.close(fig)
    return {"calibration_fit.svg": svg, "calibration_fit.png": png}
