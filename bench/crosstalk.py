"""The crosstalk budget on MagOne-sized taxels: the least pitch per layout, skin and polarity, and what the skin's
coupling model costs against finer meshes.

Run from anywhere::

    python bench/crosstalk.py [--out DIR]

What it prints (times are wall-clock seconds from :func:`time.perf_counter`, given as ratios within this run; nothing
here asserts on a time):

1. The skin coupling (:func:`magfab.models.mechanics.coupling.coupling`) for the MagOne skin at the build's mesh
   (0.1 mm cells at the load) against coarser and finer ones: dofs, time as a fraction of the finest's, and the
   largest difference in c(r) from the finest over 4-40 mm; then a thick layer against Boussinesq's half-space.
2. The least pitch of a 2x2 and a 1x5 of the default taxel (MagOne: every section but [array] at its default), as
   separate tips and as one continuous skin, same and alternating polarity, against the default tolerance (the
   taxel's normal resolution): without the host's compensation (what the build's ``min_pitch_mm`` holds), with it
   (``min_pitch_compensated_mm``), and with the neighbours only pressed, not slid (where polarity matters). The
   sweep starts below the parts' minimum (at the magnet's diameter plus 0.5 mm) so the field's own limit shows;
   a pitch under the parts' minimum (13 mm for separate tips with their lips, 5.5 mm for a skin) cannot be built.
   Also the magnets' net force on taxel 0 (a corner, an end) and the lateral shift it gives through the softest
   shear stiffness, and the most the neighbours' Bz at rest adds to a chip's own (its sign: towards saturation at
   d_min; the chip's margin there is printed), at the parts' minimum pitch.

It writes ``<out>/crosstalk_bench.json``.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from magfab import derive, parse_spec
from magfab.models import crosstalk as X
from magfab.models.mechanics.coupling import boussinesq_ratio, coupling
from magfab.models.predict import predict

DEFAULT_OUT = Path(__file__).resolve().parent / "out"
CELLS_MM = (0.2, 0.1, 0.05, 0.025)  # 0.1: the build's
LAYOUTS = {"2x2": (2, 2), "1x5": (1, 5)}
SKINS = ("separate", "continuous")


def coupling_cost(design) -> dict[str, object]:
    depth = design.elastomer_height_mm - design.pocket_roof_z_mm + design.magnet_height_mm / 2.0
    H = design.elastomer_height_mm
    runs = []
    for cell in CELLS_MM:
        t = time.perf_counter()
        c = coupling(H, depth, 60.0, cell_mm=cell)
        runs.append((cell, c, time.perf_counter() - t))
    r = np.linspace(4.0, 40.0, 73)
    finest, t_ref = runs[-1][1], runs[-1][2]
    rows = [{"cell_mm": cell, "dofs": c.dofs, "time_ratio": dt / t_ref,
             "max_diff": float(np.abs(c.at(r) - finest.at(r)).max())} for cell, c, dt in runs]
    print(f"Skin coupling, layer {H:.2f} mm, magnets {depth:.2f} mm deep, reach 60 mm (finest: {CELLS_MM[-1]} mm)")
    print(f"  {'cell mm':>8} {'dofs':>8} {'time/finest':>12} {'max |dc|, 4-40 mm':>19}")
    for row in rows:
        print(f"  {row['cell_mm']:>8g} {row['dofs']:>8d} {row['time_ratio']:>12.3f} {row['max_diff']:>19.2e}")
    rb = np.array([2.0, 5.0, 10.0])
    thick = coupling(300.0, depth, 12.0)
    err = float(np.max(np.abs(thick.at(rb) / boussinesq_ratio(rb, depth) - 1.0)))
    print(f"  a 300 mm layer against Boussinesq at r = 2, 5, 10 mm: max relative error {err:.3f}")
    at = {f"{p:g}": float(runs[1][1].at(p)) for p in (5.5, 10.0, 14.0, 20.0)}
    print("  c at " + ", ".join(f"{k} mm: {v:+.4f}" for k, v in at.items()))
    return {"layer_mm": H, "depth_mm": depth, "rows": rows, "boussinesq_error": err, "c_at_mm": at}


def least_pitches(tol_override: float | None = None) -> list[dict[str, object]]:
    single = derive(parse_spec('name = "magone"'))
    pred = predict(single)
    out = []
    own = X.fieldmod.exact(X.fieldmod.Magnet.from_design(single),
                           np.array([[0.0, 0.0, -(single.spec.sensor.d_min_mm + single.magnet_height_mm / 2)]]))[0, 2]
    print(f"\nA chip's own Bz at d_min {own:.0f} G, full scale {pred.chip.full_scale_z_G:.0f} G: "
          f"{pred.chip.full_scale_z_G - own:.0f} G of margin")
    print(f"Least pitch, MagOne-sized taxels, tolerance {pred.normal.resolution_mN:.2f} mN (normal resolution)")
    print(f"  {'layout':<6} {'skin':<11} {'polarity':<12} {'parts min':>9} {'field':>7} {'compensated':>12} "
          f"{'pressed only':>13} {'force at min, mN':>17} {'shift um':>9} {'Bz at min, G':>13}")
    for name, (rows, cols) in LAYOUTS.items():
        for skin in SKINS:
            d = derive(parse_spec(f'name = "b"\n[array]\nrows = {rows}\ncols = {cols}\npitch_mm = 14\nskin = "{skin}"'
                                 '\n[mould]\ntessellation_tolerance_mm = 0.02'))  # a 1x5 skin's mould: no physics
            loads = X._Loads.of(d, pred)
            tol = tol_override or pred.normal.resolution_mN
            curve = None
            if d.continuous:
                depth = d.elastomer_height_mm - d.pocket_roof_z_mm + d.magnet_height_mm / 2.0
                curve = coupling(d.elastomer_height_mm, depth, 60.0)  # the build's cap on the reach
            sweep = np.geomspace(2 * loads.magnet.radius_mm + 0.5, 80.0, 40)
            for alt in (False, True):
                s = X._signs(d, alt)
                field = X.least_pitch(d, loads, s, curve, sweep, tol)[1]
                comp = X.least_pitch(d, loads, s, curve, sweep[::2], tol, compensate=True, steps=14)[1]
                pressed = X.least_pitch(d, replace(loads, shear_travel_mm=1e-9), s, curve, sweep, tol)[1]
                p = d.array.min_pitch_mm
                xy = np.array([[t.x_mm, t.y_mm] for t in d.taxels])
                xy = xy.mean(axis=0) + (xy - xy.mean(axis=0)) * p / d.array.pitch_mm
                end = float(np.hypot(*X.magnet_forces(loads, xy, s)[0]))  # taxel 0: a corner, an end
                bz = float((s * X.layout_errors(loads, xy, s)[2][:, 2]).max())  # towards the own magnet's sign
                row = {"layout": name, "skin": skin, "polarity": "alternating" if alt else "same",
                       "parts_min_mm": d.array.min_pitch_mm, "field_mm": field, "compensated_mm": comp,
                       "pressed_only_mm": pressed, "end_force_at_parts_min_mN": end, "offset_z_at_parts_min_G": bz,
                       "end_shift_at_parts_min_um": end / loads.shear_stiffness_N_per_mm, "tolerance_mN": tol}
                out.append(row)
                f = lambda v: "none" if v is None else f"{v:.1f}"
                print(f"  {name:<6} {skin:<11} {row['polarity']:<12} {d.array.min_pitch_mm:>9.1f} {f(field):>7} "
                      f"{f(comp):>12} {f(pressed):>13} {end:>17.2f} "
                      f"{row['end_shift_at_parts_min_um']:>9.1f} {bz:>+13.1f}")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT)
    ap.add_argument("--tolerance-mN", type=float, default=None, help="default: the taxel's normal resolution")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    design = derive(parse_spec('name = "skin"\n[array]\nrows = 2\ncols = 2\npitch_mm = 10\nskin = "continuous"'))
    result = {"coupling": coupling_cost(design), "least_pitch": least_pitches(args.tolerance_mN)}
    (args.out / "crosstalk_bench.json").write_text(json.dumps(result, indent=2) + "\n", encoding="utf-8")
    print(f"\nwrote {args.out / 'crosstalk_bench.json'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
