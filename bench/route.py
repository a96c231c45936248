"""Routing benchmark: how long the breakout board takes to route, and how often it succeeds, over a
fixed, seeded set of [pcb]/[sensor] variants.

Run from anywhere::

    python bench/route.py [--variants N] [--seed S] [--baseline] [--out DIR]

For each variant it places and routes the board (``magfab.pcb.board``), runs our checks
(``magfab.pcb.findings``) and records the wall-clock time (:func:`time.perf_counter`), track segments,
vias and whether every check passed. With ``--baseline`` the same variants are routed again in the
same run with plain A* (heuristic weight 1.0, the router before weighting) and the table gives the
ratio of median times. Writes ``<out>/route_bench.json`` and, with matplotlib, ``route_bench.png``
(time per variant, sorted).

Nothing here asserts on a time: the figures are for reading, not for failing.
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import sys
import time
from pathlib import Path

from magfab import derive, parse_spec, pcb
from magfab.board import route
from magfab.errors import Severity, SpecError


def variants(n: int, seed: int) -> list[tuple[str, str]]:
    """``n`` seeded spec texts (name, TOML) spanning the [pcb] keys; the first is the default."""
    rng = random.Random(seed)
    out = [("default", "")]
    while len(out) < n:
        w, h = rng.choice([(30, 30), (30, 28), (32, 30), (34, 31), (40, 40)])
        via = rng.choice([(0.5, 0.25), (0.6, 0.3), (0.8, 0.4)])
        pcb_keys = {
            "density": f'"{rng.choice(["least", "nominal", "most"])}"',
            "clearance_mm": rng.choice([0.1, 0.15, 0.2, 0.24]),
            "track_width_mm": rng.choice([0.15, 0.2, 0.25, 0.3]),
            "pullups": rng.choice(["true", "false"]),
            "mounting_hole_diameter_mm": rng.choice([0, 2.2, 3.2]),
            "via_diameter_mm": via[0], "via_drill_mm": via[1], "width_mm": w, "height_mm": h,
        }
        text = f"[sensor]\ni2c_address = {rng.choice([12, 13, 14, 15])}\n[pcb]\n"
        text += "".join(f"{k} = {v}\n" for k, v in pcb_keys.items())
        if rng.random() < 0.3:
            text += "[pad]\ndiameter_mm = 18\nalignment_hole_spacing_mm = 15\n"
        out.append((f"v{len(out)}", text))
    return out


def run(cases: list[tuple[str, str]]) -> list[dict]:
    rows = []
    for name, text in cases:
        try:
            design = derive(parse_spec(text, name))
        except SpecError as exc:
            rows.append({"name": name, "refused": str(exc)})
            continue
        t = time.perf_counter()
        try:
            b = pcb.board(design)
        except SpecError as exc:
            rows.append({"name": name, "refused": str(exc)})
            continue
        dt = time.perf_counter() - t
        errors = [f.message for f in pcb.findings(b) if f.severity is Severity.ERROR]
        rows.append({"name": name, "time_s": dt, "ok": not errors, "errors": errors[:3],
                     "segments": sum(c.kind == "seg" for c in b.tracks),
                     "vias": sum(c.kind == "point" for c in b.tracks)})
    return rows


def _summary(rows: list[dict]) -> dict:
    timed = [r for r in rows if "time_s" in r]
    times = sorted(r["time_s"] for r in timed)
    return {"routed": sum(r["ok"] for r in timed), "failed": sum(not r["ok"] for r in timed),
            "refused": len(rows) - len(timed), "median_s": statistics.median(times) if times else float("nan"),
            "max_s": max(times, default=float("nan")), "total_s": sum(times)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--variants", type=int, default=30)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--baseline", action="store_true", help="also route with plain A* (slow)")
    ap.add_argument("--out", type=Path, default=Path(__file__).parent / "out")
    args = ap.parse_args(argv)
    cases = variants(args.variants, args.seed)
    results = {"magfab": run(cases)}
    if args.baseline:
        weight = route.HEURISTIC_WEIGHT
        route.HEURISTIC_WEIGHT = 1.0
        try:
            results["plain A*"] = run(cases)
        finally:
            route.HEURISTIC_WEIGHT = weight
    print(f"{'variant':8} " + " ".join(f"{k:>24}" for k in results))
    for i, (name, _) in enumerate(cases):
        cells = []
        for rows in results.values():
            r = rows[i]
            cells.append("refused" if "refused" in r else
                         f"{r['time_s']:6.2f} s {'ok  ' if r['ok'] else 'FAIL'} {r['segments']:3d}/{r['vias']:2d}")
        print(f"{name:8} " + " ".join(f"{c:>24}" for c in cells))
    summary = {k: _summary(v) for k, v in results.items()}
    for k, s in summary.items():
        print(f"{k}: routed {s['routed']}, failed {s['failed']}, refused {s['refused']}; "
              f"median {s['median_s']:.2f} s, max {s['max_s']:.2f} s, total {s['total_s']:.1f} s")
    if "plain A*" in summary:
        base = summary["plain A*"]["median_s"]
        print(f"median time ratio, plain A* = 1.00: magfab {summary['magfab']['median_s'] / base:.2f}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "route_bench.json").write_text(json.dumps({"cases": cases, "results": results, "summary": summary},
                                                          indent=1) + "\n")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return 0
    fig, ax = plt.subplots(figsize=(7, 4))
    for label, rows in results.items():
        times = sorted(r["time_s"] for r in rows if "time_s" in r)
        ax.plot(range(1, len(times) + 1), times, marker="o", ms=3, label=label)
    ax.set_xlabel("variant (sorted by time)")
    ax.set_ylabel("place + route time, s")
    ax.set_yscale("log")
    ax.legend()
    ax.set_title(f"Routing {len(cases)} board variants (seed {args.seed})")
    fig.tight_layout()
    fig.savefig(args.out / "route_bench.png", dpi=120)
    return 0


if __name__ == "__main__":
    sys.exit(main())
