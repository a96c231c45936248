"""Make the elastomer FE surrogate's table (magfab/models/mechanics/fe_surrogate.json) and measure it.

Run from the repository::

    python bench/fe_surrogate.py [--runs N] [--held-out M] [--jobs J] [--check]

1. A Latin hypercube (scipy.stats.qmc, seed 1) of N bodies over the surrogate's box of ratios, keeping those
   :class:`magfab.models.mechanics.Body` accepts with a hemispherical tip; each one FE run
   (:func:`magfab.models.mechanics.fe_surrogate.run`: the build's FE, mesh and shear probe) in J processes.
2. M held-out bodies from another hypercube (seed 2), run the same way; the surrogate fitted on the table is compared
   with them (force, magnet travel, stretch, shear displacement per newton, reach).
3. The speed: the FE runs' mean time against the surrogate's ``normal_and_shear`` on the held-out bodies, in this run
   (printed; not in the file).
4. The data file, the same bytes for the same FE runs.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent.parent / "magfab" / "models" / "mechanics"


def bodies(n: int, seed: int) -> list[dict[str, float]]:
    from scipy.stats import qmc

    from magfab.models.mechanics import MechanicsError
    from magfab.models.mechanics.fe_surrogate import BOX, body_of

    lo = np.array([BOX[k][0] for k in "ahzc"])
    hi = np.array([BOX[k][1] for k in "ahzc"])
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
        try:
            S.normal_and_shear(body, 1.0, d[d <= 3.0], 3.0, d[S.PROBED][d[S.PROBED] <= 3.0], S.REST_TABLE)
        except S.OutsideRegion:
            pass
    return (time.perf_counter() - t1) / max(len(bodies_), 1)


def _run(x):
    os.environ["MAGFAB_JOBS"] = "1"
    from magfab.models.mechanics.fe_surrogate import run

    return run(x)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=260)
    ap.add_argument("--held-out", type=int, default=60)
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    a = ap.parse_args(argv)
    from magfab.models.mechanics import fe_surrogate as S

    table, held = bodies(a.runs, 1), bodies(a.held_out, 2)
    print(f"{len(table)} table bodies, {len(held)} held-out bodies (of {a.runs} and {a.held_out} drawn)", flush=True)
    t0 = time.perf_counter()
    with multiprocessing.get_context("fork").Pool(a.jobs) as pool:
        runs = pool.map(_run, table, chunksize=1)
        held_runs = pool.map(_run, held, chunksize=1)
    print(f"FE runs done in {time.perf_counter() - t0:.0f} s", flush=True)
    fe_s = statistics.mean(r["seconds"] for r in runs + held_runs)
    for r in runs + held_runs:
        r.pop("seconds")
    data = S.fit_data(runs, held_runs)
    (HERE / S.DATA).write_text(json.dumps(data, sort_keys=True, separators=(",", ":")) + "\n")
    S._shipped.cache_clear()
    per = _surrogate_seconds(S, held)
    err = data["held_out_error"]
    for k in ("force", "travel", "stretch", "disp", "reach"):
        print(f"{k:8s} RMS {100 * err[k + '_rms']:.2f} %  p90 {100 * err[k + '_p90']:.2f} %  max {100 * err[k + '_max']:.2f} %")
    print(f"speed: FE {fe_s:.2f} s per run, surrogate {1e3 * per:.2f} ms: {fe_s / per:.0f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
