"""Calibration without a force sensor, tried on simulated sensors whose truth is not the fitted model.

Run from anywhere::

    python bench/weights.py [--sensors 50] [--seed 0] [--designs magone,flat_tip,small_magnet] [--centred]
                            [--standard] [--fixed-plan] [--out DIR]

For each design, ``--sensors`` sensors are drawn across the material, magnet and assembly bands, their response
made by the other hyperelastic law, a tilted and offset magnet, the Earth's field turning with the stand and the
chip's noise (:mod:`magfab.models.weighing_study`). Each is calibrated three ways: from the weight plan (twelve
weighings on three stand angles in the weight jig's coins on its heaviest printed cap, as the build plans them,
:meth:`magfab.jig.Jig.plan`; ``--standard``: 1-2-5 standard weights on a 5 g cap), from a full scan of the same sensor
with a force sensor's resolution, and, after a new skin (a new shear modulus and rest distance), from three
weighings with the magnet's and the silicone's parameters kept. Each calibration is scored on the region's grid
(off the scan's points) with the chip's noise: Fz and shear RMS and worst error.

Printed per design: the weight calibration's and the full scan's Fz RMS (median, p90, worst), their ratio
(median, p90, worst; the goal is at most 2), the re-skin's ratio to its own full scan, the coverage of the stated
error bound (the share of sensors whose actual Fz and shear RMS is within it; the goal is 0.9 or more), the shear
ratio, and the sensors with the largest ratio with what sets them apart. ``--centred`` draws every magnet centred
and untilted, so the calibration's own form (Fr from |Bxy|, which an off-axis magnet's lateral field at rest
confuses for both calibrations) does not hide the weights' own error. Writes ``<out>/weights_bench.json``.

Nothing here asserts: the figures are for reading (tests/models/test_weighing.py holds a smaller sample to the goals).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def _design(name: str):
    from importlib.resources import files

    from magfab import derive, load_spec

    path = HERE / "designs" / f"{name}.toml"
    return derive(load_spec(path if path.exists() else files("magfab") / "examples" / f"{name}.toml"))


def _stats(values: list[float]) -> dict[str, float]:
    v = np.asarray(values, float)
    return {"median": float(np.median(v)), "p90": float(np.quantile(v, 0.9)), "worst": float(v.max())}


def run(name: str, sensors: int, seed: int, centred: bool, standard: bool = False, adaptive: bool = True) -> dict:
    from magfab.jig import jig_plans
    from magfab.models.predict import predict
    from magfab.models.weighing import PARAMS, SensorModel
    from magfab.models.weighing_study import trial, truth_model

    design = _design(name)
    prediction = predict(design)
    model = SensorModel.of(design, prediction)
    truth = truth_model(design, prediction, model)
    rng = np.random.default_rng(seed)
    # the weight jig's coins and its heaviest printed cap, as the build's plan (--standard: 1-2-5 weights, a 5 g cap)
    plan_of = None if standard else jig_plans(design, prediction)
    rows = []
    t0 = time.perf_counter()
    for _ in range(sensors):
        rows.append(trial(design, prediction, model, truth, rng, centred=centred, adaptive=adaptive, plan_of=plan_of))
    elapsed = time.perf_counter() - t0
    ratio = [r.weights["fz_rms_N"] / r.full["fz_rms_N"] for r in rows]
    worst = sorted(range(sensors), key=lambda k: -ratio[k])[:3]
    out = {
        "design": name, "sensors": sensors, "seed": seed, "centred": centred, "loads": "1-2-5" if standard else "coins",
        "adaptive": adaptive,
        "weights_fz_rms_mN": _stats([1000 * r.weights["fz_rms_N"] for r in rows]),
        "full_fz_rms_mN": _stats([1000 * r.full["fz_rms_N"] for r in rows]),
        "weights_fz_worst_mN": _stats([1000 * r.weights["fz_worst_N"] for r in rows]),
        "full_fz_worst_mN": _stats([1000 * r.full["fz_worst_N"] for r in rows]),
        "fz_ratio": _stats(ratio),
        "shear_ratio": _stats([r.weights["shear_rms_N"] / r.full["shear_rms_N"] for r in rows]),
        "weights_shear_rms_mN": _stats([1000 * r.weights["shear_rms_N"] for r in rows]),
        "full_shear_rms_mN": _stats([1000 * r.full["shear_rms_N"] for r in rows]),
        "reskin_fz_ratio": _stats([r.reskin["fz_rms_N"] / r.reskin_full["fz_rms_N"] for r in rows]),
        "reskin_shear_ratio": _stats([r.reskin["shear_rms_N"] / r.reskin_full["shear_rms_N"] for r in rows]),
        "coverage_fz": float(np.mean([r.weights["fz_rms_N"] <= r.bound_fz_rms_N for r in rows])),
        "coverage_shear": float(np.mean([r.weights["shear_rms_N"] <= r.bound_shear_rms_N for r in rows])),
        "seconds_per_sensor": elapsed / sensors,
        "reach": _stats([r.reach for r in rows]),
        "ratios": [round(x, 4) for x in ratio],
        "reskin_ratios": [round(r.reskin["fz_rms_N"] / r.reskin_full["fz_rms_N"], 4) for r in rows],
        "worst_sensors": [{"ratio": ratio[k], "truth": dict(zip(PARAMS, map(float, rows[k].sensor.theta))),
                           "weights_fz_rms_mN": 1000 * rows[k].weights["fz_rms_N"],
                           "full_fz_rms_mN": 1000 * rows[k].full["fz_rms_N"]} for k in worst],
    }
    return out


def _line(r: dict) -> str:
    f = lambda s: f"{s['median']:.2f}/{s['p90']:.2f}/{s['worst']:.2f}"
    g = lambda s: f"{s['median']:.1f}/{s['p90']:.1f}/{s['worst']:.1f}"
    tags = [t for t, on in (("centred", r["centred"]), ("1-2-5", r["loads"] == "1-2-5"),
                            ("fixed plan", not r["adaptive"])) if on]
    return (f"| {r['design']}{''.join(f' ({t})' for t in tags)} | {r['sensors']} | {g(r['weights_fz_rms_mN'])} | "
            f"{g(r['full_fz_rms_mN'])} | {f(r['fz_ratio'])} | {f(r['reskin_fz_ratio'])} | {f(r['shear_ratio'])} | "
            f"{r['coverage_fz']:.2f} / {r['coverage_shear']:.2f} | {r['reach']['worst']:.2f} |")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sensors", type=int, default=50)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--designs", default="magone,flat_tip,small_magnet")
    p.add_argument("--centred", action="store_true")
    p.add_argument("--standard", action="store_true", help="1-2-5 standard weights on a 5 g cap, not the jig's coins")
    p.add_argument("--fixed-plan", action="store_true",
                   help="the softest skin's plan for every sensor (as the build ships it), not one set by the first "
                   "two weighings")
    p.add_argument("--out", type=Path, default=Path(tempfile.gettempdir()) / "magfab-bench")
    p.add_argument("--package", action="store_true",
                   help="also add the rows (per-sensor ratios, no seconds) to magfab/weights_bench.json, which every "
                   "build's report charts (a row of the same design, draw and plan is replaced)")
    a = p.parse_args(argv)
    print("| design | sensors | weights Fz RMS mN (median/p90/worst) | full scan Fz RMS mN | Fz ratio | re-skin Fz "
          "ratio | shear ratio | bound coverage Fz / shear | heaviest load over the skin's range (worst) |")
    print("|---|---|---|---|---|---|---|---|---|")
    results = []
    for name in a.designs.split(","):
        r = run(name, a.sensors, a.seed, a.centred, a.standard, not a.fixed_plan)
        results.append(r)
        print(_line(r), flush=True)
    for r in results:
        for w in r["worst_sensors"]:
            t = w["truth"]
            print(f"{r['design']}: ratio {w['ratio']:.2f} (weights {w['weights_fz_rms_mN']:.1f} mN, full scan "
                  f"{w['full_fz_rms_mN']:.1f} mN): mu x{np.exp(t['log_mu']):.2f}, Br x{np.exp(t['log_br']):.3f}, "
                  f"d {t['d_mm']:+.3f} mm, tilt ({t['tilt_x_deg']:.1f}, {t['tilt_y_deg']:.1f}) deg, offset "
                  f"({t['offset_x_mm']:.3f}, {t['offset_y_mm']:.3f}) mm")
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "weights_bench.json").write_text(json.dumps(results, indent=1, sort_keys=True) + "\n")
    if a.package:
        args = list(argv if argv is not None else sys.argv[1:])
        if "--out" in args:  # where this machine put its files is no part of the measurement
            del args[args.index("--out"):args.index("--out") + 2]
        _package(results, " ".join(["python bench/weights.py", *args]))
    return 0


def _package(results: list[dict], command: str) -> None:
    """The rows into magfab/weights_bench.json (deterministic: no timings, no truth parameters)."""
    path = HERE.parent / "magfab" / "weights_bench.json"
    keep = ("design", "sensors", "seed", "centred", "loads", "adaptive", "fz_ratio", "reskin_fz_ratio", "ratios",
            "reskin_ratios", "coverage_fz", "coverage_shear")
    doc = json.loads(path.read_text()) if path.exists() else {"rows": []}
    key = lambda r: (r["design"], r["centred"], r["loads"], r["adaptive"])
    rows = {key(r): r for r in doc["rows"]}
    for r in results:
        rows[key(r)] = {k: r[k] for k in keep} | {"command": command}
    doc = {"what": "a weight calibration's held-out Fz RMS over a full scan's, per drawn sensor (docs/models.md M25)",
           "rows": list(rows.values())}
    path.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")


if __name__ == "__main__":
    sys.exit(main())
