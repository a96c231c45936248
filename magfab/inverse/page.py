"""The study's files: the tables, the Pareto plot and the page (Markdown and HTML) of ``magfab design``."""

from __future__ import annotations

import html
import io
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .evaluate import REQUIREMENTS, bench_point, constraint_names
from .files import spec_toml, write_bytes
from .pareto import front_mask
from .result import margins, nearest
from .space import CATEGORICAL, NUMERIC, candidate_spec
from .study import Record, tally
from .tables import FIGURES, csv_bytes, parquet_bytes, rows, write_table
from .targets import OBJECTIVES, Models, Objective

if TYPE_CHECKING:
    from .result import DesignResult

# Imported lazily, inside the functions that use it, for speed: matplotlib takes a
# noticeable time to import, and importing this module should not.

__all__ = ["write_outputs", "write_specs", "plot_front", "pareto_rows"]

_LABELS = {"normal_resolution_mN": "normal resolution, mN", "shear_resolution_mN": "shear resolution, mN",
           "normal_range_N": "normal range, N", "shear_range_N": "shear range, N",
           "diameter_mm": "elastomer diameter, mm", "height_mm": "elastomer height, mm",
           "drift_mN_per_C": "drift at rest, mN/C", "earth_field_mN": "turned over in the Earth field, mN"}


def write_outputs(result: DesignResult, base) -> list[Path]:
    folder = result.folder
    files = write_table(folder, "trials", rows(result.trials))
    table = pareto_rows(result, base)
    files += [write_bytes(folder / "pareto.csv", csv_bytes(table)),
              write_bytes(folder / "pareto.parquet", parquet_bytes(table))]
    for ext in ("svg", "png"):
        files.append(write_bytes(folder / f"pareto.{ext}", plot_front(result, ext)))
    files += write_specs(result, base)
    files.append(write_bytes(folder / "README.md", page_markdown(result).encode()))
    files.append(write_bytes(folder / "index.html", _html(result).encode()))
    _remove_stale(folder, files)
    return files


def _written(r: Record) -> bool:
    """A verified design with figures (met the targets or not) gets a spec; one the models refused has none."""
    return r.state in ("ok", "infeasible") and bool(r.metrics)


def spec_path(result: DesignResult, i: int) -> str:
    """The spec of verified design ``i``, relative to the study folder ("" when none is written)."""
    return f"designs/{result.names[i]}.toml" if _written(result.verified[i]) else ""


def _margin_cells(result: DesignResult, r: Record) -> dict[str, Any]:
    """Per requirement: the design's figure's distance from it (met_by_pct: > 0 met by that much) and the margin it
    must be met by (margin_pct), in percent of the requirement."""
    out: dict[str, Any] = {}
    for m in margins(result.targets, r) if r.metrics else []:
        out[f"{m.name}_met_by_pct"] = 100.0 * m.slack if math.isfinite(m.slack) else None
        out[f"{m.name}_margin_pct"] = 100.0 * m.margin
    return out


def pareto_rows(result: DesignResult, base) -> list[dict[str, Any]]:
    """pareto.csv: the designs the full chain verified, each with its figures (full chain), its distance from each
    requirement against the margin, whether it meets the targets, is on the front or chosen, its spec's path and the
    cheap models' figures beside (screened_*); the dimensions are the ones verified and written (on the printer's
    step). When no design was verified (the search found none feasible or near it), the search's designs nearest to
    meeting the targets, with their cheap-model figures and ``verified`` false."""
    t = result.targets
    names = [f"{n}_{k}" for n in (r for r in REQUIREMENTS if getattr(t.require, r) is not None)
             for k in ("met_by_pct", "margin_pct")]
    table = []
    if result.verified:
        recs, screened = result.verified, result.screened
        labels = list(result.names)
        verified = True
    else:
        ranked = [result.trials[i] for i in nearest(t, result.trials)]
        recs, screened, labels, verified = ranked[:t.study.verify], [], [f"trial-{r.number}" for r in ranked], False
    for i, r in enumerate(recs):
        point = bench_point(r.point, base, t) if verified and r.metrics else r.point
        row: dict[str, Any] = {"design": labels[i], "verified": verified, "model": r.model, "state": r.state,
                               "meets_targets": r.state == "ok", "on_front": verified and i in result.front,
                               "chosen": verified and i == result.chosen,
                               "spec": spec_path(result, i) if verified else ""}
        row.update({k: _cell(point.get(k)) for k in CATEGORICAL + NUMERIC})
        row.update({k: _cell(r.metrics.get(k)) for k in FIGURES})
        row.update(dict.fromkeys(names))
        row.update({k: _cell(v) for k, v in _margin_cells(result, r).items()})
        row.update({f"screened_{o.value}": _cell(screened[i].metrics.get(o.value)) if screened else None
                    for o in t.objectives})
        row["reason"] = r.reason
        table.append(row)
    return table


def _cell(v: Any) -> Any:
    return float(f"{v:.6g}") if isinstance(v, float) and math.isfinite(v) else (None if isinstance(v, float) else v)


def _header(result: DesignResult, i: int) -> str:
    r, name = result.verified[i], result.names[i]
    lines = [f"{name}: a design magfab design found for the targets {result.targets.name!r}.",
             "Full-chain figures: " + ", ".join(f"{o.value} = {r.metrics[o.value]:.4g}"
                                                for o in result.targets.objectives)]
    lines += [("meets " if m.met else "DOES NOT MEET ") + _margin_text(m) for m in margins(result.targets, r)]
    if r.errors:
        lines.append("error findings: " + "; ".join(r.errors))
    step = "dimensions on the printer's step (its layer height, recipes/printers.toml)"
    return "\n".join([*lines, step])


def _margin_text(m) -> str:
    sense = "<=" if REQUIREMENTS[m.name][1] == "at_most" else ">="
    by = f"{100 * m.slack:+.1f} %" if math.isfinite(m.slack) else "no figure"
    return f"{m.name} {m.shown} {sense} {m.need:g}: by {by} (margin {100 * m.margin:.1f} %)"


def write_specs(result: DesignResult, base) -> list[Path]:
    """designs/NAME.toml and NAME.json for each verified design with figures (its header says whether it meets the
    targets, and by how much each requirement), and chosen.toml."""
    out = []
    for i, r in enumerate(result.verified):
        if not _written(r):
            continue
        name = result.names[i]
        spec = candidate_spec(bench_point(r.point, base, result.targets), base, result.targets, name)
        text = spec_toml(spec, _header(result, i))
        out.append(write_bytes(result.folder / "designs" / f"{name}.toml", text))
        if i == result.chosen:  # one fixed name for the chosen design, so a page can say how to build it
            out.append(write_bytes(result.folder / "chosen.toml", text))
        data: dict[str, Any] = {"design": name, "point": bench_point(r.point, base, result.targets),
                                "figures": r.metrics, "model": r.model, "meets_targets": r.state == "ok",
                                "on_front": i in result.front,
                                "requirements": dict(zip(constraint_names(result.targets), r.constraints)),
                                "margins": {m.name: {"value": m.value, "required": m.need, "met_by": m.slack,
                                                     "margin": m.margin, "met": m.met}
                                            for m in margins(result.targets, r)},
                                "error_findings": r.errors}
        out.append(write_bytes(result.folder / "designs" / f"{name}.json",
                               (json.dumps(data, indent=1, sort_keys=True, default=_json) + "\n").encode()))
    return out


def _json(v: Any) -> Any:
    raise TypeError(f"not JSON: {type(v).__name__}")


def _remove_stale(folder: Path, written: list[Path]) -> None:
    """A resumed study's front may have moved: its earlier designs/ files and chosen.toml go."""
    keep = {p.resolve() for p in written}
    stale = [p for p in (folder / "designs").glob("*") if p.suffix in (".toml", ".json")] + [folder / "chosen.toml"]
    for p in stale:
        if p.exists() and p.resolve() not in keep:
            p.unlink()


def plot_front(result: DesignResult, ext: str) -> bytes:
    """The first objective against each other one: every feasible design the search evaluated (cheap models), the
    infeasible ones, the cheap models' front, and the verified designs (full chain) joined to their screening value,
    the chosen one ringed."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    objs = [o.value for o in result.targets.objectives]
    pairs = [(0, j) for j in range(1, len(objs))] or [(0, 0)]
    fig, axes = plt.subplots(1, len(pairs), figsize=(4.6 * len(pairs), 4.2), squeeze=False)
    ok = [r for r in result.trials if r.state == "ok"]
    bad = [r for r in result.trials if r.state == "infeasible"]
    v_ok, v_bad = result.objective_values(ok), result.objective_values(bad)
    front = v_ok[front_mask(v_ok, result.targets.directions())] if len(v_ok) else v_ok
    ver = [i for i, r in enumerate(result.verified) if r.state in ("ok", "infeasible")]
    v_ver = result.objective_values([result.verified[i] for i in ver])
    v_scr = result.objective_values([result.screened[i] for i in ver])
    for ax, (a, b) in zip(axes[0], pairs):
        ax.scatter(v_bad[:, a], v_bad[:, b], s=8, marker="x", color="#e8a0a0", label="infeasible (search)")
        ax.scatter(v_ok[:, a], v_ok[:, b], s=8, color="#b0b0b0", label="feasible (search)")
        ax.scatter(front[:, a], front[:, b], s=22, color="#1f77b4", label="front of the search")
        for k in range(len(ver)):
            ax.plot([v_scr[k, a], v_ver[k, a]], [v_scr[k, b], v_ver[k, b]], color="#555555", lw=0.8)
        on = np.array([i in result.front for i in ver], dtype=bool)
        if len(v_ver):
            ax.scatter(v_ver[on, a], v_ver[on, b], s=46, marker="D", facecolor="none", edgecolor="black",
                       label="verified front (full chain)")
            ax.scatter(v_ver[~on, a], v_ver[~on, b], s=30, marker="D", facecolor="none", edgecolor="#999999",
                       label="verified, off the front")
        if result.chosen is not None:
            c = result.objective_values([result.verified[result.chosen]])[0]
            ax.scatter([c[a]], [c[b]], s=160, facecolor="none", edgecolor="red", lw=1.5, label="chosen")
        _zoom(ax, np.vstack([v_ok, v_ver]) if len(v_ok) else v_bad, a, b)
        for col, vertical in ((a, True), (b, False)) if a != b else ((a, True),):
            _requirement(ax, result, objs[col], vertical)
        ax.set_xlabel(_LABELS[objs[a]] + _arrow(objs[a]))
        ax.set_ylabel(_LABELS[objs[b]] + _arrow(objs[b]))
        ax.grid(alpha=0.3)
    handles, labels = [], []
    for ax in axes[0]:  # each label once: the requirement lines may be on any panel
        for h, label in zip(*ax.get_legend_handles_labels()):
            if label not in labels:
                handles.append(h)
                labels.append(label)
    ncol = 2 if len(pairs) == 1 else 3  # four columns ran the margin bands' labels past the figure's edge
    fig.legend(handles, labels, loc="lower center", ncol=ncol, fontsize=8, frameon=False)
    rows = -(-len(labels) // ncol)  # the legend's rows: room kept below the axes for them
    fig.suptitle(f"{result.targets.name}: {len(result.trials)} designs searched, {len(result.verified)} verified",
                 fontsize=10)
    fig.tight_layout(rect=(0, (0.045 if len(pairs) == 1 else 0.05) * rows + 0.02, 1, 0.95))
    buf = io.BytesIO()
    meta = {"svg": {"Date": None}, "png": {"Software": None}}[ext]
    fig.savefig(buf, format=ext, dpi=130, metadata=meta, bbox_inches="tight", pad_inches=0.1)  # the legend whole
    plt.close(fig)
    return buf.getvalue()


def _requirement_of(objective: str) -> str | None:
    return next((n for n, (figure, _, _) in REQUIREMENTS.items() if figure == objective), None)


def _requirement(ax, result: DesignResult, objective: str, vertical: bool) -> None:
    """The requirement on ``objective``'s axis as a dashed line, and inside it the margin bands: the search's (the
    largest margin among its designs: the cheap models' error) and the full chain's (the largest among the verified
    designs), both labelled. A design in a band meets the requirement, but not by the model chain's own error."""
    name = _requirement_of(objective)
    t = result.targets
    if name is None or getattr(t.require, name) is None:
        return
    need = float(getattr(t.require, name))
    at_most = REQUIREMENTS[name][1] == "at_most"
    what = "model error" if t.require.margin == "model" else "targets' margin"
    line, span = (ax.axvline, ax.axvspan) if vertical else (ax.axhline, ax.axhspan)
    bands = []
    for recs, who, alpha in ((result.trials, "search", 0.08), (result.verified, "full chain", 0.18)):
        margin = max((m.margin for r in recs if r.metrics for m in margins(t, r) if m.name == name), default=0.0)
        if margin > 0:
            bands.append((need * (1.0 - margin) if at_most else need * (1.0 + margin), who, alpha, margin))
    lim = ax.get_xlim() if vertical else ax.get_ylim()
    lo, hi = min([lim[0], need, *(b[0] for b in bands)]), max([lim[1], need, *(b[0] for b in bands)])
    pad = 0.03 * (hi - lo) if (lo, hi) != tuple(lim) else 0.0
    (ax.set_xlim if vertical else ax.set_ylim)(lo - pad, hi + pad)  # the requirement stays in view
    line(need, color="#d62728", lw=1.0, ls="--", label="requirement")
    for inner, who, alpha, margin in bands:
        span(min(need, inner), max(need, inner), color="#d62728", alpha=alpha, lw=0,
             label=f"margin band, {who} ({what}, up to {100 * margin:.1f} %)")


def _zoom(ax, v: np.ndarray, a: int, b: int) -> None:
    """Axes spanning the feasible and verified designs (with a margin): far infeasible ones stay off the chart."""
    for col, setter in ((a, ax.set_xlim), (b, ax.set_ylim)):
        if len(v):
            lo, hi = float(np.min(v[:, col])), float(np.max(v[:, col]))
            pad = 0.08 * (hi - lo) or 0.05 * abs(hi) or 1.0
            setter(lo - pad, hi + pad)


def _arrow(objective: str) -> str:
    return " (lower is better)" if OBJECTIVES[Objective(objective)] == "minimize" else " (higher is better)"


def _fmt(v: Any) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def _md(text: object) -> str:
    """Text from a study (reasons, names) in Markdown: no markup, no pipes, one line."""
    s = html.escape(str(text), quote=False).replace("|", "\\|").replace("\n", " ")
    for ch in "*_`[]#":
        s = s.replace(ch, "\\" + ch)
    return s


def _parts(result: DesignResult) -> list[tuple[str, Any]]:
    """The page as (kind, content) parts, rendered to Markdown and HTML alike: h1, p, code, img, table."""
    t = result.targets
    objs = [o.value for o in t.objectives]
    req = {k: v for k, v in t.require.model_dump().items() if v is not None and k != "margin"}
    states = tally(result.trials)
    cheap = t.study.models is Models.SURROGATE
    how = "the cheap models (the elastomer surrogate for the FE)" if cheap else "the full model chain (FE)"
    again = (f"The {len(result.verified)} designs nearest the front (a third of them from those the cheap models "
             "found just short of a requirement, if any) were re-evaluated by the full model chain (FE), which every "
             "figure below is." if cheap else "Every figure below is the full chain's.")
    parts: list[tuple[str, Any]] = [
        ("h1", f"Design study: {t.name}"),
        ("p", "Requirements: " + ", ".join(f"{k} = {v:g}" for k, v in req.items()) + ". Objectives: "
         + ", ".join(f"{o} ({OBJECTIVES[Objective(o)]})" for o in objs) + "."),
        ("p", f"The search evaluated {len(result.trials)} designs with {how}: {states['ok']} meet every requirement, "
              f"{states['infeasible']} do not, {states['failed']} could not be evaluated (trials.csv gives each "
              f"reason). {again}"),
        ("img", "pareto.svg"),
    ]
    margin = ("the model chain's own error estimate (field model plus mechanics model, predictions.json's models)"
              if t.require.margin == "model" else f"{t.require.margin:g} %")
    parts.append(("p", f"Every requirement the models predict is met by a margin: {margin}; sizes are exact. The "
                       "verified designs' dimensions are on the printer's step (its layer height), as written."))
    if result.chosen is None:
        parts.append(("p", "No verified design meets every requirement with its margin; " + result.closest() + ". "
                           "Relax a requirement, widen the variables, or raise study.trials; pareto.csv lists what "
                           "the verified designs reach."))
    else:
        c = result.verified[result.chosen]
        parts += [("p", f"Chosen: {result.names[result.chosen]}, the best on {objs[0]} (its spec is also "
                        "chosen.toml). It meets every requirement with margin: "
                        + "; ".join(_margin_text(m) for m in margins(t, c)) + ". Build it from this folder:"),
                  ("code", f"magfab build designs/{result.names[result.chosen]}.toml")]
    head = ["design", *objs, "magnet", "grade", "material", "tip", "d_max_mm", "d_min_mm",
            "elastomer_diameter_mm", "cover_mm"]
    body = [[result.names[i]] + [_fmt(result.verified[i].metrics[o]) for o in objs]
            + [_fmt(result.verified[i].point[k]) for k in head[1 + len(objs):]] for i in result.front]
    parts += [("table", (head, body)),
              ("p", "Each verified design's spec is designs/NAME.toml (its header says whether it meets the targets) "
                    "and its full-chain figures and margins designs/NAME.json; pareto.csv lists every verified "
                    "design with its figures, how far it meets each requirement (*_met_by_pct) against the margin "
                    "(*_margin_pct), its spec, and the cheap models' figures (screened_*).")]
    return parts


def page_markdown(result: DesignResult) -> str:
    out = []
    for kind, c in _parts(result):
        if kind == "h1":
            out += [f"# {_md(c)}", ""]
        elif kind == "p":
            out += [_md(c), ""]
        elif kind == "code":
            out += ["```sh", c, "```", ""]
        elif kind == "img":
            out += [f"![Pareto front]({c})", ""]
        else:
            head, rows = c
            out += ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
            out += ["| " + " | ".join(_md(x) for x in row) + " |" for row in rows] + [""]
    return "\n".join(out)


def _html(result: DesignResult) -> str:
    out = []
    for kind, c in _parts(result):
        if kind == "h1":
            out.append(f"<h1>{html.escape(c)}</h1>")
        elif kind == "p":
            out.append(f"<p>{html.escape(c)}</p>")
        elif kind == "code":
            out.append(f"<pre>{html.escape(c)}</pre>")
        elif kind == "img":
            out.append(f'<p><img src="{html.escape(c)}" alt="Pareto front" style="max-width:100%"></p>')
        else:
            head, rows = c
            cells = ["<tr>" + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr>"]
            cells += ["<tr>" + "".join(f"<td>{html.escape(x)}</td>" for x in row) + "</tr>" for row in rows]
            out.append('<div class="wide"><table>' + "".join(cells) + "</table></div>")  # scrolls, not the page
    return ('<!doctype html>\n<html><head><meta charset="utf-8"><meta name="viewport" content="width=device-width">'
            "<title>" + html.escape(result.targets.name) + "</title><style>" + _STYLE + "</style></head><body>\n"
            + "\n".join(out) + "\n</body></html>\n")


#: The page's look: a readable column, and a table that scrolls inside it rather than running past the page.
_STYLE = ("body{font-family:system-ui,sans-serif;max-width:60rem;margin:2rem auto;padding:0 1rem;line-height:1.45;"
          "color:#222}h1{font-size:1.5rem}pre{background:#f4f4f4;padding:.6rem;overflow-x:auto}"
          ".wide{overflow-x:auto;margin:1rem 0}table{border-collapse:collapse;font-size:.85rem;"
          "font-variant-numeric:tabular-nums}th,td{border:1px solid #ccc;padding:.25rem .5rem;text-align:right;"
          "white-space:nowrap}th{background:#f0f0f0}td:first-child,th:first-child{text-align:left}")
