"""The closed-mould checks (magfab/fit.py, manifold3d on the exported meshes) against the same checks done
with OCCT booleans on the exact CadQuery solids, in one run: time as a ratio and the results side by side.

    python bench/fit.py [SPEC.toml] [--repeat N]

Both routes measure: cup-lid interference, the cavity left by the closed mould against the cast part (the
part outside the cavity, the cavity outside the part), and the thinnest cup wall
round a cavity. OCCT measures the wall with BRepExtrema_DistShapeShape between the cup's hollow and the
outside. Nothing here asserts a time.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from magfab import derive, load_spec


def occt_route(design, solids):
    """The fit checks on the exact solids with OCCT booleans; same quantities as magfab.fit.MouldFit."""
    import cadquery as cq
    from OCP.BRepExtrema import BRepExtrema_DistShapeShape

    from magfab.fit import TOP_GAP_MM, lid_to_cast_pose, part_to_cavity

    def moved(wp, m):  # both poses are a half turn about x and a shift: m = [[1,0,0,dx],[0,-1,0,0],[0,0,-1,dz]]
        return wp.rotate((0, 0, 0), (1, 0, 0), 180).translate((float(m[0, 3]), 0.0, float(m[2, 3])))

    cup, lid = solids["mould_cup"], moved(solids["mould_lid"], lid_to_cast_pose(design))
    lx, ly, h = design.cup_size_mm
    R, wall = design.elastomer_radius_mm, design.wall_mm
    bottom = h - design.elastomer_height_mm - 0.5 * wall
    mould = cup.union(lid)
    out = {"cup_lid_interference_mm3": cup.intersect(lid).val().Volume() if cup.intersect(lid).vals() else 0.0}
    cav, part_out, cavity_out, walls = [], [], [], []
    for x in design.cavity_centres_x_mm:
        part = moved(solids["elastomer"], part_to_cavity(design, x))
        region = cq.Workplane("XY", origin=(x, 0, bottom)).circle(R + 0.5 * wall).extrude(h - bottom)
        cavity = region.cut(mould)
        cav.append(cavity.val().Volume())
        part_out.append(sum(v.Volume() for v in part.cut(cavity).vals()))
        cavity_out.append(sum(v.Volume() for v in cavity.cut(part).vals()))
        hollow = (cq.Workplane("XY", origin=(x, 0, TOP_GAP_MM)).circle(R + wall - TOP_GAP_MM)
                  .extrude(h - 2 * TOP_GAP_MM).cut(cup))
        big = cq.Workplane("XY", origin=(0, 0, -10)).box(lx + 20, ly + 20, h + 10, centered=(True, True, False))
        outside = big.cut(cq.Workplane("XY").box(lx, ly, h + 10, centered=(True, True, False)))
        dist = BRepExtrema_DistShapeShape(hollow.val().wrapped, outside.val().wrapped)
        walls.append(dist.Value())
    out.update(cavity_volume_mm3=tuple(cav), part_outside_mm3=tuple(part_out), cavity_outside_mm3=tuple(cavity_out),
               cup_wall_mm=min(walls))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("spec", nargs="?", type=Path)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    spec = load_spec(args.spec)
    design = derive(spec)

    from magfab.export.cad import tessellate
    from magfab.fit import mould_fit
    from magfab.pipeline import PARTS

    solids = {part.stem: part.make(design) for part in PARTS if part.stem != "pad"}
    tol, ang = spec.mould.tessellation_tolerance_mm, spec.mould.angular_tolerance_deg
    meshes = {stem: tessellate(s, tol, ang) for stem, s in solids.items()}

    def timed(fn):
        times, result = [], None
        for _ in range(args.repeat):
            t = time.perf_counter()
            result = fn()
            times.append(time.perf_counter() - t)
        return statistics.median(times), result

    t_occt, occt = timed(lambda: occt_route(design, solids))
    t_mf, mf = timed(lambda: mould_fit(design, meshes, tol))
    print(f"spec {spec.name}: {len(design.cavity_centres_x_mm)} cavities, tessellation tolerance {tol} mm")
    print(f"{'quantity':34s} {'OCCT (exact solids)':>22s} {'manifold3d (STL meshes)':>24s}")
    for key in ("cup_lid_interference_mm3", "cavity_volume_mm3", "part_outside_mm3", "cavity_outside_mm3",
                "cup_wall_mm"):
        print(f"{key:34s} {_r(occt[key])!s:>22s} {_r(getattr(mf, key))!s:>24s}")
    print(f"closed-form cast part volume {design.elastomer_volume_mm3:.3f} mm^3; mesh part {mf.part_volume_mm3:.3f}")
    print(f"time (median of {args.repeat}): OCCT 1.00, manifold3d {t_mf / t_occt:.3f} "
          f"({t_occt / t_mf:.1f}x faster)")


def _r(v):
    if isinstance(v, tuple):
        return tuple(round(x, 4) for x in v)
    return round(v, 4)


if __name__ == "__main__":
    main()
