"""Every model's error against its reference and its time, in one run, and the speed-accuracy chart.

Run from anywhere::

    python bench/models.py [--out DIR] [--repeat N] [--reference-mesh MM] [--ship]

On the MagOne design (the embedded spec):

1. Field (``magfab.models.field.measure``): every field model over the working volume (d_min..d_max below the
   magnet, lateral offset 0..R, ~10^5 points) against magpylib's ``Cylinder``; median time per 10^5 points.
2. Elastomer (``magfab.models.mechanics.measure``): the column and Hertz-plus-column closed forms and the FE model at
   several mesh sizes against the finest FE mesh, over the indentation range the reference reaches;
   time per force curve at the nominal modulus.
3. Shear: the Timoshenko column against the mode-1 FE at the finest mesh (load on the magnet); and the shear as the
   build applies it (through the contact patch, the magnet shifting and tilting): the chip's lateral sensitivity
   at rest on the build's meshes against the finest.
4. The whole MagOne prediction (``magfab.models.predict.predict``, band included), median of N runs.

Prints one table, writes ``<out>/model_bench.json`` and ``<out>/model_bench.svg``/``.png`` (error against
time, log-log, one point per model and mesh size). With ``--ship`` it also writes the table to
``magfab/model_bench.json``, which every build charts as ``plots/speed_accuracy.*`` (so the build's chart is
deterministic: it shows these measured figures, not a timing taken during the build).

Nothing here asserts on a time: the figures are for reading, not for failing.
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import sys
import time
from pathlib import Path

from magfab import derive, load_spec
from magfab.models import field as F
from magfab.models import mechanics as M
from magfab.models.predict import predict

BENCH_DIR = Path(__file__).resolve().parent
SHIPPED = BENCH_DIR.parent / "magfab" / "model_bench.json"


def rows(repeat: int, reference_mesh_mm: float) -> tuple[list[dict], dict]:
    design = derive(load_spec(None))
    spec = design.spec
    magnet = F.Magnet.from_spec(spec)
    out: list[dict] = []
    for m in F.measure(magnet, spec.sensor.d_min_mm, design.d_rest_mm, repeat=repeat):
        out.append({"family": "field", "model": m.model, "label": m.model, "error": m.relative_error,
                    "time_s": m.time_per_1e5_s, "unit": "per 10^5 points",
                    "reference": "magpylib Cylinder", "ratio_to_reference_time": 1.0 / m.speedup_vs_magpylib})
    body = M.Body.from_design(design)
    mu = M.band(spec.elastomer.material)[1]
    # Over the depth the build solves the FE to (predict.normal_curve): the scan depth, or 1.25 x the travel to d_min.
    depth = min(float(spec.calibration.scan_z_mm), 1.25 * (design.d_rest_mm - spec.sensor.d_min_mm))
    mech = M.measure(body, mu, depth, reference_mesh_mm=reference_mesh_mm)
    t_ref = next(r["time_s"] for r in mech["rows"] if r["model"] == "fe" and r["error"] == 0.0)
    for r in mech["rows"]:
        label = r["model"] if r.get("mesh_mm") is None else f"fe {r['mesh_mm']:g} mm"
        out.append({"family": "mechanics", "model": r["model"], "label": label, "error": r["error"],
                    "time_s": r["time_s"], "unit": "per force curve", "mesh_mm": r.get("mesh_mm"),
                    "reference": f"fe {reference_mesh_mm:g} mm", "ratio_to_reference_time": r["time_s"] / t_ref})
    t = time.perf_counter()
    k_fe = M.shear_stiffness(body, mu, "fe", mesh_mm=reference_mesh_mm)
    t_fe = time.perf_counter() - t
    t = time.perf_counter()
    k_t = M.shear_stiffness(body, mu, "timoshenko")
    t_t = time.perf_counter() - t
    t = time.perf_counter()
    k_b = M.shear_stiffness(body, mu, "fe")  # the build's mesh (radius / 12)
    t_b = time.perf_counter() - t
    for label, k, dt, mesh in (("timoshenko", k_t, t_t, None), ("fe build mesh", k_b, t_b, None),
                               (f"fe {reference_mesh_mm:g} mm", k_fe, t_fe, reference_mesh_mm)):
        out.append({"family": "shear", "model": label.split()[0], "label": f"shear {label}",
                    "error": abs(k - k_fe) / k_fe,
                    "time_s": dt, "unit": "per stiffness", "reference": f"shear fe {reference_mesh_mm:g} mm",
                    "ratio_to_reference_time": dt / t_fe, "mesh_mm": mesh})
    # Shear as the build applies it (through the contact patch; the magnet shifts and tilts): the chip's lateral
    # sensitivity at rest, G/N, on the build's meshes against the reference mesh.
    gap, rest = design.d_rest_mm, spec.calibration.scan_step_mm

    def surface(h: float | None) -> tuple[float, float]:
        t0 = time.perf_counter()
        r = M.shear_response(body, mu, (0.0,), mesh_mm=h, rest_indentation_mm=rest)
        return float(F.lateral_field(magnet, gap, r.displacement_mm_per_N[0], r.tilt_rad_per_N[0])), \
            time.perf_counter() - t0

    s_ref, t_sref = surface(reference_mesh_mm)
    for h in (1.0, 0.75, reference_mesh_mm):
        sv, dt = (s_ref, t_sref) if h == reference_mesh_mm else surface(h)
        out.append({"family": "shear", "model": "surface", "label": f"shear surface {h:g} mm",
                    "error": abs(sv - s_ref) / abs(s_ref), "time_s": dt, "unit": "per sensitivity at rest",
                    "reference": f"shear surface {reference_mesh_mm:g} mm", "ratio_to_reference_time": dt / t_sref,
                    "mesh_mm": h})
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        pred = predict(design)
        times.append(time.perf_counter() - t)
    extra = {"prediction_s": statistics.median(times), "prediction_min_s": min(times),
             "mechanics_compared_to_mm": mech["compared_to_mm"], "reference_failure": mech["reference_failure"],
             "models_chosen": {m.family: m.name for m in pred.models}}
    return out, extra


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=BENCH_DIR / "out")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--reference-mesh", type=float, default=0.2)
    ap.add_argument("--ship", action="store_true", help="also write magfab/model_bench.json for the builds' chart")
    args = ap.parse_args(argv)
    table, extra = rows(args.repeat, args.reference_mesh)
    print(f"{'family':10} {'model':18} {'max rel. error':>15} {'time':>12}  {'x ref. time':>11}  unit")
    for r in table:
        print(f"{r['family']:10} {r['label']:18} {r['error']:15.3g} {r['time_s']:10.4f} s  "
              f"{r['ratio_to_reference_time']:11.4f}"
              f"  {r['unit']} (reference: {r['reference']})")
    print(f"whole MagOne prediction (band included): median {extra['prediction_s']:.2f} s, "
          f"min {extra['prediction_min_s']:.2f} s over {args.repeat} runs; models {extra['models_chosen']}")
    print(f"elastomer models compared over 0-{extra['mechanics_compared_to_mm']:.2f} mm of indentation "
          f"(the reference mesh stopped: {extra['reference_failure']})")
    doc = {"rows": table, "extra": extra,
           "machine": f"{platform.machine()}, {platform.python_implementation()} {platform.python_version()}",
           "design": "MagOne (embedded spec)", "made_by": "bench/models.py"}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "model_bench.json").write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    if args.ship:
        SHIPPED.write_text(json.dumps(doc, indent=1, sort_keys=True) + "\n")
    import matplotlib
    matplotlib.use("Agg")
    from magfab.export import figures as plots
    from magfab.models.predict import predict as run
    design = derive(load_spec(None))
    for name, data in plots.figures(design, run(design), table).items():
        if name.startswith("speed_accuracy"):
            (args.out / name.replace("speed_accuracy", "model_bench")).write_bytes(data)
    return 0


if __name__ == "__main__":
    sys.exit(main())
