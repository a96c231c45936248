"""Design-search benchmark: how fast ``magfab design`` evaluates designs, on how many workers, and how right its cheap
models are against the full chain.

Run from anywhere::

    python bench/design.py [--surrogate-designs N] [--fe-designs M] [--out DIR]

What it measures, each on the same Latin hypercube of the example targets' variables (magfab/examples/targets.toml)
and on local Dask clusters started here (wall clock, :func:`time.perf_counter`):

1. **Throughput**: designs per second through :func:`magfab.inverse.study.evaluate_all` (the code the search and
   ``magfab sweep`` run: one Dask task per design) with the cheap models (elastomer surrogate) and with the full
   chain (FE), on 1 and on 2 worker processes; the scaling efficiency rate(2) / (2 rate(1)).
2. **Overhead**: no-op tasks through the same cluster: the scheduler's cost per task, which bounds how finely a study
   can be cut.
3. **Error**: on the designs both chains evaluated, the cheap models' error in each objective figure against the
   full chain (median, 90th percentile, max), and the speed ratio between the two chains in the same run.
4. **On paper**: a study of 10^6 designs on N workers, from the measured per-design cost and per-task overhead.

A table on stdout and ``<out>/design_bench.json``. Nothing here asserts on a time.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from importlib import resources
from pathlib import Path

import numpy as np

FIGURES = ("normal_resolution_mN", "normal_range_N", "shear_resolution_mN", "shear_range_N")


def _targets():
    from magfab.inverse.targets import parse_targets
    from magfab.spec import load_spec

    text = resources.files("magfab.examples").joinpath("targets.toml").read_text(encoding="utf-8")
    return parse_targets(text), load_spec(None)


def _rate(points, targets, base, workers: int, fidelity: str) -> tuple[float, list]:
    """Designs per second over ``points`` on a fresh local cluster of ``workers`` (after one warm-up design per
    worker, so imports and first-call caches are not counted)."""
    from magfab.inverse.study import client, evaluate_all

    with client(None, workers) as c:
        evaluate_all(points[:workers], targets, base, c, fidelity)  # warm-up
        t0 = time.perf_counter()
        recs = evaluate_all(points, targets, base, c, fidelity)
        dt = time.perf_counter() - t0
        t1 = time.perf_counter()
        n_noop = 400
        c.gather(c.map(lambda i: i, range(n_noop), pure=False))
        overhead = (time.perf_counter() - t1) / n_noop
    return len(points) / dt, recs, overhead


def _study_overhead(targets, n: int, where) -> dict[str, float]:
    """Seconds per trial the search loop itself costs (ask, the point, the stored result, tell) on the storage at
    ``where`` with the targets' sampler, evaluating nothing: the mean up to N trials, since a sampler's ask grows with
    history."""
    from magfab.inverse import study as st
    from magfab.inverse.space import Space
    from magfab.spec import load_spec

    t = targets.model_copy(update={"name": "overhead"})
    study = st.open_study(t, where)
    fake = {"state": "ok", "reason": "", "model": "none", "errors": [],
            "constraints": [0.0] * len(st.constraint_names(t))}
    space = Space(t, load_spec(None))
    out, t0, rng = {}, time.perf_counter(), np.random.default_rng(0)
    for i in range(1, n + 1):
        trial = study.ask()
        space.suggest(trial)
        metrics = {o.value: float(rng.random()) for o in t.objectives}
        st.tell(study, trial, {**fake, "metrics": metrics}, t)
        if i in (50, 100, 200, 400, 800, 1600) or i == n:
            out[str(i)] = (time.perf_counter() - t0) / i
    return out


def _errors(cheap, full) -> dict[str, dict[str, float]]:
    out = {}
    for f in FIGURES:
        e = [abs(a.metrics[f] - b.metrics[f]) / abs(b.metrics[f]) for a, b in zip(cheap, full)
             if a.state != "failed" and b.state != "failed" and a.model == "surrogate" and b.metrics.get(f)]
        if e:
            out[f] = {"median": statistics.median(e), "p90": float(np.percentile(e, 90)), "max": max(e), "n": len(e)}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--surrogate-designs", type=int, default=400)
    ap.add_argument("--fe-designs", type=int, default=16)
    ap.add_argument("--overhead-trials", type=int, default=800)
    ap.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "magfab-bench")
    a = ap.parse_args(argv)
    from magfab.inverse.space import latin_hypercube

    targets, base = _targets()
    points = latin_hypercube(targets.variables, a.surrogate_designs, seed=7)
    fe_points = points[:a.fe_designs]
    result: dict[str, object] = {"cores": os.cpu_count(), "surrogate_designs": len(points),
                                 "fe_designs": len(fe_points)}
    rates: dict[str, dict[int, float]] = {"surrogate": {}, "fe": {}}
    recs: dict[str, list] = {}
    overheads = []
    for fidelity, pts in (("surrogate", points), ("fe", fe_points)):
        for workers in (1, 2):
            rate, r, overhead = _rate(pts, targets, base, workers, fidelity)
            rates[fidelity][workers] = rate
            overheads.append(overhead)
            recs[fidelity] = r
            print(f"{fidelity:9s} {workers} worker(s): {rate:9.2f} designs/s over {len(pts)} designs", flush=True)
    cheap_on_fe = recs["surrogate"][:len(fe_points)]
    per_task = statistics.median(overheads)
    speed_ratio = rates["surrogate"][1] / rates["fe"][1]
    result.update(
        rates_designs_per_s={k: {str(w): v for w, v in d.items()} for k, d in rates.items()},
        scaling_efficiency_2_workers={k: d[2] / (2 * d[1]) for k, d in rates.items()},
        surrogate_speed_ratio_vs_fe=speed_ratio,
        overhead_s_per_task=per_task,
        surrogate_share_of_designs=sum(r.model == "surrogate" for r in recs["surrogate"]) / len(points),
        error_vs_full_chain=_errors(cheap_on_fe, recs["fe"]),
        states={k: {s: sum(r.state == s for r in v) for s in ("ok", "infeasible", "failed")} for k, v in recs.items()},
    )
    a.out.mkdir(parents=True, exist_ok=True)
    loops = {}
    for store, where in (("journal file (default)", a.out / "overhead.log"),
                         ("sqlite", f"sqlite:///{a.out / 'overhead.db'}")):
        for old in (a.out / "overhead.log", a.out / "overhead.db"):
            old.unlink(missing_ok=True)
        n = a.overhead_trials if store.startswith("journal") else min(a.overhead_trials, 200)
        loops[store] = loop = _study_overhead(targets, n, where)
        print(f"search loop on the {store} (ask + store + tell, no evaluation), mean per trial up to N trials: "
              + ", ".join(f"{k}: {1e3 * v:.1f} ms" for k, v in loop.items()))
    result["search_loop_s_per_trial_mean_to"] = loops
    t1 = 1.0 / rates["surrogate"][1]  # s per design on one worker, cheap models
    efficiency = rates["surrogate"][2] / (2 * rates["surrogate"][1])
    loop = max(loops["journal file (default)"].values())  # the client's own cost per trial, at its largest measured
    paper = {}
    for n in (2, 8, 32, 128, 512):
        # A sweep (no sampler): the workers run designs back to back at the measured 2-worker efficiency; the scheduler
        # handles one task per design (batching designs into tasks would lift that bound). A search: every trial also
        # passes the client's ask-store-tell loop, one at a time.
        compute = 1e6 * t1 / (n * efficiency)
        sweep_h = max(compute, 1e6 * per_task) / 3600.0
        paper[str(n)] = {"sweep_hours": sweep_h, "sweep_bound": "scheduler" if 1e6 * per_task > compute else "workers",
                         "search_hours": max(sweep_h, 1e6 * loop / 3600.0)}
    result["study_1e6_on_paper"] = paper
    print(f"surrogate vs FE speed ratio (1 worker): {speed_ratio:.0f}x; "
          f"scheduler overhead {1e3 * per_task:.2f} ms/task")
    for f, e in result["error_vs_full_chain"].items():
        print(f"  {f:22s} median {100 * e['median']:.1f} %  p90 {100 * e['p90']:.1f} %  max {100 * e['max']:.1f} % "
              f"(n={e['n']})")
    for n, p in paper.items():
        print(f"  10^6 designs on {n:>3s} workers: sweep {p['sweep_hours']:.2f} h ({p['sweep_bound']}-bound), "
              f"search at least {p['search_hours']:.2f} h (the client's loop)")
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "design_bench.json").write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
    print(f"wrote {a.out / 'design_bench.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
