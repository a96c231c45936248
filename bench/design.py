"""Design-search benchmark: how fast ``magfab design`` evaluates designs, on how many workers, and how right its cheap
models are against the full chain.

Run from anywhere::

    python bench/design.py [--surrogate-designs N] [--fe-designs M] [--out DIR]

What it measures, each on the same Latin hypercube over the example targets' whole box (magfab/examples/targets.toml's
ranges and magnets, with both tips and every silicone of the catalogue: :func:`whole_box`, the real studies' mix) and
on local Dask clusters started here (wall clock, :func:`time.perf_counter`):

0. **Before / after, on one 2-worker cluster**: the cheap models' designs per second and share of FE fallbacks with
   the surrogate as it was (hemispherical tips only: the flat family taken out of the workers' ``BOXES``) and glibc's
   allocator thresholds as Dask's nanny leaves them (``MALLOC_TRIM_THRESHOLD_=65536``, mmap threshold fixed at
   128 KiB), against both families and :func:`magfab.inverse.worker.malloc_thresholds`; and the workers' system CPU
   time (``os.times``) on the same FE designs under each allocator setting: their ratio.
1. **Throughput**: designs per second through :func:`magfab.inverse.study.evaluate_all` (the code ``magfab sweep``
   and the search's verification run: up to :data:`~magfab.inverse.study.CHUNK` cheap designs a Dask task; the
   search's own loop sends one design a task) with the cheap models (elastomer surrogate) and with the full
   chain (FE), on 1 and on 2 worker processes; the scaling efficiency rate(2) / (2 rate(1)).
2. **Overhead**: no-op tasks through the same cluster: the scheduler's cost per task, which bounds how finely a study
   can be cut.
3. **Error**: on the designs both chains evaluated, the cheap models' error in each objective figure against the
   full chain (median, 90th percentile, max), apart for the designs whose range either chain ends at a model's reach
   (:func:`_errors`), and the speed ratio between the two chains in the same run.
4. **On paper**: a study of 10^6 designs on N workers, from the measured per-design cost and per-task overhead.
5. **The search as a user runs it**: :func:`magfab.inverse.study.run_study` (what ``magfab design`` runs) over the whole
   box on a 2-worker cluster, one study per seed (``--study-seeds``): designs per second from its progress
   callback's first call to its last (``magfab design``'s search line), the designs that fell back to the FE, and
   the ratio to the evaluation alone (item 1's 2-worker rate; with ``--only-study``, measured here first).

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
from typing import Any

import numpy as np

FIGURES = ("normal_resolution_mN", "normal_range_N", "shear_resolution_mN", "shear_range_N")


def _targets():
    from magfab.inverse.targets import parse_targets
    from magfab.spec import load_spec

    text = resources.files("magfab.examples").joinpath("targets.toml").read_text(encoding="utf-8")
    return parse_targets(text), load_spec(None)


def whole_box():
    """(targets, base spec) of the example targets over their whole box: their ranges and magnets, every tip and every
    silicone of the catalogue (the real studies' mix: the example's own list has the hemispherical tip only)."""
    from magfab.spec import Tip

    targets, base = _targets()
    variables = targets.variables.model_copy(update={"tips": [Tip.HEMISPHERE, Tip.FLAT], "materials": None})
    return targets.model_copy(update={"variables": variables}), base


def _cpu() -> tuple[float, float]:
    """(user, system) CPU seconds of this process so far."""
    t = os.times()
    return t.user, t.system


def _cpu_of(c) -> tuple[float, float]:
    """(user, system) CPU seconds of every worker of ``c``, summed."""
    times = c.run(_cpu).values()
    return sum(t[0] for t in times), sum(t[1] for t in times)


def _dask_malloc() -> bool:
    """glibc's thresholds as Dask's nanny leaves them (MALLOC_TRIM_THRESHOLD_=65536; the mmap threshold glibc's
    128 KiB default, no longer dynamic)."""
    from magfab.inverse.worker import malloc_thresholds

    return malloc_thresholds(128 * 1024, 65536)


def _ours_malloc() -> bool:
    from magfab.inverse.worker import malloc_thresholds

    return malloc_thresholds()


def _flat_family(on: bool) -> None:
    """The surrogate's flat-tip family in this worker (off: the surrogate as it was, hemispherical tips only)."""
    from magfab.models.mechanics import fe_surrogate as S
    from magfab.spec import Tip

    if on:
        S.BOXES[Tip.FLAT] = S.FLAT_BOX
    else:
        S.BOXES.pop(Tip.FLAT, None)


def _fallbacks(recs, modelled: int) -> float:
    """Share of the ``modelled`` designs (the points the spec accepts: the rest fail in milliseconds before any
    model) that fell back to the FE."""
    return sum(r.model.startswith("fe") for r in recs) / max(modelled, 1)


def before_after(points, fe_points, targets, base, workers: int = 2) -> dict[str, object]:
    """Item 0 of the module doc, on one cluster of ``workers``: rates, fallback shares and system-time ratio."""
    from magfab.inverse.study import client, evaluate_all

    modelled = len(_modelled(points, targets, base))
    out: dict[str, object] = {"points": len(points), "modelled": modelled}
    with client(None, workers) as c:
        evaluate_all(points[-2 * workers:], targets, base, c, "surrogate")  # warm-up: imports, tables, caches
        evaluate_all(fe_points[-workers:], targets, base, c, "fe")
        for name, malloc, flat in (("before", _dask_malloc, False), ("after", _ours_malloc, True)):
            assert all(c.run(malloc).values()), "glibc's mallopt refused"
            c.run(_flat_family, flat)
            u0, s0 = _cpu_of(c)
            t0 = time.perf_counter()
            fe_recs = evaluate_all(fe_points, targets, base, c, "fe")
            fe_rate = len(fe_points) / (time.perf_counter() - t0)
            u1, s1 = _cpu_of(c)
            t0 = time.perf_counter()
            recs = evaluate_all(points, targets, base, c, "surrogate")
            rate = len(points) / (time.perf_counter() - t0)
            u2, s2 = _cpu_of(c)
            # CPU seconds the workers spent per design: on a machine shared with other work the wall clock's rate
            # falls, this does not; workers / cpu is the rate the cluster reaches with its cores to itself.
            cpu = (u2 + s2 - u1 - s1) / len(points)
            out[name] = {"fe_designs_per_s": fe_rate, "fe_user_s": u1 - u0, "fe_system_s": s1 - s0,
                         "designs_per_s": rate, "worker_cpu_s_per_design": cpu,
                         "designs_per_s_cores_to_itself": workers / cpu,
                         "fe_fallback_share": _fallbacks(recs, modelled)}
            if name == "after":  # the cheap models' error in each figure against the full chain, on the FE designs
                index = {json.dumps(p, sort_keys=True): i for i, p in enumerate(points)}
                cheap = [recs[index[json.dumps(p, sort_keys=True)]] for p in fe_points]
                out["error_vs_full_chain"] = _errors(cheap, fe_recs)
            print(f"{name:6s}: {rate:7.2f} designs/s on {workers} workers over {len(points)} designs of the whole box, "
                  f"({workers / cpu:.1f} from the workers' CPU time), "
                  f"FE fallbacks {100 * out[name]['fe_fallback_share']:.0f} % of the designs modelled; "
                  f"{len(fe_points)} FE designs: system {s1 - s0:.2f} s, user {u1 - u0:.2f} s", flush=True)
        c.run(_flat_family, True)
    b, a = out["before"], out["after"]
    out["ratios"] = {"designs_per_s_after_over_before": a["designs_per_s"] / b["designs_per_s"],
                     "worker_cpu_per_design_before_over_after": b["worker_cpu_s_per_design"]
                     / a["worker_cpu_s_per_design"],
                     "fe_system_s_before_over_after": b["fe_system_s"] / max(a["fe_system_s"], 1e-9),
                     "fe_designs_per_s_after_over_before": a["fe_designs_per_s"] / b["fe_designs_per_s"]}
    print("ratios: " + ", ".join(f"{k} {v:.2f}" for k, v in out["ratios"].items()), flush=True)
    return out


def _rate(points, targets, base, workers: int, fidelity: str) -> tuple[float, list, float]:
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


def study_rates(targets, base, seeds: list[int], workers: int = 2) -> list[dict[str, Any]]:
    """Item 5 of the module doc: each seed's study over ``targets`` on one fresh cluster of ``workers``."""
    from magfab.inverse.study import client, first_phase, records, run_study

    out = []
    with client(None, workers) as c:
        for seed in seeds:
            t = targets.model_copy(update={"study": targets.study.model_copy(update={"seed": seed})})
            marks: list[tuple[int, float]] = []

            def mark(done: int, total: int, m: list[tuple[int, float]] = marks) -> None:
                m.append((done, time.perf_counter()))

            with tempfile.TemporaryDirectory() as d:
                study = run_study(t, base, Path(d) / "study.log", c, progress=mark)
                recs = records(study)
            (n0, t0), (n1, t1) = marks[0], marks[-1]
            out.append({"seed": seed, "designs": n1 - n0, "designs_per_s": (n1 - n0) / (t1 - t0),
                        "first_phase": first_phase(t), "fe_fallbacks": sum(r.model.startswith("fe") for r in recs)})
            print(f"study seed {seed}: {out[-1]['designs_per_s']:.1f} designs/s over {n1 - n0} designs of the whole "
                  f"box on {workers} workers, {out[-1]['fe_fallbacks']} fell back to the FE", flush=True)
    return out


def _modelled(points, targets, base) -> list:
    """The points the spec accepts (the ones the models run on), in order."""
    from magfab.design import derive
    from magfab.inverse.space import candidate_spec

    ok = []
    for p in points:
        try:
            derive(candidate_spec(p, base, targets, "bench"))
        except Exception:
            continue
        ok.append(p)
    return ok


def _study_overhead(targets, n: int, where) -> dict[str, float]:
    """Seconds per trial the search loop itself costs (ask, the point, the stored result, tell) on the storage at
    ``where`` with the targets' sampler, evaluating nothing: the mean up to N trials, since a sampler's ask grows with
    history."""
    from magfab.inverse import study as st
    from magfab.inverse.evaluate import constraint_names
    from magfab.inverse.space import Space
    from magfab.spec import load_spec

    t = targets.model_copy(update={"name": "overhead"})
    study = st.open_study(t, where)
    fake = {"state": "ok", "reason": "", "model": "none", "errors": [],
            "constraints": [0.0] * len(constraint_names(t))}
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


def _errors(cheap, full) -> dict[str, dict[str, dict[str, float]]]:
    """The cheap chain's relative error in each figure against the full chain, in two groups: the designs whose
    normal range both chains end at a limit of the sensor (the models' error), and those where either ends at a
    model's reach ('at least' figures: the two models stop at different depths, and the worst-case resolution is
    taken over each one's range, so their gap is not an error of either)."""
    from magfab.models.predict import MODEL_REACH

    out: dict[str, dict[str, dict[str, float]]] = {}
    for group, reached in (("sensor_limit_both", False), ("model_reach_either", True)):
        pairs = [(a, b) for a, b in zip(cheap, full) if a.state != "failed" and b.state != "failed"
                 and a.model == "surrogate"
                 and reached == bool({a.metrics.get("range_limit"), b.metrics.get("range_limit")} & MODEL_REACH)]
        for f in FIGURES:
            e = [abs(a.metrics[f] - b.metrics[f]) / abs(b.metrics[f]) for a, b in pairs if b.metrics.get(f)]
            if e:
                out.setdefault(group, {})[f] = {"median": statistics.median(e), "p90": float(np.percentile(e, 90)),
                                                "max": max(e), "n": len(e)}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--surrogate-designs", type=int, default=400)
    ap.add_argument("--fe-designs", type=int, default=16)
    ap.add_argument("--overhead-trials", type=int, default=800)
    ap.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "magfab-bench")
    ap.add_argument("--only-before-after", action="store_true", help="item 0 only")
    ap.add_argument("--study-seeds", type=int, default=5, help="item 5: studies of seeds 0 to N-1")
    ap.add_argument("--only-study", action="store_true", help="item 5 only, with item 1's 2-worker rate")
    a = ap.parse_args(argv)
    from magfab.inverse.space import latin_hypercube

    targets, base = whole_box()
    points = latin_hypercube(targets.variables, a.surrogate_designs, seed=7)
    if a.only_study:
        return _only_study(points, targets, base, a)
    by_tip = [[p for p in _modelled(points, targets, base) if p["tip"] == t] for t in ("flat", "hemisphere")]
    fe_points = [p for pair in zip(*by_tip) for p in pair][:a.fe_designs]  # the two tips in turn
    result: dict[str, object] = {"cores": os.cpu_count(), "surrogate_designs": len(points),
                                 "fe_designs": len(fe_points)}
    result["before_after_2_workers"] = before_after(points, fe_points, targets, base)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "design_bench.json").write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
    if a.only_before_after:
        print(f"wrote {a.out / 'design_bench.json'}")
        return 0
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
    index = {json.dumps(p, sort_keys=True): i for i, p in enumerate(points)}
    cheap_on_fe = [recs["surrogate"][index[json.dumps(p, sort_keys=True)]] for p in fe_points]
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
    for group, figures in result["error_vs_full_chain"].items():
        print(f"  the cheap chain against the full chain, {group.replace('_', ' ')} (range ended by):")
        for f, e in figures.items():
            print(f"    {f:22s} median {100 * e['median']:.1f} %  p90 {100 * e['p90']:.1f} %  "
                  f"max {100 * e['max']:.1f} % (n={e['n']})")
    for n, p in paper.items():
        print(f"  10^6 designs on {n:>3s} workers: sweep {p['sweep_hours']:.2f} h ({p['sweep_bound']}-bound), "
              f"search at least {p['search_hours']:.2f} h (the client's loop)")
    result["study"] = _with_ratio(study_rates(targets, base, list(range(a.study_seeds))), rates["surrogate"][2])
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "design_bench.json").write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
    print(f"wrote {a.out / 'design_bench.json'}")
    return 0


def _with_ratio(studies: list[dict[str, Any]], evaluation_rate: float) -> dict[str, object]:
    """Item 5's studies with each one's rate over the evaluation alone's (same run), printed."""
    for s in studies:
        s["over_evaluation_alone"] = s["designs_per_s"] / evaluation_rate
    rates = sorted(s["designs_per_s"] for s in studies)
    print(f"the search: {rates[0]:.1f}-{rates[-1]:.1f} designs/s (median {statistics.median(rates):.1f}) against "
          f"{evaluation_rate:.1f} for the evaluation alone on 2 workers (x{rates[0] / evaluation_rate:.2f}-"
          f"{rates[-1] / evaluation_rate:.2f})", flush=True)
    return {"evaluation_alone_designs_per_s": evaluation_rate, "studies": studies}


def _only_study(points, targets, base, a) -> int:
    """``--only-study``: item 1's 2-worker rate of the cheap models, then item 5."""
    rate, _, _ = _rate(points, targets, base, 2, "surrogate")
    result = {"study": _with_ratio(study_rates(targets, base, list(range(a.study_seeds))), rate)}
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "design_study_bench.json").write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
    print(f"wrote {a.out / 'design_study_bench.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
