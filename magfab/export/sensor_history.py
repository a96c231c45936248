"""A sensor's history as a chart (``magfab sensor show ID --plot FILE.png``): against the date, its sensitivities at
rest, its field at rest (with the design's band), each calibration's held-out error, and each check's verdict, with
every new skin marked, so a drift over weeks shows. Drawn and saved as the prediction plots are
(:mod:`magfab.export.figures`: fixed SVG salt, no dates in the file), so the same record gives the same bytes."""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping, Sequence
from typing import Any

from .figures import RC, _legend_below, _render

# Imported lazily, inside the functions that use it, for speed: matplotlib takes a
# noticeable time to import, and importing this module should not.

__all__ = ["CAPTION", "chart", "check_error_mN", "check_rest_uT"]

CAPTION = ("against the date: the normal and shear sensitivities at rest; the field Bz at rest, the design's band "
           "shaded; each calibration's held-out RMS error and each check's error; each check's verdict; a new skin "
           "dashed, each line broken there")

#: The lines' colours (green and red kept for the verdicts).
_COLOURS = ("#1f77b4", "#ff7f0e", "#9467bd", "#8c564b", "#17becf", "#e377c2", "#7f7f7f", "#bcbd22")


def check_rest_uT(event: Mapping[str, Any]) -> float | None:
    """A check's field Bz at rest, uT (``magfab-readout check``'s figure ``Bz_rest_uT``)."""
    value = (event.get("figures") or {}).get("Bz_rest_uT")
    return float(value) if isinstance(value, (int, float)) and not isinstance(value, bool) else None


def check_error_mN(event: Mapping[str, Any]) -> float | None:
    """A check's force error, mN: the largest force change it read where none was applied, turned over
    (``turned_dFz_mN``) or warmed (``warmup_dFz_mN``); None when the check ran neither step."""
    figures = event.get("figures") or {}
    found = [abs(float(v)) for k, v in figures.items() if k in ("turned_dFz_mN", "warmup_dFz_mN")
             and isinstance(v, (int, float)) and not isinstance(v, bool)]
    return max(found) if found else None


def _when(text: str) -> dt.datetime:
    return dt.datetime.fromisoformat(text[:-1] + "+00:00" if text.endswith("Z") else text)


def _series(events: Sequence[Mapping[str, Any]], kind: str, value) -> dict[Any, list[tuple[int, dt.datetime, float]]]:
    """{taxel: [(skin epoch, date, value)]} of ``value(event)`` over the events of ``kind`` where it is a number."""
    out: dict[Any, list[tuple[int, dt.datetime, float]]] = {}
    epoch = 0
    for e in events:
        epoch += e["kind"] == "reskin"
        y = value(e) if e["kind"] == kind else None
        if isinstance(y, (int, float)) and not isinstance(y, bool):
            out.setdefault(e.get("taxel"), []).append((epoch, _when(e["date"]), float(y)))
    return out


def _label(name: str, taxel: Any, many: bool) -> str:
    return name if not many or taxel is None else f"{name}, taxel {taxel}"


def _lines(ax, events, specs, unit: str) -> None:
    """One line per (quantity, taxel), broken at each new skin: ``specs`` is [(name, kind, value(event), marker)]."""
    k = 0
    for name, kind, value, marker in specs:
        series = _series(events, kind, value)
        for taxel, points in sorted(series.items(), key=lambda t: -1 if t[0] is None else t[0]):
            colour = _COLOURS[k % len(_COLOURS)]
            for n, epoch in enumerate(sorted({p[0] for p in points})):
                ax.plot([p[1] for p in points if p[0] == epoch], [p[2] for p in points if p[0] == epoch],
                        marker=marker, color=colour, lw=1.2, ms=5,
                        label=_label(name, taxel, len(series) > 1) if n == 0 else None)
            k += 1
    ax.set_ylabel(unit, fontsize=8)
    ax.margins(y=0.15)
    if k:
        ax.legend(fontsize=7, loc="best", frameon=False)


def _rest(e: Mapping[str, Any]) -> Any:
    rest = e.get("rest_field_uT") or [None, None, None]
    return rest[2]


def _checks(ax, events: Sequence[Mapping[str, Any]]) -> None:
    """Each check as a marker on its taxel's row: a green triangle for pass, a red cross for fail."""
    rows = sorted({e.get("taxel") for e in events if e["kind"] in ("check", "drift")}, key=lambda t: -1 if t is None
                  else t)
    for e in events:
        if e["kind"] not in ("check", "drift"):
            continue
        y = rows.index(e.get("taxel"))
        ok = e.get("verdict") == "pass"
        ax.plot([_when(e["date"])], [y], "^" if ok else "X", color="#2ca02c" if ok else "#d62728", ms=9)
        ax.annotate(str(e.get("verdict", "?")), (_when(e["date"]), y), xytext=(0, -14), textcoords="offset points",
                    ha="center", fontsize=7)
    ax.set_yticks(range(len(rows)), ["sensor" if t is None else f"taxel {t}" for t in rows] or [], fontsize=7)
    ax.set_ylim(-0.8, max(len(rows), 1) - 0.2)
    ax.set_ylabel("checks", fontsize=8)


def chart(sensor_id: str, events: Sequence[Mapping[str, Any]], bands: Mapping[str, Any] | None = None) -> bytes:
    """The history chart of one sensor as PNG bytes: ``events`` as :meth:`Sensor.events` gives them (dates in UTC
    ISO 8601), ``bands`` its acceptance.json (the rest field's band is shaded) or None."""
    import matplotlib  # lazy: slow to import

    matplotlib.use("Agg")
    import matplotlib.dates as mdates
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    with matplotlib.rc_context(RC):
        fig, axes = plt.subplots(4, 1, figsize=(8.0, 8.6), sharex=True, layout="constrained",
                                 gridspec_kw={"height_ratios": [3, 3, 3, 1.6]})
        sens, rest, err, checks = axes
        _lines(sens, events, [("normal", "calibration", lambda e: e.get("sensitivity_normal_uT_per_N"), "o"),
                              ("shear", "calibration", lambda e: e.get("sensitivity_shear_uT_per_N"), "s")], "uT/N")
        sens.set_title("sensitivity at rest", fontsize=9, loc="left")
        bz = (bands or {}).get("rest", {}).get("Bz_uT", {})
        if {"min", "max"} <= set(bz):
            rest.axhspan(bz["min"], bz["max"], color="#1f77b4", alpha=0.12, lw=0, label="design band")
        _lines(rest, events, [("calibration", "calibration", _rest, "o"),
                              ("check", "check", check_rest_uT, "D")], "uT")
        rest.set_title("field Bz at rest", fontsize=9, loc="left")
        _lines(err, events, [("calibration, Fz held out", "calibration", lambda e: e.get("rms_holdout_Fz_mN"), "o"),
                             ("calibration, Fr held out", "calibration", lambda e: e.get("rms_holdout_Fr_mN"), "s"),
                             ("check, turned over or warmed", "check", check_error_mN, "D")], "mN")
        err.set_title("force error: each calibration's held-out RMS, each check's", fontsize=9, loc="left")
        err.set_ylim(bottom=0)
        _checks(checks, events)
        for e in events:
            if e["kind"] == "reskin":
                for ax in axes:
                    ax.axvline(_when(e["date"]), color="0.35", ls="--", lw=1)
                sens.annotate("new skin", (_when(e["date"]), 0.0), xycoords=("data", "axes fraction"), xytext=(3, 4),
                              textcoords="offset points", fontsize=7, color="0.35")
        for ax in axes:
            ax.grid(True, color="0.9", lw=0.6)
            ax.tick_params(labelsize=7)
        checks.xaxis.set_major_formatter(mdates.DateFormatter("%Y-%m-%d"))
        checks.set_xlabel("date (UTC)", fontsize=8)
        fig.autofmt_xdate(rotation=30, ha="right")
        fig.suptitle(f"sensor {sensor_id}: history", fontsize=10)
        _legend_below(fig, [Line2D([], [], color="0.35", ls="--", lw=1, label="new skin"),
                            Line2D([], [], marker="^", color="#2ca02c", ls="", label="check passed"),
                            Line2D([], [], marker="X", color="#d62728", ls="", label="check failed")], 3)
        png = _render(fig)[1]
        plt.close(fig)
    return png
