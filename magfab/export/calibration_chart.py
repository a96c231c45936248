"""The calibration chart: held-out force error against evaluation cost, one point per fit tried."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .figures import RC, _legend_below, _render

if TYPE_CHECKING:
    from ..models.calibration import FitResult

# Imported lazily, inside the functions that use it, for speed: matplotlib takes a
# noticeable time to import, and importing this module should not.

__all__ = ["chart", "caption"]

#: Per force: marker and colour (the polynomials joined by a line, moving least squares a lone star).
FORCE_STYLE = {"Fz_N": ("o", "#1f77b4"), "Fr_N": ("s", "#ff7f0e")}


def _fitted_mls(result: FitResult) -> bool:
    return any(c.method == "mls" for c in result.candidates)


def caption(result: FitResult) -> str:
    """What :func:`chart` draws for this fit, in one line (the report's caption and the file table's entry)."""
    what = "held-out force error against evaluation cost, per polynomial order"
    if _fitted_mls(result):
        return what + " and for moving least squares (MLS)"
    return what + " (no MLS point: this build's calibration.method did not fit it)"


def _legend(fig, result: FitResult) -> None:
    from matplotlib.lines import Line2D


    mls = _fitted_mls(result)
    handles = [Line2D([], [], marker=m, color=c, lw=0.8, ms=6, label=f"{f[:2]}, polynomial (number: order)")
               for f, (m, c) in FORCE_STYLE.items()]
    if mls:
        handles += [Line2D([], [], marker="*", color=c, ls="none", ms=11, label=f"{f[:2]}, moving least squares")
                    for f, (_m, c) in FORCE_STYLE.items()]
    handles += [Line2D([], [], marker="o", ms=14, mfc="none", mec="k", ls="none", label=f"ringed: {result.chosen}, "
                       "the fit chosen"),
                Line2D([], [], color="r", lw=0.8, ls="--", label=f"tolerance {result.tolerance_mN:g} mN "
                       "(calibration.tolerance_mN)")]
    if not mls:
        handles.append(Line2D([], [], ls="none", label='moving least squares not fitted (calibration.method '
                              '"auto" or "mls" fits it)'))
    _legend_below(fig, handles, ncol=2)


def chart(result: FitResult) -> dict[str, bytes]:
    """{"calibration_fit.svg": bytes, "calibration_fit.png": bytes}: held-out RMS error (mN) against
    evaluation cost (operations per evaluation), one point per polynomial order and one for MLS when the fit
    tried it, per force; the chosen fit ringed; legend below the axes. Byte-identical for the same fit
    (operation counts, not timings)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt


    with matplotlib.rc_context(RC):
        fig = draw(plt, result)
        svg, png = _render(fig)
        plt.close(fig)
    return {"calibration_fit.svg": svg, "calibration_fit.png": png}


def draw(plt, result: FitResult):
    """The chart as an open matplotlib Figure (for :func:`chart` and the tests)."""
    fig, ax = plt.subplots(figsize=(6.4, 4.8), layout="constrained")
    for f, (marker, colour) in FORCE_STYLE.items():
        for method in ("poly", "mls"):
            cs = [c for c in result.candidates if c.method == method]
            if not cs:
                continue
            x = [c.cost_ops for c in cs]
            e = [1000.0 * c.rms_holdout_N[f] for c in cs]
            if method == "poly":
                ax.plot(x, e, marker=marker, ms=6, color=colour, lw=0.8)
            else:
                ax.plot(x, e, marker="*", ms=11, ls="none", color=colour)
            for c, xc, ec in zip(cs, x, e):
                if f == "Fz_N":
                    ax.annotate(str(c.order) if method == "poly" else "MLS", (xc, ec), textcoords="offset points",
                                xytext=(0, 8), ha="center", fontsize=7)
                if c.label == result.chosen:
                    ax.plot([xc], [ec], marker="o", ms=14, mfc="none", mec="k", ls="none")
    ax.axhline(result.tolerance_mN, color="r", lw=0.8, ls="--")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.margins(x=0.08, y=0.12)
    ax.set_xlabel("evaluation cost, flops per reading")
    ax.set_ylabel(f"held-out RMS error ({result.calibration.errors.get('folds')}-fold), mN")
    scan = result.calibration.scan
    ax.set_title(f"Calibration fits on the {scan.get('source')} scan ({scan.get('rows')} rows)", fontsize=9)
    _legend(fig, result)
    return fig
