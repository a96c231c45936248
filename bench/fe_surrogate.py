"""Make the elastomer FE surrogate's table (magfab/models/mechanics/fe_surrogate.json) and measure it.

Run from the repository::

    python bench/fe_surrogate.py [--jobs J] [--reuse]

1. Latin hypercubes (scipy.stats.qmc, :data:`TABLE`: boxes, sizes, seeds) of bodies over the surrogate's box of
   ratios, keeping those :class:`magfab.models.mechanics.Body` accepts with a hemispherical tip; each one FE run
   (:func:`magfab.models.mechanics.fe_surrogate.run`: the build's FE, mesh and shear probe) in J processes
   (``--reuse``: the shipped file's runs of the same bodies are taken instead of rerun).
2. Held-out bodies from other hypercubes (:data:`HELD_OUT`), run the same way; the surrogate fitted on the table is
   compared with them (force, magnet travel, stretch, shear displacement per newton, reach).
3. The speed: the FE runs' mean time against the surrogate's ``normal_and_shear`` on the held-out bodies, in this run
   (printed; not in the file).
4. The data file, the same bytes for the same FE runs.
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


def bodies(n: int, seed: int, box: dict | None = None) -> list[dict[str, float]]:
    from scipy.stats import qmc

    from magfab.models.mechanics import MechanicsError
    from magfab.models.mechanics.fe_surrogate import body_of

    box = box or MAIN
    lo = np.array([box[k][0] for k in "ahzc"])
    hi = np.array([box[k][1] for k in "ahzc"])
    out = []
    for u in qmc.LatinHypercube(d=4, seed=seed).random(n):
        x = {k: float(f"{v:.6g}") for k, v in zip("ahzc", lo + u * (hi - lo))}
        if x["z"] + x["h"] + x["c"] < 1.0:  # a hemisphere needs the body at least R high
            continue
        try:
            body_of(x)
        except MechanicsError:
            continue
        out.append(x)
    return out


def _surrogate_seconds(S, held: list[dict[str, float]]) -> float:
    """Seconds per body of ``normal_and_shear`` (what the search calls: the fit, PCHIP, scaling) on the held-out
    bodies at R_TABLE, after the table is loaded."""
    S.held_out_error()
    bodies_ = [S.body_of(x) for x in held]
    d = S.GRID * S.R_TABLE
    t1 = time.perf_counter()
    for body in bodies_:
        with contextlib.suppress(S.OutsideRegion):
            S.normal_and_shear(body, 1.0, d[d <= 3.0], 3.0, d[S.PROBED][d[S.PROBED] <= 3.0], S.REST_TABLE)
    return (time.perf_counter() - t1) / max(len(bodies_), 1)


def _run(x):
    os.environ["MAGFAB_JOBS"] = "1"
    from magfab.models.mechanics.fe_surrogate import run

    return run(x)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reuse", action="store_true", help="take the shipped file's FE runs of the same bodies")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    a = ap.parse_args(argv)
    from magfab.models.mechanics import fe_surrogate as S

    table = [x for box, n, seed in TABLE for x in bodies(n, seed, box)]
    held = [x for box, n, seed in HELD_OUT for x in bodies(n, seed, box)]
    print(f"{len(table)} table bodies, {len(held)} held-out bodies", flush=True)
    known = {}
    if a.reuse and (HERE / S.DATA).exists():  # runs of the shipped file with the same ratios: the FE is deterministic
        old = json.loads((HERE / S.DATA).read_text())
        known = {json.dumps(r["x"], sort_keys=True): r for r in old["runs"] + old["held_out"]}
    todo = [x for x in table + held if json.dumps(x, sort_keys=True) not in known]
    t0 = time.perf_counter()
    with multiprocessing.get_context("fork").Pool(a.jobs) as pool:
        fresh = pool.map(_run, todo, chunksize=1)
    print(f"{len(fresh)} FE runs done in {time.perf_counter() - t0:.0f} s ({len(known)} reused)", flush=True)
    fe_s = statistics.mean(r.pop("seconds") for r in fresh) if fresh else float("nan")
    known.update({json.dumps(r["x"], sort_keys=True): r for r in fresh})
    runs = [known[json.dumps(x, sort_keys=True)] for x in table]
    held_runs = [known[json.dumps(x, sort_keys=True)] for x in held]
    data = S.fit_data(runs, held_runs)
    (HERE / S.DATA).write_text(json.dumps(data, sort_keys=True, separators=(",", ":")) + "\n")
    S._shipped.cache_clear()
    per = _surrogate_seconds(S, held)
    err = data["held_out_error"]
    for k in ("force", "travel", "stretch", "disp", "reach"):
        print(f"{k:8s} RMS {100 * err[k + '_rms']:.2f} %  p90 {100 * err[k + '_p90']:.2f} %  "
              f"max {100 * err[k + '_max']:.2f} %")
    print(f"speed: FE {fe_s:.2f} s per run (the runs made now), surrogate {1e3 * per:.2f} ms: {fe_s / per:.0f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
