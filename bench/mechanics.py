"""Speed against accuracy of the elastomer models on the MagOne fingertip.

Run from anywhere::

    python bench/mechanics.py [--out DIR] [--reference-mesh MM]

What it prints (times are wall-clock seconds from :func:`time.perf_counter`, caches cleared before each run, so
meshing is included; nothing here asserts on a time):

1. The speed-accuracy table: each normal model (column, Hertz + column, FE at several mesh sizes) with its max
   force error against the finest FE mesh over the compared range (max |F - F_ref| / max F_ref), its time, and
   its time as a fraction of the finest FE's in the same run. If the finest mesh fails before 3 mm (the silicone
   at the magnet's edge over-compresses), the range compared is where it succeeded, and the table says so.
2. MagOne at 3 mm: force per model for the soft / nominal / stiff band (one solve, scaled by mu), the FE at the
   build mesh and how far each FE mesh gets before it reports a failure.
3. Mesh convergence on nested meshes (errors and observed orders).
4. Shear stiffness at the magnet: Timoshenko against the mode-1 FE, for MagOne and for a plate column.

It writes ``<out>/mechanics_bench.json`` and the chart ``<out>/mechanics_bench.svg`` / ``.png`` (matplotlib Agg;
deterministic: fixed svg.hashsalt and no dates in the metadata).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from magfab import load_spec
from magfab.design import derive
from magfab.models import mechanics as mech

BENCH_DIR = Path(__file__).resolve().parent
DEFAULT_OUT = BENCH_DIR / "out"
MESHES_MM = (1.0, 0.75, 0.5, 0.35, 0.25)
DELTA_MAX_MM = 3.0


def _fmt_mesh(h: float | None) -> str:
    return "-" if h is None else f"{h:g}"


def speed_accuracy(body: mech.Body, mu_kPa: float, reference_mm: float) -> dict[str, object]:
    out = mech.measure(body, mu_kPa, DELTA_MAX_MM, mesh_sizes_mm=MESHES_MM, reference_mesh_mm=reference_mm)
    t_ref = out["rows"][-1]["time_s"]
    print(f"Speed against accuracy, MagOne, mu = {mu_kPa:g} kPa, indentation 0..{out['compared_to_mm']:g} mm "
          f"(reference: FE, mesh {reference_mm:g} mm)")
    if out["reference_failure"]:
        print(f"  the reference stops there: {out['reference_failure']}")
    print(f"  {'model':<13} {'mesh mm':>8} {'max rel err':>12} {'time s':>9} {'time/ref':>9}")
    for r in out["rows"]:
        err = "failed" if r["failure"] else f"{r['error']:.2e}"
        print(f"  {r['model']:<13} {_fmt_mesh(r['mesh_mm']):>8} {err:>12} {r['time_s']:>9.4f} "
              f"{r['time_s'] / t_ref:>9.4f}")
    return out


def magone_at_3mm(body: mech.Body, band: tuple[float, float, float]) -> dict[str, object]:
    d = np.linspace(0.0, DELTA_MAX_MM, 13)
    soft, nominal, stiff = band
    print(f"\nMagOne force at {DELTA_MAX_MM:g} mm, band mu = {soft:g} / {nominal:g} / {stiff:g} kPa "
          "(one solve, scaled by mu)")
    result: dict[str, object] = {}
    for name in ("column", "hertz_column"):
        mech.clear_caches()
        t0 = time.perf_counter()
        curves = mech.band_curves(body, band, name, d)
        dt = time.perf_counter() - t0
        forces = [float(curves[k].force_N[-1]) for k in ("soft", "nominal", "stiff")]
        result[name] = {"force_N": forces, "time_s": dt}
        print(f"  {name:<13} " + " / ".join(f"{f:.3f}" for f in forces) + f" N   ({dt:.3f} s)")
    build_mesh = body.radius_mm * mech.BUILD_MESH_FRACTION
    mech.clear_caches()
    t0 = time.perf_counter()
    curves = mech.band_curves(body, band, "fe", d, mesh_mm=build_mesh, on_failure="truncate")
    dt = time.perf_counter() - t0
    nom = curves["nominal"]
    reached = float(nom.indentation_mm[-1])
    forces = [float(curves[k].force_N[-1]) for k in ("soft", "nominal", "stiff")]
    print(f"  {'fe':<13} " + " / ".join(f"{f:.3f}" for f in forces) + f" N at {reached:g} mm   "
          f"(mesh {build_mesh:g} mm, band in {dt:.3f} s)")
    if "failure" in nom.info:
        print(f"    stops: {nom.info['failure']}")
    result["fe_build"] = {"mesh_mm": build_mesh, "reached_mm": reached, "force_N": forces, "time_s": dt,
                          "failure": nom.info.get("failure"),
                          "magnet_displacement_mm": float(nom.magnet_displacement_mm[-1]),
                          "max_stretch": float(nom.max_stretch[-1])}
    print("  how far each FE mesh gets (nominal mu, 0.1 mm steps):")
    reach = []
    for h in MESHES_MM:
        mech.clear_caches()
        c = mech.fe(body, nominal, np.linspace(0.0, DELTA_MAX_MM, 31), mesh_mm=h, on_failure="truncate")
        reach.append({"mesh_mm": h, "reached_mm": float(c.indentation_mm[-1]), "force_N": float(c.force_N[-1]),
                      "failure": c.info.get("failure")})
        print(f"    mesh {h:<5g} reaches {c.indentation_mm[-1]:.1f} mm, F = {c.force_N[-1]:.3f} N"
              + (f"   ({c.info['failure'].split(': ', 1)[1]})" if "failure" in c.info else ""))
    result["fe_reach"] = reach
    return result


def convergence(body: mech.Body, mu_kPa: float) -> dict[str, object]:
    c = mech.convergence(body, mu_kPa, [0.0, 0.5, 1.0], base_mesh_mm=1.0, levels=3)
    print("\nMesh convergence (nested meshes, MagOne, indentation 0..1 mm)")
    print(f"  {'mesh mm':>8} {'F(1 mm) N':>10} {'err vs finest':>14} {'time s':>8}")
    for k, h in enumerate(c.mesh_mm):
        err = f"{c.error[k]:.2e}" if k < c.error.size else "reference"
        print(f"  {h:>8g} {c.force_N[k, -1]:>10.5f} {err:>14} {c.time_s[k]:>8.3f}")
    print("  observed orders (Richardson, consecutive triples): " + ", ".join(f"{r:.2f}" for r in c.rates))
    return {"mesh_mm": c.mesh_mm.tolist(), "error": c.error.tolist(), "rates": c.rates.tolist(),
            "force_1mm_N": c.force_N[:, -1].tolist(), "time_s": c.time_s.tolist()}


def shear(body: mech.Body, mu_kPa: float) -> dict[str, object]:
    print(f"\nShear stiffness at the magnet, mu = {mu_kPa:g} kPa (N/mm)")
    out: dict[str, object] = {}
    plate = mech.Body(radius_mm=6.0, height_mm=4.8, base_height_mm=4.8, tip="flat", magnet_radius_mm=6.0,
                      magnet_height_mm=0.5, magnet_z_mm=4.3)
    for label, b in (("MagOne", body), ("plate column R 6, h 4.3", plate)):
        for ends in ("free", "guided"):
            kt = mech.shear_stiffness(b, mu_kPa, "timoshenko", ends)
            mech.clear_caches()
            t0 = time.perf_counter()
            kf = mech.shear_stiffness(b, mu_kPa, "fe", ends, mesh_mm=0.25)
            dt = time.perf_counter() - t0
            out[f"{label} {ends}"] = {"timoshenko": kt, "fe": kf, "fe_time_s": dt}
            print(f"  {label:<24} {ends:<7} timoshenko {kt:.4f}  fe {kf:.4f}  timoshenko/fe {kt / kf:.3f}  "
                  f"magnet travel {1 / kf:.3f} mm/N  ({dt:.3f} s)")
    return out


def chart(rows: list[dict[str, object]], out_dir: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    plt.rcParams["svg.hashsalt"] = "magfab-mechanics"
    fig, ax = plt.subplots(figsize=(6.4, 4.4))
    floor = min(r["error"] for r in rows if r["error"] > 0) / 3.0
    for r in rows:
        if r["failure"]:
            continue
        err = max(r["error"], floor)
        marker = {"column": "s", "hertz_column": "^", "fe": "o"}[r["model"]]
        ax.loglog(r["time_s"], err, marker, color="C0" if r["model"] == "fe" else "C1")
        label = r["model"] if r["mesh_mm"] is None else f"fe {r['mesh_mm']:g} mm"
        if r["error"] == 0.0:
            label += " (reference)"
        ax.annotate(label, (r["time_s"], err), textcoords="offset points", xytext=(5, 4), fontsize=8)
    ax.set_xlabel("time per force curve, s (cold)")
    ax.set_ylabel("max force error / max force")
    ax.set_title("MagOne elastomer models: error against time")
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    paths = [out_dir / "mechanics_bench.svg", out_dir / "mechanics_bench.png"]
    fig.savefig(paths[0], metadata={"Date": None})
    fig.savefig(paths[1], dpi=120, metadata={"Software": None})
    plt.close(fig)
    return paths


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    ap.add_argument("--reference-mesh", type=float, default=0.15, help="finest FE mesh, mm (default 0.15)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    design = derive(load_spec(None))
    body = mech.Body.from_design(design)
    band = mech.band(design.material)
    print(f"Body: {body}\n")
    t0 = time.perf_counter()
    sa = speed_accuracy(body, band[1], args.reference_mesh)
    result = {"body": body.__dict__, "band_kPa": band, "speed_accuracy": sa,
              "magone_3mm": magone_at_3mm(body, band), "convergence": convergence(body, band[1]),
              "shear": shear(body, band[1])}
    paths = chart(sa["rows"], args.out)
    (args.out / "mechanics_bench.json").write_text(json.dumps(result, indent=2, default=_json) + "\n",
                                                   encoding="utf-8")
    print(f"\nwrote {', '.join(str(p) for p in paths)} and mechanics_bench.json ({time.perf_counter() - t0:.1f} s)")
    return 0


def _json(x: object) -> object:
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    if isinstance(x, float) and math.isnan(x):
        return None
    raise TypeError(type(x))


if __name__ == "__main__":
    raise SystemExit(main())
