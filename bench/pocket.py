"""The magnet's pocket, measured: bonded (the build's model) against a sliding magnet and an open insertion channel.

Run from anywhere::

    python bench/pocket.py [--mesh MM] [--json FILE]

The FE (:func:`magfab.models.mechanics.fe`) bonds the rigid magnet into solid silicone. The design's pocket is the
magnet plus a clearance, reached from the base through an insertion channel and a funnel, and sealed with
Sil-Poxy. This bench solves, on MagOne and the three bench designs (``bench/designs``), at the design's nominal
shear modulus:

* ``bonded``: the build's model;
* ``sliding``: the magnet held by bilateral frictionless contact (no glue, no separation);
* ``open channel``: bonded, with the channel and funnel under the magnet left empty
  (:func:`magfab.models.mechanics.channel_wall`).

It prints a Markdown table of the force and the magnet's travel at 0.5, 1, 2 and 3 mm of indentation, each variant's
difference from bonded in %, and the travel per newton (what the field sees per unit force), and where a variant's
FE stopped (on_failure="truncate": the depth and the reason). Forces and travels scale with mu; the differences in %
do not depend on it.
"""

from __future__ import annotations

import argparse
import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from magfab import load_spec
from magfab.design import derive
from magfab.models import mechanics as mech

BENCH_DIR = Path(__file__).resolve().parent
DESIGNS = (("MagOne", None), ("small_magnet", BENCH_DIR / "designs" / "small_magnet.toml"),
           ("stiff_material", BENCH_DIR / "designs" / "stiff_material.toml"),
           ("flat_tip", BENCH_DIR / "designs" / "flat_tip.toml"))
REPORT_MM = (0.5, 1.0, 2.0, 3.0)
STEPS_MM = np.array([0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0, 2.25, 2.5, 2.75, 3.0])
VARIANTS = ("bonded", "sliding", "open channel")


def solve(name: str, path: Path | None, mesh_mm: float) -> dict[str, object]:
    """The three variants on one design: {variant: {"F": [...], "travel": [...], "failed_at": mm or None, ...}}."""
    design = derive(load_spec(path))
    body = mech.Body.from_design(design)
    el = design.spec.elastomer
    mu = el.shear_modulus_kPa[1] if el.shear_modulus_kPa else mech.band(el.material)[1]
    options = {"bonded": {}, "sliding": {"interface": "sliding"},
               "open channel": {"void": mech.channel_wall(body, design.core_profile)}}
    out: dict[str, object] = {"mu_kPa": mu, "wall": options["open channel"]["void"]}
    for variant, kw in options.items():
        c = mech.fe(body, mu, STEPS_MM, mesh_mm=mesh_mm, on_failure="truncate", **kw)
        pick = [int(np.nonzero(np.isclose(STEPS_MM, d))[0][0]) for d in REPORT_MM]
        n = c.force_N.size
        out[variant] = {"F": [float(c.force_N[i]) if i < n else math.nan for i in pick],
                        "travel": [float(c.magnet_displacement_mm[i]) if i < n else math.nan for i in pick],
                        "failed_at": c.info.get("failed_at_mm"), "failure": c.info.get("failure"),
                        "max_slide_mm": float(np.max(c.info["max_slide_mm"])) if "max_slide_mm" in c.info else 0.0}
    return out


def _pct(x: float, ref: float) -> str:
    return "—" if not (math.isfinite(x) and math.isfinite(ref)) else f"{100.0 * (x / ref - 1.0):+.1f} %"


def _num(x: float, fmt: str) -> str:
    return "—" if not math.isfinite(x) else format(x, fmt)


def table(results: dict[str, dict[str, object]], mesh_mm: float) -> str:
    """The Markdown table: one row per design, variant and depth."""
    lines = [f"FE mesh {mesh_mm:g} mm, nominal mu. Differences from bonded at the same indentation; travel per N is "
             "the magnet's travel over the force (mm/N).", "",
             "| design | variant | delta mm | F N | dF | travel mm | d travel | travel/F mm/N | d travel/F |",
             "|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for name, res in results.items():
        ref = res["bonded"]
        for variant in VARIANTS:
            v = res[variant]
            for k, d in enumerate(REPORT_MM):
                F, u, F0, u0 = v["F"][k], v["travel"][k], ref["F"][k], ref["travel"][k]
                per, per0 = u / F if F else math.nan, u0 / F0 if F0 else math.nan
                same = variant == "bonded"
                lines.append(f"| {name} | {variant} | {d:g} | {_num(F, '.4f')} | {'' if same else _pct(F, F0)} | "
                             f"{_num(u, '.4f')} | {'' if same else _pct(u, u0)} | {_num(per, '.4f')} | "
                             f"{'' if same else _pct(per, per0)} |")
    lines.append("")
    for name, res in results.items():
        for variant in VARIANTS:
            v = res[variant]
            if v["failed_at"] is not None:
                lines.append(f"- {name}, {variant}: stopped at {v['failed_at']:g} mm ({v['failure']})")
            if variant == "sliding":
                lines.append(f"- {name}, sliding: largest slide along the magnet {v['max_slide_mm']:.3f} mm")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--mesh", type=float, default=0.75, help="FE mesh size, mm (0.75: one auto picks for MagOne)")
    ap.add_argument("--json", type=Path, default=None, help="also write the numbers to this file")
    args = ap.parse_args(argv)
    results = {name: solve(name, path, args.mesh) for name, path in DESIGNS}
    print(table(results, args.mesh))
    if args.json:
        args.json.write_text(json.dumps(results, indent=1, default=str) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
