"""Make the elastomer FE surrogate's tables (magfab/models/mechanics/fe_surrogate.json, hemispherical tip, and
fe_surrogate_flat.json, flat tip) and measure them.

Run from the repository::

    python bench/fe_surrogate.py [--tip hemisphere|flat] [--jobs J] [--reuse]

1. Latin hypercubes (scipy.stats.qmc, :data:`TABLE`: boxes, sizes, seeds) of bodies over the surrogate's box of
   ratios, keeping those :class:`magfab.models.mechanics.Body` accepts with a hemispherical tip; each one FE run
   (:func:`magfab.models.mechanics.fe_surrogate.run`: the build's FE, mesh and shear probe) in J processes
   (``--reuse``: the shipped file's runs of the same bodies are taken instead of rerun).
2. Held-out bodies from other hypercubes (:data:`HELD_OUT`), run the same way; the surrogate fitted on the table is
   compared with them (force, magnet travel, stretch, shear displacement per newton, reach).
3. The speed: the FE runs' mean time against the surrogate's ``normal_and_shear`` on the held-out bodies, in this run
   (printed; not in the file).
4. The data file, the same bytes for the same FE runs.

The flat tip (``--tip flat``): its table is one hypercube over ``FLAT_BOX`` (:data:`FLAT_TABLE`); its held-out bodies
are not a hypercube but the ratios of designs drawn over the example targets' whole box (every tip, stock disc and
silicone; bench/design.py's :func:`whole_box`), flat-tip ones, at the table's radius: independent of the table and
distributed as the search's designs are. The table's size is a cost trade-off: a flat-tip run takes 8-26 s on a core
of its own (the full grid with 13 shear probes; 37 s on 2 cores shared with other work), so the table has 100 runs
in two hypercubes (the second added to the first; a third would add to these the same way). Held-out force error
(median, RMS, 90th percentile, max): 60 runs 2.1, 6.4, 13.8, 21 %; 100 runs 1.6, 4.8, 9.4, 17 %; the hemispherical
tip's 281 runs 0.55, 2.5, 3.1, 19 %.
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


#: The hypercubes the table is drawn from: (box over a, h, z, c; runs drawn; seed), and the held-out ones. The second
#: extends z (a rest distance far above a small elastomer: 11 of 400 designs of the example targets were beyond the
#: first box and fell back to the FE in the search).
MAIN = {"a": (0.10, 0.80), "h": (0.08, 0.80), "z": (0.15, 1.60), "c": (0.05, 0.80)}
SLAB = dict(MAIN, z=(1.60, 2.20))
TABLE = ((MAIN, 260, 1), (SLAB, 70, 3))
HELD_OUT = ((MAIN, 60, 2), (SLAB, 16, 4))
#: The flat tip's hypercube (over fe_surrogate.FLAT_BOX), and how many held-out designs, from which seed.
FLAT_TABLE = ((None, 60, 5), (None, 40, 7))
FLAT_HELD_OUT = (20, 6)


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


def bodies(n: int, seed: int, box: dict | None = None, tip: str = "hemisphere") -> list[dict[str, float]]:
    from scipy.stats import qmc

    from magfab.models.mechanics import MechanicsError
    from magfab.models.mechanics.fe_surrogate import BOXES, body_of
    from magfab.spec import Tip

    box = box or (MAIN if tip == "hemisphere" else BOXES[Tip.FLAT])
    lo = np.array([box[k][0] for k in "ahzc"])
    hi = np.array([box[k][1] for k in "ahzc"])
    out = []
    for u in qmc.LatinHypercube(d=4, seed=seed).random(n):
        x = {k: float(f"{v:.6g}") for k, v in zip("ahzc", lo + u * (hi - lo))}
        if tip == "hemisphere" and x["z"] + x["h"] + x["c"] < 1.0:  # a hemisphere needs the body at least R high
            continue
        try:
            body_of(x, tip=Tip(tip))
        except MechanicsError:
            continue
        out.append(x)
    return out


def _surrogate_seconds(S, held: list[dict[str, float]], tip) -> float:
    """Seconds per body of ``normal_and_shear`` (what the search calls: the fit, PCHIP, scaling) on the held-out
    bodies at R_TABLE, after the table is loaded."""
    S.held_out_error(tip)
    bodies_ = [S.body_of(x, tip=tip) for x in held]
    d = S.GRID * S.R_TABLE
    t1 = time.perf_counter()
    for body in bodies_:
        with contextlib.suppress(S.OutsideRegion):
            S.normal_and_shear(body, 1.0, d[d <= 3.0], 3.0, d[S.PROBED][d[S.PROBED] <= 3.0], S.REST_TABLE)
    return (time.perf_counter() - t1) / max(len(bodies_), 1)


def _run(job):
    os.environ["MAGFAB_JOBS"] = "1"
    from magfab.models.mechanics.fe_surrogate import run
    from magfab.spec import Tip

    x, tip = job
    return run(x, Tip(tip))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reuse", action="store_true", help="take the shipped file's FE runs of the same bodies")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--tip", choices=("hemisphere", "flat"), default="hemisphere")
    ap.add_argument("--log", type=Path, help="append each FE run to this JSON-lines file as it ends, and with --reuse "
                    "take the runs it holds (a long table survives an interruption)")
    a = ap.parse_args(argv)
    from magfab.models.mechanics import fe_surrogate as S
    from magfab.spec import Tip

    tip = Tip(a.tip)
    if tip == Tip.HEMISPHERE:
        table = [x for box, n, seed in TABLE for x in bodies(n, seed, box)]
        held = [x for box, n, seed in HELD_OUT for x in bodies(n, seed, box)]
    else:
        table = [x for box, n, seed in FLAT_TABLE for x in bodies(n, seed, box, tip="flat")]
        held = design_ratios(*FLAT_HELD_OUT, tip="flat")
    path = HERE / S.DATAS[tip]
    print(f"{len(table)} table bodies, {len(held)} held-out bodies", flush=True)
    known = {}
    if a.reuse and path.exists():  # runs of the shipped file with the same ratios: the FE is deterministic
        old = json.loads(path.read_text())
        known = {json.dumps(r["x"], sort_keys=True): r for r in old["runs"] + old["held_out"]}
    if a.reuse and a.log and a.log.exists():
        for line in a.log.read_text().splitlines():
            r = json.loads(line)
            r.pop("seconds", None)
            known[json.dumps(r["x"], sort_keys=True)] = r
    todo = [x for x in table + held if json.dumps(x, sort_keys=True) not in known]
    t0 = time.perf_counter()
    with multiprocessing.get_context("fork").Pool(a.jobs) as pool:
        fresh = []
        for r in pool.imap(_run, [(x, tip.value) for x in todo], chunksize=1):
            fresh.append(r)
            if a.log:
                with a.log.open("a") as f:
                    f.write(json.dumps(r, sort_keys=True) + "\n")
    print(f"{len(fresh)} FE runs done in {time.perf_counter() - t0:.0f} s ({len(known)} reused)", flush=True)
    fe_s = statistics.mean(r.pop("seconds") for r in fresh) if fresh else float("nan")
    known.update({json.dumps(r["x"], sort_keys=True): r for r in fresh})
    runs = [known[json.dumps(x, sort_keys=True)] for x in table]
    held_runs = [known[json.dumps(x, sort_keys=True)] for x in held]
    data = S.fit_data(runs, held_runs, tip)
    path.write_text(json.dumps(data, sort_keys=True, separators=(",", ":")) + "\n")
    S._shipped.cache_clear()
    per = _surrogate_seconds(S, held, tip)
    err = data["held_out_error"]
    for k in ("force", "travel", "stretch", "disp", "reach"):
        print(f"{k:8s} median {100 * err[k + '_median']:.2f} %  RMS {100 * err[k + '_rms']:.2f} %  "
              f"p90 {100 * err[k + '_p90']:.2f} %  "
              f"max {100 * err[k + '_max']:.2f} %")
    print(f"speed: FE {fe_s:.2f} s per run (the runs made now), surrogate {1e3 * per:.2f} ms: {fe_s / per:.0f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
