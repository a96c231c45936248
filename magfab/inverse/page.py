"""The study's files: the tables, the Pareto plot and the page (Markdown and HTML) of ``magfab design``."""

from __future__ import annotations

import html
import io
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .evaluate import constraint_names
from .files import spec_toml, write_bytes
from .pareto import front_mask
from .space import candidate_spec
from .study import tally
from .tables import rows, write_table
from .targets import OBJECTIVES, Models, Objective

if TYPE_CHECKING:
    from .result import DesignResult

# Imported lazily, inside the functions that use it, for speed: matplotlib takes a
# noticeable time to import, and importing this module should not.

__all__ = ["write_outputs", "write_specs", "plot_front"]

_LABELS = {"normal_resolution_mN": "normal resolution, mN", "shear_resolution_mN": "shear resolution, mN",
           "normal_range_N": "normal range, N", "shear_range_N": "shear range, N",
           "diameter_mm": "elastomer diameter, mm", "height_mm": "elastomer height, mm"}


def write_outputs(result: DesignResult, base) -> list[Path]:
    folder = result.folder
    files = write_table(folder, "trials", rows(result.trials))
    extra = [{**{f"screened_{o.value}": s.metrics.get(o.value) for o in result.targets.objectives},
              "on_front": i in result.front, "chosen": i == result.chosen}
             for i, s in enumerate(result.screened)]
    files += write_table(folder, "pareto", rows(result.verified, result.names, extra))
    for ext in ("svg", "png"):
        files.append(write_bytes(folder / f"pareto.{ext}", plot_front(result, ext)))
    files += write_specs(result, base)
    files.append(write_bytes(folder / "README.md", page_markdown(result).encode()))
    files.append(write_bytes(folder / "index.html", _html(result).encode()))
    _remove_stale(folder, files)
    return files


def write_specs(result: DesignResult, base) -> list[Path]:
    """designs/NAME.toml and NAME.json for each verified front design, and chosen.toml."""
    out = []
    for i in result.front:
        r, name = result.verified[i], result.names[i]
        spec = candidate_spec(r.point, base, result.targets, name)
        header = (f"{name}: a design magfab design found for the targets {result.targets.name!r}.\n"
                  f"Full-chain figures: " + ", ".join(f"{o.value} = {r.metrics[o.value]:.4g}"
                                                      for o in result.targets.objectives))
        text = spec_toml(spec, header)
        out.append(write_bytes(result.folder / "designs" / f"{name}.toml", text))
        if i == result.chosen:  # one fixed name for the chosen design, so a page can say how to build it
            out.append(write_bytes(result.folder / "chosen.toml", text))
        data: dict[str, Any] = {"design": name, "point": r.point, "figures": r.metrics, "model": r.model,
                                "requirements": dict(zip(constraint_names(result.targets), r.constraints)),
                                "error_findings": r.errors}
        out.append(write_bytes(result.folder / "designs" / f"{name}.json",
                               (json.dumps(data, indent=1, sort_keys=True) + "\n").encode()))
    return out


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
        ax.set_xlabel(_LABELS[objs[a]] + _arrow(objs[a]))
        ax.set_ylabel(_LABELS[objs[b]] + _arrow(objs[b]))
        ax.grid(alpha=0.3)
    handles, labels = axes[0][0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", ncol=2 if len(pairs) == 1 else 4, fontsize=8, frameon=False)
    fig.suptitle(f"{result.targets.name}: {len(result.trials)} designs searched, {len(result.verified)} verified",
                 fontsize=10)
    fig.tight_layout(rect=(0, 0.16 if len(pairs) == 1 else 0.1, 1, 0.95))
    buf = io.BytesIO()
    meta = {"svg": {"Date": None}, "png": {"Software": None}}[ext]
    fig.savefig(buf, format=ext, dpi=130, metadata=meta)
    plt.close(fig)
    return buf.getvalue()


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
    req = {k: v for k, v in t.require.model_dump().items() if v is not None}
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
    if result.chosen is None:
        parts.append(("p", "No verified design meets every requirement. Relax a requirement, widen the variables, or "
                           "raise study.trials; pareto.csv lists what the verified designs reach."))
    else:
        parts += [("p", f"Chosen: {result.names[result.chosen]}, the best on {objs[0]} (its spec is also "
                        "chosen.toml). Build it from this folder:"),
                  ("code", f"magfab build designs/{result.names[result.chosen]}.toml")]
    head = ["design", *objs, "magnet", "grade", "material", "tip", "d_max_mm", "d_min_mm",
            "elastomer_diameter_mm", "cover_mm"]
    body = [[result.names[i]] + [_fmt(result.verified[i].metrics[o]) for o in objs]
            + [_fmt(result.verified[i].point[k]) for k in head[1 + len(objs):]] for i in result.front]
    parts += [("table", (head, body)),
              ("p", "Each design's spec is designs/NAME.toml and its full-chain figures designs/NAME.json; the cheap "
                    "models' figures for the same designs are in pareto.csv (columns screened_*).")]
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
            out.append('<table border="1" cellspacing="0" cellpadding="3">' + "".join(cells) + "</table>")
    return ('<!doctype html>\n<html><head><meta charset="utf-8"><title>' + html.escape(result.targets.name)
            + "</title></head><body>\n" + "\n".join(out) + "\n</body></html>\n")
