"""Calibration fits on the MagOne simulated scan: held-out error against evaluation cost, measured.

Run from anywhere::

    python bench/calibrate.py [--out DIR] [--repeat N]

Simulates the MagOne scan (``magfab.models.calibration.simulate_scan``: the paper's y-z track with the chip's noise and
the Nano17's 6.25 mN resolution), fits every candidate (polynomials of order 1-6, moving least squares) and
prints, per candidate: the k-fold held-out RMS and largest error of Fz and Fr (mN), the RMS fit residual, the
condition number of the scaled (and unscaled) design matrix, the evaluation cost in operations, the measured
host time per 1000 evaluations (``Calibration.evaluate`` over the scan's readings, numpy-vectorised, guard
included; median of N runs) and its ratio to the order-4 polynomial measured in the same run. Because the scan
is simulated, it also prints each fit's RMS error against the true (noise-free) force at the noisy readings, over
all rows (in-sample): the reference's quantisation error is a fixed function of the true force, repeated along
every row (Fz) and column (Fy) of the track, so a fit that follows it looks better against the reference than it
is against the truth. Writes
``<out>/calibration_bench.json`` and the chart ``<out>/calibration_fit.svg``/``.png`` (the build's chart: it
plots operation counts, not these timings, so it stays byte-identical).

Nothing here asserts on a time: the figures are for reading, not for failing.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np

from magfab import derive, load_spec
from magfab.export.calibration_chart import chart
from magfab.models import calibration as C
from magfab.models.predict import predict
from magfab.models.scan import simulate_scan

BENCH_DIR = Path(__file__).resolve().parent


def run(repeat: int) -> tuple[C.FitResult, list[dict], dict]:
    design = derive(load_spec(None))
    pred = predict(design)
    t = time.perf_counter()
    scan = simulate_scan(design, pred)
    t_scan = time.perf_counter() - t
    t = time.perf_counter()
    result = C.fit(scan, design)
    t_fit = time.perf_counter() - t
    ideal = simulate_scan(design, pred, ideal=True)
    readings = scan.B_uT
    times = {c.label: C.evaluation_time_s(result.calibration_for(c.label), readings, repeat=repeat)
             for c in result.candidates}
    rows = []
    for c in result.candidates:
        row = c.as_dict()
        f, _ = result.calibration_for(c.label).evaluate(readings)
        row["rms_vs_true_N"] = {"Fz_N": float(np.sqrt(np.mean((f[:, 2] - ideal.F_N[:, 2]) ** 2))),
                                "Fxy_N": float(np.sqrt(np.mean(np.sum((f[:, :2] - ideal.F_N[:, :2]) ** 2, axis=1))))}
        row["time_per_1000_s"] = times[c.label]
        row["ratio_to_poly4_time"] = times[c.label] / times["poly 4"]
        rows.append(row)
    extra = {"rows_in_scan": scan.rows, "scan_sha256": scan.sha256, "simulate_s": t_scan, "fit_s": t_fit,
             "chosen": result.chosen, "meets_tolerance": result.meets_tolerance, "tolerance_mN": result.tolerance_mN,
             "guard_ops": result.guard_ops, "hull_vertices": len(result.calibration.region.hull),
             "firmware_order": result.firmware_order, "shear_sign": result.calibration.shear_sign,
             "direction_min_uT": result.calibration.direction_min_uT,
             "calibration_json_bytes": {c.label: len(result.calibration_for(c.label).dumps())
                                        for c in result.candidates if c.label in ("poly 4", "mls")}}
    return result, rows, extra


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=BENCH_DIR / "out")
    ap.add_argument("--repeat", type=int, default=7)
    args = ap.parse_args(argv)
    result, rows, extra = run(args.repeat)
    print(f"{'fit':8} {'held-out RMS mN':>17} {'max held-out mN':>17} {'fit RMS mN':>13} {'cond scaled':>11} "
          f"{'cond raw uT':>11} {'ops/eval':>9} {'s/1000 eval':>11} {'x poly 4':>9} {'vs true mN':>13}")
    print(f"{'':8} {'Fz':>8} {'Fr':>8} {'Fz':>8} {'Fr':>8} {'Fz':>6} {'Fr':>6} {'':>11} {'':>11} {'':>9} {'':>11} "
          f"{'':>9} {'Fz':>6} {'Fxy':>6}")
    for r in rows:
        h, m, f = r["rms_holdout_N"], r["max_holdout_N"], r["rms_fit_N"]
        cond = f"{r['condition']:11.3g}" if r["condition"] is not None else f"{'-':>11}"
        raw = f"{r['condition_raw']:11.3g}" if r["condition_raw"] is not None else f"{'-':>11}"
        print(f"{r['label']:8} {1e3 * h['Fz_N']:8.3f} {1e3 * h['Fr_N']:8.3f} {1e3 * m['Fz_N']:8.2f} "
              f"{1e3 * m['Fr_N']:8.2f} {1e3 * f['Fz_N']:6.2f} {1e3 * f['Fr_N']:6.2f} {cond} {raw} "
              f"{r['cost_ops']:9d} {r['time_per_1000_s']:11.2e} {r['ratio_to_poly4_time']:9.2f} "
              f"{1e3 * r['rms_vs_true_N']['Fz_N']:6.2f} {1e3 * r['rms_vs_true_N']['Fxy_N']:6.2f}")
    mls = next(r for r in rows if r["method"] == "mls")
    print(f"MLS: local order {mls['order']}, bandwidth {mls['bandwidth']:.4g} in scaled (u, v)")
    print(f"scan: {extra['rows_in_scan']} rows (simulated in {extra['simulate_s']:.2f} s); fit with "
          f"{len(rows)} candidates and {result.calibration.errors['folds']}-fold cross-validation in "
          f"{extra['fit_s']:.2f} s")
    print(f"chosen (method {load_spec(None).calibration.method.value}, tolerance {extra['tolerance_mN']:g} mN): "
          f"{extra['chosen']}{'' if extra['meets_tolerance'] else ' (NOT within tolerance: ' + result.message + ')'}; "
          f"the firmware's polynomial for MLS: order {extra['firmware_order']}")
    print(f"guard: {extra['hull_vertices']} hull vertices, {extra['guard_ops']} operations per reading; "
          f"shear_sign {extra['shear_sign']:+d}, direction_min {extra['direction_min_uT']:.1f} uT; "
          f"calibration.json bytes {extra['calibration_json_bytes']}")
    args.out.mkdir(parents=True, exist_ok=True)
    doc = {"rows": rows, "extra": extra, "design": "MagOne (embedded spec)", "made_by": "bench/calibrate.py",
           "machine": f"{platform.machine()}, {platform.python_implementation()} {platform.python_version()}"}
    (args.out / "calibration_bench.json").write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    for name, data in chart(result).items():
        (args.out / name).write_bytes(data)
    print(f"wrote {args.out / 'calibration_bench.json'} and {args.out / 'calibration_fit.svg'} (.png)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
