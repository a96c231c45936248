"""Field-model benchmark: each model's error against magpylib and its time, and the speed-accuracy chart.

Run from anywhere::

    python bench/field.py [--out DIR] [--repeat N] [--n N]

What it measures, on the MagOne magnet (D = 5 mm, H = 2 mm, N35 nominal Br from recipes/magnets.toml)
over its working volume (sensing point d = d_min..d_max below the lower face, lateral offset 0..R,
n x n points, default 317^2 ~ 10^5):

1. For every model in ``magfab.models.field.MODELS``, via ``magfab.models.field.measure``: the largest relative
   vector error |B - B_ref| / |B_ref| against ``magpylib.magnet.Cylinder(...).getB`` (and the same
   normalised by the largest |B_ref|), the median wall time of N calls scaled to 10^5 points, and the
   speed ratio to magpylib timed in the same run. Approximate models run with ``rtol=None`` so their
   error is measured where they would refuse.
2. A candidate that is *not* in the package: our own Derby & Olbert field with Bulirsch's ``cel``
   (both faces and both integrals sharing one AGM iteration). It is here so the decision not to keep
   it can be re-checked: it has to beat magpylib's kernel (what ``exact`` calls), not only ``getB``.
3. A table on stdout, ``<out>/field_bench.json``, and the chart (log-log, error against time, one point
   per model) as ``<out>/field_bench.svg`` and ``.png``.

Nothing here asserts on a time: the figures are for reading, not for failing.
"""

from __future__ import annotations

import argparse
import json
import math
import platform
import sys
from collections.abc import Sequence
from dataclasses import asdict
from pathlib import Path

import numpy as np

from magfab import load_spec
from magfab.models import field as F
from magfab.models.field.exact import _kernel

BENCH_DIR = Path(__file__).resolve().parent
DEFAULT_OUT = BENCH_DIR / "out"
STEM = "field_bench"
ERROR_FLOOR = 1e-16  # errors at or below machine precision are drawn here on the log axis


# ---- the candidate that was not kept --------------------------------------------------------------


def bulirsch_cel_field(magnet: F.Magnet, points_mm: np.ndarray) -> np.ndarray:
    """Derby & Olbert (2010) field in G at (N, 3) points (mm), our own implementation.

    B_rho = Br/pi [a+ C(k+, 1, 1, -1) - a- C(k-, 1, 1, -1)], Bz = Br/pi R/(R + r) [b+ C(k+, g^2, 1, g) - ...]
    with Bulirsch's complete integral C(kc, p, c, s); the four integrals share one AGM sequence per
    face. Same accuracy as magpylib (checked below); no surface or far-field checks.
    """
    p = np.asarray(points_mm, float)
    R, z0 = magnet.radius_mm, magnet.height_mm / (2.0 * magnet.radius_mm)
    rho = np.hypot(p[:, 0], p[:, 1]) / R
    z = p[:, 2] / R
    dpr, dmr = 1.0 + rho, 1.0 - rho
    dpr2, dmr2 = dpr * dpr, dmr * dmr
    gam = dmr / dpr
    pb0, sb0 = np.abs(gam), np.sign(gam)
    zero = gam == 0  # r = R: p = gamma^2 = 0 takes Bulirsch's p <= 0 branch
    terms = []
    for zz in (z + z0, z - z0):
        zz2 = zz * zz
        den = zz2 + dpr2
        kc = np.sqrt((zz2 + dmr2) / den)
        pa = np.ones_like(kc)
        ca, sa = pa.copy(), -pa
        pb, cb, sb = pb0.copy(), pa.copy(), sb0.copy()
        pb[zero], sb[zero] = kc[zero], kc[zero]
        em, qc, kk = pa.copy(), kc, kc
        while True:
            for (pp, cc, ss) in ((pa, ca, sa), (pb, cb, sb)):
                g = kk / pp
                t = ss / pp
                t += cc
                g *= cc
                g += ss
                g *= 2.0
                ss[...] = g
                cc[...] = t
                pp += kk / pp
            g, em = em, em + qc
            if np.all(np.abs(g - qc) <= g * 1e-8):
                break
            qc = 2.0 * np.sqrt(kk)
            kk = em * qc
        sq = np.sqrt(den)
        terms.append(((sa + ca * em) / (em * (em + pa)) / sq, (sb + cb * em) / (em * (em + pb)) / sq * zz))
    brho = 0.5 * (terms[0][0] - terms[1][0])  # (pi/2) from cel, 1/pi from B0
    bz = 0.5 * (terms[0][1] - terms[1][1]) / dpr
    q = np.divide(brho, rho * R, out=np.zeros_like(brho), where=rho > 0)
    scale = magnet.remanence_T * F.GAUSS_PER_TESLA
    return np.column_stack([q * p[:, 0], q * p[:, 1], bz]) * scale


def kernel_only(magnet: F.Magnet, points_mm: np.ndarray) -> np.ndarray:
    """magpylib's kernel with the same bare conversions as the candidate (no checks): its fair rival."""
    p = np.asarray(points_mm, float)
    rho = np.hypot(p[:, 0], p[:, 1])
    bz, brho = _kernel(magnet, rho, p[:, 2])
    q = np.divide(brho, rho, out=np.zeros_like(brho), where=rho > 0)
    return np.column_stack([q * p[:, 0], q * p[:, 1], bz]) * (magnet.remanence_T * F.GAUSS_PER_TESLA)


CANDIDATES = (
    ("magpylib kernel, bare", "magpylib.core kernel, no checks (the rival of the candidate)", kernel_only),
    ("own Bulirsch cel", "our Derby-Olbert + Bulirsch cel, shared AGM (not kept)", bulirsch_cel_field),
)


# ---- report ---------------------------------------------------------------------------------------


def run(n: int, repeat: int) -> dict[str, object]:
    """Every figure of the benchmark, as a JSON-ready dict (G, s, mm)."""
    spec = load_spec(None)
    magnet = F.Magnet.from_spec(spec)
    d_min, d_max = spec.sensor.d_min_mm, spec.sensor.d_max_mm
    rows = F.measure(magnet, d_min, d_max, n=n, repeat=repeat, extra=CANDIDATES)
    table = F.surrogate_table(magnet.aspect)
    return {
        "magnet": asdict(magnet),
        "working_volume": {"d_min_mm": d_min, "d_max_mm": d_max, "r_max_mm": magnet.radius_mm, "points": n * n},
        "repeat": repeat,  # timed calls per model, round-robin
        "rows": [asdict(r) for r in rows],
        "surrogate_table": {"aspect": table.aspect, "cells": [table.ns, table.nv], "self_check_error": table.max_error,
                            "build_s": table.build_s, "bytes": table.coef.nbytes},
        "environment": {"python": platform.python_version(), "machine": platform.machine(),
                        "numpy": np.__version__, "magpylib": _version("magpylib")},
    }


def _version(module: str) -> str:
    import importlib

    return getattr(importlib.import_module(module), "__version__", "?")


def format_report(res: dict[str, object]) -> str:
    """The table printed on stdout."""
    wv, mg = res["working_volume"], res["magnet"]
    lines = [
        f"Field models, MagOne magnet R = {mg['radius_mm']:g} mm, H = {mg['height_mm']:g} mm, "
        f"Br = {mg['remanence_T']:g} T; working volume d = {wv['d_min_mm']:g}..{wv['d_max_mm']:g} mm, "
        f"r = 0..{wv['r_max_mm']:g} mm, {wv['points']} points; median (and min) of {res['repeat']} round-robin calls",
        "",
        f"{'model':<22} {'max rel err':>11} {'norm err':>9} {'ms/1e5 pts':>10} {'(min)':>7} {'vs magpylib':>11} "
        f"{'setup s':>8}",
    ]
    for r in res["rows"]:
        lines.append(f"{r['model']:<22} {r['relative_error']:>11.2e} {r['normalised_error']:>9.1e} "
                     f"{1e3 * r['time_per_1e5_s']:>10.2f} {1e3 * r['time_min_per_1e5_s']:>7.2f} "
                     f"{r['speedup_vs_magpylib']:>10.1f}x {r['setup_s']:>8.3f}")
    t = res["surrogate_table"]
    by = {r["model"]: r for r in res["rows"]}
    own, bare = by["own Bulirsch cel"], by["magpylib kernel, bare"]
    lines += [
        "",
        f"surrogate table: H/R = {t['aspect']:g}, {t['cells'][0]} x {t['cells'][1]} cells, "
        f"{t['bytes'] / 1e6:.1f} MB, self-check error {t['self_check_error']:.2e}, built in {t['build_s']:.3f} s",
        f"own Bulirsch cel vs magpylib's bare kernel: {bare['time_per_1e5_s'] / own['time_per_1e5_s']:.2f}x "
        f"(error {own['relative_error']:.1e} vs {bare['relative_error']:.1e}); not kept unless clearly faster",
        _order_note(res["rows"]),
    ]
    return "\n".join(lines)


def _order_note(rows: Sequence[dict[str, object]]) -> str:
    """Whether the measured times agree with the registry's cost order (used by choose())."""
    times = {r["model"]: r["time_per_1e5_s"] for r in rows}
    order = sorted(F.MODELS, key=lambda k: F.MODELS[k].cost_rank)
    measured = sorted(order, key=times.get)
    if measured == order:
        return f"cost order {' < '.join(order)}: agrees with the measured times"
    return (f"cost order {' < '.join(order)}: measured {' < '.join(measured)} "
            "(close times swap between runs; choose() uses the registry order)")


def write_chart(res: dict[str, object], stem: Path) -> list[Path]:
    """Log-log error against time, one point per row; SVG and PNG with fixed metadata."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    matplotlib.rcParams["svg.hashsalt"] = "magfab-field-bench"
    fig, ax = plt.subplots(figsize=(7.5, 5.0))
    placed: list[tuple[float, float]] = []
    for r in res["rows"]:
        x, y = 1e3 * r["time_per_1e5_s"], max(r["relative_error"], ERROR_FLOOR)
        kept = r["model"] in F.MODELS or r["model"] == "magpylib"
        ax.loglog([x], [y], "o" if kept else "s", color="#4c72b0" if kept else "#999999", ms=7)
        # stack the labels of points that (nearly) coincide instead of printing them over each other
        crowd = sum(1 for px, py in placed if abs(math.log10(x / px)) < 0.3 and abs(math.log10(y / py)) < 1.0)
        placed.append((x, y))
        label = r["model"] + (" (reference)" if r["model"] == "magpylib" else "")
        ax.annotate(label, (x, y), xytext=(7, -11 * crowd), textcoords="offset points", fontsize=8, va="center",
                    color="black" if kept else "#666666")
    ax.axhline(1e-3, color="#dd8452", lw=1, ls="--")
    ax.annotate("0.1 % target", (1.0, 1e-3), xycoords=("axes fraction", "data"), ha="right", va="bottom",
                fontsize=8, color="#dd8452")
    ax.set_xlim(ax.get_xlim()[0], ax.get_xlim()[1] * 3)  # room for the labels of the slowest
    ax.set_xlabel("time per 10^5 points, ms (median)")
    ax.set_ylabel(f"max relative error over the working volume (floor {ERROR_FLOOR:g})")
    ax.set_title("Field models: speed against accuracy (MagOne magnet)")
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    fig.tight_layout()
    paths = [stem.with_suffix(".svg"), stem.with_suffix(".png")]
    fig.savefig(paths[0], metadata={"Date": None, "Creator": None})
    fig.savefig(paths[1], dpi=110, metadata={"Software": None})
    plt.close(fig)
    return paths


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: run the benchmark, print the table, write JSON and the chart; exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (default bench/out)")
    parser.add_argument("--repeat", type=int, default=7, help="timed calls per model (default 7)")
    parser.add_argument("--n", type=int, default=317, help="grid points per axis of the working volume (default 317)")
    args = parser.parse_args(argv)
    if args.repeat < 1 or args.n < 2:
        parser.error("--repeat must be at least 1 and --n at least 2")
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    res = run(args.n, args.repeat)
    print(format_report(res))
    json_path = out / f"{STEM}.json"
    json_path.write_text(json.dumps(res, indent=2, default=_json_number) + "\n", encoding="utf-8")
    print(f"\nwrote {json_path}")
    for path in write_chart(res, out / STEM):
        print(f"wrote {path}")
    return 0


def _json_number(x: object) -> object:
    if isinstance(x, (np.floating, np.integer)):
        return x.item()
    raise TypeError(f"not JSON: {x!r}")


if __name__ == "__main__":
    sys.exit(main())
