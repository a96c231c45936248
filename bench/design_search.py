"""Design-search benchmark: does ``magfab design``'s search find what a dense sweep of the same variables finds?

Run from anywhere::

    python bench/design_search.py [--trials N] [--seeds 5] [--sweep-factor 10] [--workers 2] [--sets a,b]
                                  [--hemisphere-only] [--out DIR]

On each fixed target set of bench/targets/ (fingertip, delicate-grasp taxel, stiff high-range pad), with the same
cheap model chain (the elastomer surrogate, :func:`magfab.inverse.evaluate.evaluate`) for both:

- the study (:func:`magfab.inverse.study.run_study`) run to N trials, once per seed 0 .. seeds-1, on a local Dask
  cluster;
- a sweep: a Latin hypercube of N x sweep-factor designs over the same variables (in the search's buildable
  coordinates, :meth:`magfab.inverse.space.Space.latin_hypercube`), evaluated on the same cluster.

Per seed: the hypervolume of the study's feasible front over the sweep's (objectives scaled to the range both span,
reference point 1.1 past the worst; >= 0.95 wanted), how many sweep designs dominate the study's chosen design (its
best feasible on the first objective, by the cheap chain: the re-verification by the full chain is not run here; 0
wanted), the sweep's front designs no study design reaches (none weakly dominates them), and the (material, tip)
pairs with a feasible sweep design and none in the study. Over the seeds: the chosen design's first objective (min,
max, their ratio). Beside them, the share of geometrically impossible points (refused by the geometry or the build's
preflight, before any model) in a Latin hypercube of the raw mm ranges against one of the search's coordinates.

Both tips run (the surrogate's flat family covers most flat-tip designs; those outside its region go to the FE, a few
seconds each, which makes the stiff pad's sweep the slow one); ``--hemisphere-only`` keeps the hemispherical tips
alone, and the table says which tips ran. A table on stdout and ``<out>/design_search.json``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SETS = ("fingertip", "taxel", "stiff_pad")


def _load(name: str, trials: int, all_tips: bool):
    from magfab.inverse.targets import load_targets

    targets, base = load_targets(HERE / "targets" / f"{name}.toml")
    v = targets.variables
    tips = list(v.tips) if all_tips else [t for t in v.tips if t.value == "hemisphere"]
    targets = targets.model_copy(update={"variables": v.model_copy(update={"tips": tips}),
                                         "study": targets.study.model_copy(update={"trials": trials})})
    return targets, base


def impossible_share(targets, base, n: int, seed: int = 11) -> dict[str, float]:
    """The share of points the geometry (or the build's preflight) refuses before any model runs: a Latin hypercube
    of the raw mm ranges against one of the search's coordinates."""
    from magfab.check import preflight
    from magfab.design import derive
    from magfab.errors import InputError
    from magfab.inverse.space import Space, candidate_spec, latin_hypercube

    def refused(point) -> bool:
        try:
            preflight(derive(candidate_spec(point, base, targets, "probe")))
        except InputError:
            return True
        return False

    space = Space(targets, base)
    raw = latin_hypercube(targets.variables, n, seed)
    ours = [space.point(p) for p in space.latin_hypercube(n, seed)]
    return {"mm_ranges": sum(map(refused, raw)) / n, "search_coordinates": sum(map(refused, ours)) / n, "n": n}


def _min_form(values: np.ndarray, directions) -> np.ndarray:
    return values * np.where(np.array(directions) == "minimize", 1.0, -1.0)


def _feasible(recs, objectives) -> tuple[list, np.ndarray]:
    ok = [r for r in recs if r.state == "ok"]
    return ok, np.array([[r.metrics[o] for o in objectives] for r in ok]).reshape(len(ok), len(objectives))


def _hv(points: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> float:
    from optuna._hypervolume import compute_hypervolume

    if len(points) == 0:
        return 0.0
    scaled = (points - lo) / np.where(hi > lo, hi - lo, 1.0)
    return float(compute_hypervolume(scaled, np.full(points.shape[1], 1.1)))


def compare(study_recs, sweep_recs, targets) -> dict:
    """The figures of one study against the sweep (module doc)."""
    from magfab.inverse.pareto import front_mask

    objectives, dirs = [o.value for o in targets.objectives], targets.directions()
    s_ok, s_v = _feasible(study_recs, objectives)
    w_ok, w_v = _feasible(sweep_recs, objectives)
    s_m, w_m = _min_form(s_v, dirs), _min_form(w_v, dirs)
    both = np.vstack([s_m, w_m]) if len(s_m) + len(w_m) else np.zeros((0, len(objectives)))
    out: dict = {"study_feasible": len(s_ok), "sweep_feasible": len(w_ok)}
    if len(both):
        lo, hi = both.min(axis=0), both.max(axis=0)
        hv_s, hv_w = _hv(s_m, lo, hi), _hv(w_m, lo, hi)
        out["hypervolume_ratio"] = hv_s / hv_w if hv_w > 0 else (1.0 if hv_s == 0 else float("inf"))
    else:
        out["hypervolume_ratio"] = None
    chosen = None
    if s_ok:
        keys = [tuple(row) for row in s_m]
        chosen = min(range(len(s_ok)), key=lambda i: keys[i])
        c = s_m[chosen]
        out["chosen"] = {"first_objective": float(s_v[chosen][0]), "point": s_ok[chosen].point}
        out["sweep_dominating_chosen"] = int(sum(bool(np.all(w <= c) and np.any(w < c)) for w in w_m))
    else:
        out["chosen"], out["sweep_dominating_chosen"] = None, None
    front = w_m[front_mask(w_v, dirs)] if len(w_v) else w_m
    reached = [bool(len(s_m)) and bool(np.any(np.all(s_m <= f, axis=1))) for f in front]
    out["sweep_front"] = len(front)
    out["sweep_front_unreached"] = int(len(front) - sum(reached))
    pairs = lambda recs: {(r.point["material"], r.point["tip"]) for r in recs}
    out["pairs_missed"] = sorted(f"{m}/{t}" for m, t in pairs(w_ok) - pairs(s_ok))
    mags = lambda recs: {f"{r.point['magnet']}:{r.point['grade']}" for r in recs}
    out["magnets_missed"] = sorted(mags(w_ok) - mags(s_ok))
    return out


def run_set(name: str, a, dask_client) -> dict:
    from magfab.inverse.space import Space
    from magfab.inverse.study import evaluate_all, records, run_study

    targets, base = _load(name, a.trials, not a.hemisphere_only)
    res: dict = {"set": name, "tips": [t.value for t in targets.variables.tips], "trials": a.trials,
                 "impossible": impossible_share(targets, base, a.probe)}
    space = Space(targets, base)
    t0 = time.perf_counter()
    sweep_points = [space.point(p) for p in space.latin_hypercube(a.trials * a.sweep_factor, 12345)]
    sweep = evaluate_all(sweep_points, targets, base, dask_client, "surrogate", prefix="s")
    res["sweep"] = {"designs": len(sweep), "seconds": time.perf_counter() - t0,
                    "states": {s: sum(r.state == s for r in sweep) for s in ("ok", "infeasible", "failed")}}
    res["seeds"] = []
    for seed in range(a.seeds):
        t = targets.model_copy(update={"study": targets.study.model_copy(update={"seed": seed})})
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            recs = records(run_study(t, base, Path(tmp) / "study.log", dask_client))
            dt = time.perf_counter() - t0
        row = compare(recs, sweep, t)
        row.update(seed=seed, seconds=dt, states={s: sum(r.state == s for r in recs)
                                                  for s in ("ok", "infeasible", "failed")})
        res["seeds"].append(row)
        print(f"  {name} seed {seed}: HV ratio {row['hypervolume_ratio']}, dominating {row['sweep_dominating_chosen']}"
              f", {dt:.0f} s", file=sys.stderr, flush=True)
    firsts = [r["chosen"]["first_objective"] for r in res["seeds"] if r["chosen"]]
    res["first_objective"] = ({"min": min(firsts), "max": max(firsts), "ratio": max(firsts) / min(firsts)
                               if min(firsts) > 0 else None, "median": statistics.median(firsts), "found": len(firsts)}
                              if firsts else None)
    return res


def table(results: list[dict]) -> str:
    lines = [f"{'set':<10} {'tips':<10} {'impossible mm->ours':>20} {'seed':>4} {'HV ratio':>8} {'dom':>4} "
             f"{'unreached':>9} {'feas s/w':>9} {'first obj':>10} {'s':>5}  pairs missed"]
    for r in results:
        imp = r["impossible"]
        for k, s in enumerate(r["seeds"]):
            hv = "-" if s["hypervolume_ratio"] is None else f"{s['hypervolume_ratio']:.3f}"
            first = "-" if not s["chosen"] else f"{s['chosen']['first_objective']:.4g}"
            lead = (f"{r['set']:<10} {','.join(r['tips']):<10} "
                    f"{100 * imp['mm_ranges']:>8.1f}% -> {100 * imp['search_coordinates']:>5.1f}%") if k == 0 \
                else f"{'':<10} {'':<10} {'':>20}"
            lines.append(f"{lead} {s['seed']:>4} {hv:>8} {s['sweep_dominating_chosen']!s:>4} "
                         f"{s['sweep_front_unreached']:>4}/{s['sweep_front']:<4} "
                         f"{s['study_feasible']:>4}/{s['sweep_feasible']:<4} {first:>10} {s['seconds']:>5.0f}  "
                         f"{' '.join(s['pairs_missed']) or '-'}")
        fo = r["first_objective"]
        spread = "no feasible design" if not fo else \
            f"first objective over seeds {fo['min']:.4g} .. {fo['max']:.4g} (x{fo['ratio']:.2f})"
        lines.append(f"{'':<10} sweep {r['sweep']['designs']} designs in {r['sweep']['seconds']:.0f} s "
                     f"({r['sweep']['states']['ok']} feasible); {spread}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--trials", type=int, default=300)
    p.add_argument("--seeds", type=int, default=5)
    p.add_argument("--sweep-factor", type=int, default=10)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--probe", type=int, default=400, help="points of each hypercube the geometry share counts")
    p.add_argument("--sets", default=",".join(SETS))
    p.add_argument("--hemisphere-only", action="store_true", help="the hemispherical tips alone")
    p.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "design_search_bench")
    a = p.parse_args(argv)
    from magfab.inverse.study import client

    results = []
    with client(None, a.workers) as c:
        for name in a.sets.split(","):
            results.append(run_set(name, a, c))
            a.out.mkdir(parents=True, exist_ok=True)
            (a.out / "design_search.json").write_text(json.dumps(results, indent=1, default=str))
    print(table(results))
    print(f"\nJSON: {a.out / 'design_search.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
