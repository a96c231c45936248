"""Make the elastomer FE surrogate's tables (magfab/models/mechanics/fe_surrogate.json, hemispherical tip, and
fe_surrogate_flat.json, flat tip; with ``--law yeoh`` the Yeoh law's, fe_surrogate_yeoh.json and
fe_surrogate_flat_yeoh.json) and measure them.

Run from the repository::

    python bench/fe_surrogate.py [--tip hemisphere|flat] [--law neo-hookean|yeoh] [--jobs J] [--reuse] [--log FILE]

The Yeoh tables run the same bodies with C20/C10 = fe_surrogate.YEOH_K2 (0.06, above every recipe's fit) and the
held-out bodies at YEOH_HELD_OUT_K2 (0.03); the surrogate blends the neo-Hookean and Yeoh tables linearly in a
silicone's k2, and the held-out error printed and shipped is that blend's at 0.03 against the FE at 0.03.

1. Latin hypercubes (scipy.stats.qmc, :data:`TABLE`: boxes, sizes, seeds) of bodies over the surrogate's box of
   ratios, keeping those :class:`magfab.models.mechanics.Body` accepts with a hemispherical tip; each one FE run
   (:func:`magfab.models.mechanics.fe_surrogate.run`: the build's FE, mesh and shear probe) in J processes
   (``--reuse``: the shipped file's runs of the same bodies are taken instead of rerun).
2. Held-out bodies from other hypercubes (:data:`HELD_OUT`), run the same way; the surrogate fitted on the table is
   compared with them (force, magnet travel, stretch, shear displacement per newton, reach).
3. The speed: the FE runs' mean time against the surrogate's ``normal_and_shear`` on the held-out bodies, in this run
   (printed; not in the file).
4. The data file, the same bytes for the same FE runs.

The flat tip (``--tip flat``): its table is hypercubes over ``FLAT_BOX`` (:data:`FLAT_TABLE`); its held-out bodies
are the ratios of designs drawn over the example targets' whole box (every tip, stock disc and silicone;
bench/design.py's :func:`whole_box`), flat-tip ones, at the table's radius (independent of the table and distributed
as the search's designs are), and a hypercube over the part of the box the third table hypercube added.

Each tip's last hypercube widens its box to the bench target sets' designs (bench/targets/): before it, a sweep of
each set's search coordinates (300 designs, 2 workers, one run) fell back to the FE for 0.7 % (fingertip), 20 %
(taxel) and 6 % (stiff pad) of its designs; after it, none did, and the same sweeps ran 1.9, 21.5 and 6.5 times as
many designs per second (measured in one run, each before and after on the same cluster). A flat-tip run costs about
what a hemispherical one does (0.96 of its mean time in the run that made the last hypercubes). Held-out force error
(median, RMS, 90th percentile, max): hemispherical tip, 478 runs, 141 held out, 0.44, 2.8, 2.8, 33 % (281 runs over
the first box: 0.55, 2.5, 3.1, 19 %); flat tip, 203 runs, 64 held out, 0.98, 4.4, 4.9, 35 % (100 runs over the first
box: 1.6, 4.8, 9.4, 17 %). The maxima are single tall or thin-based bodies at their deepest grid points.

The flat tip's fourth hypercube (:data:`FLAT_CORNER`, 40 runs) and its 16 held-out bodies, against the table without
it (163 runs), force error median / RMS / max: on the 16 corner bodies 9.9 / 25.7 / 68 % before, 3.6 / 9.7 / 35 %
after; on the 48 held-out bodies from before 0.80 / 4.3 / 44 % before, 0.87 / 2.9 / 24 % after; the reach's median
error on the corner 33 % before, 15 % after. Over 2,000 designs of the example targets' whole box the reach's fit
no longer goes below 0.10 R (it went to 0.005 R), and no design falls back to the FE (one did).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import multiprocessing
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent.parent / "magfab" / "models" / "mechanics"


#: The hypercubes the table is drawn from: (box over a, h, z, c; runs drawn; seed; a box whose points it skips, or
#: None), and the held-out ones. The second extends z (a rest distance far above a small elastomer: 11 of 400 designs
#: of the example targets were beyond the first box and fell back to the FE in the search).
MAIN = {"a": (0.10, 0.80), "h": (0.08, 0.80), "z": (0.15, 1.60), "c": (0.05, 0.80)}
SLAB = dict(MAIN, z=(1.60, 2.20))
#: The third widens the box to the bench target sets' designs (bench/targets/: a small taxel's large magnet, a stiff
#: pad's thick cover), skipping the first two's box: 190 of 750 hemispherical designs of the taxel set's hypercube
#: were beyond a = 0.8, h = 0.8 or c = 0.8 and fell back to the FE.
FIRST = dict(MAIN, z=(0.15, 2.20))
WIDE = {"a": (0.10, 0.92), "h": (0.08, 1.10), "z": (0.15, 2.20), "c": (0.05, 1.05)}
TABLE = ((MAIN, 260, 1, None), (SLAB, 70, 3, None), (WIDE, 420, 8, FIRST))
HELD_OUT = ((MAIN, 60, 2, None), (SLAB, 16, 4, None), (WIDE, 150, 9, FIRST))
#: The flat tip's hypercubes: two over its first box, a third widening it as the hemispherical tip's does (a taxel's
#: tall magnet, a pad's thick cover, a thin base: h 1.06, c 1.0, z 0.16); how many held-out designs of the example
#: targets' whole box, from which seed; and a held-out hypercube over the widened part.
FLAT_FIRST = {"a": (0.20, 0.93), "h": (0.12, 0.80), "z": (0.20, 2.05), "c": (0.07, 0.75)}
FLAT_WIDE = {"a": (0.20, 0.95), "h": (0.12, 1.10), "z": (0.15, 2.15), "c": (0.07, 1.05)}
#: A fourth over the corner of a wide magnet low in a thin body (a over 0.65, h, z and c under 0.45), where the three
#: had few runs: the reach's fit dipped below every run's there (to 0.005 R, against the FE's 0.11 R, at a d10_h1
#: Dragon Skin 20 design of the whole box), cutting 27 of 1,002 flat-tip designs of a 2,000-design hypercube of the
#: example targets' whole box short and sending one to the FE (5 s, a tenth of a study's time on 2 workers).
FLAT_CORNER = {"a": (0.65, 0.95), "h": (0.12, 0.45), "z": (0.15, 0.45), "c": (0.07, 0.45)}
FLAT_TABLE = ((FLAT_FIRST, 60, 5, None), (FLAT_FIRST, 40, 7, None), (FLAT_WIDE, 110, 10, FLAT_FIRST),
              (FLAT_CORNER, 40, 12, None))
FLAT_HELD_OUT = (20, 6)
FLAT_WIDE_HELD_OUT = (FLAT_WIDE, 50, 11, FLAT_FIRST)
FLAT_CORNER_HELD_OUT = (FLAT_CORNER, 16, 13, None)


def design_ratios(n: int, seed: int, tip: str) -> list[dict[str, float]]:
    """The ratios of the first ``n`` designs with tip ``tip`` of a hypercube over the example targets' whole box (the
    designs the spec accepts)."""
    from design import whole_box

    from magfab.design import derive
    from magfab.inverse.space import candidate_spec, latin_hypercube
    from magfab.models.mechanics import Body
    from magfab.models.mechanics.fe_surrogate import ratios

    targets, base = whole_box()
    out = []
    for p in latin_hypercube(targets.variables, 40 * n, seed=seed):
        if p["tip"] != tip:
            continue
        try:
            body = Body.from_design(derive(candidate_spec(p, base, targets, "held-out")))
        except Exception:
            continue
        out.append({k: float(f"{v:.6g}") for k, v in ratios(body).items()})
        if len(out) == n:
            break
    return out


def bodies(n: int, seed: int, box: dict | None = None, outside: dict | None = None,
           tip: str = "hemisphere") -> list[dict[str, float]]:
    from scipy.stats import qmc

    from magfab.models.mechanics import MechanicsError
    from magfab.models.mechanics.fe_surrogate import body_of
    from magfab.spec import Tip

    box = box or (MAIN if tip == "hemisphere" else FLAT_FIRST)
    lo = np.array([box[k][0] for k in "ahzc"])
    hi = np.array([box[k][1] for k in "ahzc"])
    out = []
    for u in qmc.LatinHypercube(d=4, seed=seed).random(n):
        x = {k: float(f"{v:.6g}") for k, v in zip("ahzc", lo + u * (hi - lo))}
        if outside is not None and all(outside[k][0] <= x[k] <= outside[k][1] for k in "ahzc"):
            continue  # a point of a box an earlier hypercube covers
        if tip == "hemisphere" and x["z"] + x["h"] + x["c"] < 1.0:  # a hemisphere needs the body at least R high
            continue
        try:
            body_of(x, tip=Tip(tip))
        except MechanicsError:
            continue
        out.append(x)
    return out


def _surrogate_seconds(S, held: list[dict[str, float]], tip, k2: float = 0.0) -> float:
    """Seconds per body of ``normal_and_shear`` (what the search calls: the fit, PCHIP, scaling) on the held-out
    bodies at R_TABLE, after the table is loaded (``k2`` > 0: the Yeoh blend's)."""
    S.held_out_error(tip, k2 > 0.0)
    bodies_ = [S.body_of(x, tip=tip) for x in held]
    d = S.GRID * S.R_TABLE
    t1 = time.perf_counter()
    for body in bodies_:
        with contextlib.suppress(S.OutsideRegion):
            S.normal_and_shear(body, 1.0, d[d <= 3.0], 3.0, d[S.PROBED][d[S.PROBED] <= 3.0], S.REST_TABLE, k2)
    return (time.perf_counter() - t1) / max(len(bodies_), 1)


def _run(job):
    os.environ["MAGFAB_JOBS"] = "1"
    from magfab.models.mechanics.fe_surrogate import run
    from magfab.spec import Tip

    x, tip, k2 = job
    return run(x, Tip(tip), k2)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reuse", action="store_true", help="take the shipped file's FE runs of the same bodies")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--tip", choices=("hemisphere", "flat"), default="hemisphere")
    ap.add_argument("--log", type=Path, help="append each FE run to this JSON-lines file as it ends, and with --reuse "
                    "take the runs it holds (a long table survives an interruption)")
    ap.add_argument("--law", choices=("neo-hookean", "yeoh"), default="neo-hookean",
                    help="yeoh: the Yeoh tables (the table's bodies at YEOH_K2, the held-out ones at YEOH_HELD_OUT_K2)")
    a = ap.parse_args(argv)
    from magfab.models.mechanics import fe_surrogate as S
    from magfab.spec import Tip

    yeoh = a.law == "yeoh"
    k2_table, k2_held = (S.YEOH_K2, S.YEOH_HELD_OUT_K2) if yeoh else (0.0, 0.0)

    tip = Tip(a.tip)
    if tip == Tip.HEMISPHERE:
        table = [x for box, n, seed, outside in TABLE for x in bodies(n, seed, box, outside)]
        held = [x for box, n, seed, outside in HELD_OUT for x in bodies(n, seed, box, outside)]
    else:
        table = [x for box, n, seed, outside in FLAT_TABLE for x in bodies(n, seed, box, outside, tip="flat")]
        held = design_ratios(*FLAT_HELD_OUT, tip="flat") + [
            x for box, n, seed, outside in (FLAT_WIDE_HELD_OUT, FLAT_CORNER_HELD_OUT)
            for x in bodies(n, seed, box, outside, tip="flat")]
    path = HERE / (S.YEOH_DATAS if yeoh else S.DATAS)[tip]
    print(f"{len(table)} table bodies, {len(held)} held-out bodies", flush=True)

    def key(x: dict, k2: float) -> str:
        return json.dumps([x, k2], sort_keys=True)

    known = {}
    if a.reuse and path.exists():  # runs of the shipped file with the same ratios: the FE is deterministic
        old = json.loads(path.read_text())
        known = {key(r["x"], k2): r for rs, k2 in ((old["runs"], k2_table), (old["held_out"], k2_held)) for r in rs}
    if a.reuse and a.log and a.log.exists():
        for line in a.log.read_text().splitlines():
            r = json.loads(line)
            if r.pop("tip", tip.value) == tip.value:
                r.pop("seconds", None)
                known[key(r["x"], r.pop("k2", 0.0))] = r
    jobs = [(x, k2_table) for x in table] + [(x, k2_held) for x in held]
    todo = [(x, k2) for x, k2 in jobs if key(x, k2) not in known]
    t0 = time.perf_counter()
    with multiprocessing.get_context("fork").Pool(a.jobs) as pool:
        fresh = []
        for (_, k2), r in zip(todo, pool.imap(_run, [(x, tip.value, k2) for x, k2 in todo], chunksize=1)):
            fresh.append((k2, r))
            if a.log:
                with a.log.open("a") as f:
                    f.write(json.dumps({**r, "k2": k2, "tip": tip.value}, sort_keys=True) + "\n")
    print(f"{len(fresh)} FE runs done in {time.perf_counter() - t0:.0f} s ({len(known)} reused)", flush=True)
    fe_s = statistics.mean(r.pop("seconds") for _, r in fresh) if fresh else float("nan")
    known.update({key(r["x"], k2): r for k2, r in fresh})
    runs = [known[key(x, k2_table)] for x in table]
    held_runs = [known[key(x, k2_held)] for x in held]
    data = (S.fit_yeoh_data if yeoh else S.fit_data)(runs, held_runs, tip)
    path.write_text(json.dumps(data, sort_keys=True, separators=(",", ":")) + "\n")
    S._loaded.cache_clear()
    per = _surrogate_seconds(S, held, tip, k2_held)
    err = data["held_out_error"]
    for k in ("force", "travel", "stretch", "disp", "reach"):
        print(f"{k:8s} median {100 * err[k + '_median']:.2f} %  RMS {100 * err[k + '_rms']:.2f} %  "
              f"p90 {100 * err[k + '_p90']:.2f} %  "
              f"max {100 * err[k + '_max']:.2f} %")
    print(f"speed: FE {fe_s:.2f} s per run (the runs made now), surrogate {1e3 * per:.2f} ms: {fe_s / per:.0f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
