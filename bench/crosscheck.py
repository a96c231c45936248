"""magfab's indentation FE against an independent one (FElupe), side by side: forces, differences and times.

Run from anywhere (FElupe is in the ``test`` extra)::

    python bench/crosscheck.py

For MagOne and the three bench designs (``bench/designs``): the indenter force at 0.5, 1, 2, 2.5 and 3 mm of
indentation (up to the design's scan depth, ``calibration.scan_z_mm``) for the three materials of its band (soft,
nominal, stiff shear modulus). The material is neo-Hookean, so force is linear in mu at a given indentation and
magnet travel does not depend on it: each code solves once at mu = 1 and the forces are scaled by each mu.

magfab's FE (:func:`magfab.models.mechanics.fe`) runs on each mesh the automatic choice may pick (1.0 and 0.75 mm),
FElupe (``FElupeIndentation`` of ``tests/models/test_mechanics_crosscheck.py``: FElupe's quadratic triangles and
mixed (u, p, J) axisymmetric solid on the same vertices, its own contact loop) on the same two meshes. Each cell
gives magfab's force / FElupe's force in N and their difference in % (FElupe against magfab). Times are cold (the
meshes and operators rebuilt) and given as ratios to magfab's 1.0 mm solve of the same design in the same run. Where
a code stops before the scan depth, the table says where and why. Prints Markdown tables; writes nothing.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

BENCH_DIR = Path(__file__).resolve().parent
sys.path.insert(0, str(BENCH_DIR.parent))
sys.path.insert(0, str(BENCH_DIR.parent / "tests" / "models"))  # the FElupe model lives with its test

from test_mechanics_crosscheck import FElupeIndentation  # noqa: E402 - imported after sys.path points at its test folder

from magfab import load_spec  # noqa: E402 - imported after sys.path points at the repository
from magfab.design import derive  # noqa: E402 - imported after sys.path points at the repository
from magfab.models import mechanics as mech  # noqa: E402 - imported after sys.path points at the repository
from magfab.models.mechanics.schedule import FE_MESHES_MM  # noqa: E402 - imported after sys.path points at the repository
from magfab.models.predict import _band  # noqa: E402 - imported after sys.path points at the repository

DESIGNS = (("MagOne", None), ("small_magnet", BENCH_DIR / "designs" / "small_magnet.toml"),
           ("stiff_material", BENCH_DIR / "designs" / "stiff_material.toml"),
           ("flat_tip", BENCH_DIR / "designs" / "flat_tip.toml"))
DEPTHS_MM = (0.5, 1.0, 2.0, 2.5, 3.0)
MESHES_MM = FE_MESHES_MM[:2]  # the meshes auto may pick on these designs


def _ours(body: mech.Body, depths: np.ndarray, mesh_mm: float) -> tuple[np.ndarray, float, str]:
    """magfab's force (mu mm^2, NaN past a failure) at ``depths``, the cold time (s), and what stopped it ('')."""
    mech.clear_caches()
    t0 = time.perf_counter()
    curve = mech.fe(body, 1.0, np.concatenate([[0.0], depths]), mesh_mm=mesh_mm, on_failure="truncate")
    seconds = time.perf_counter() - t0
    force = np.full(depths.size, np.nan)
    n = min(curve.force_N.size - 1, depths.size)
    force[:n] = curve.force_N[1:n + 1] * 1e3  # mu = 1 kPa: 1 kPa mm^2 = 1e-3 N
    return force, seconds, str(curve.info.get("failure", "")) if n < depths.size else ""


def _theirs(body: mech.Body, depths: np.ndarray, mesh_mm: float) -> tuple[np.ndarray, float, str]:
    """FElupe's force (mu mm^2, NaN past a failure), the cold time (s, mesh included), and what stopped it ('')."""
    mech.clear_caches()
    t0 = time.perf_counter()
    force, why = np.full(depths.size, np.nan), ""
    for k in range(depths.size, 0, -1):  # a failure: keep the depths before it
        try:
            force[:k] = FElupeIndentation(body, mesh_mm).run(depths[:k])[:, 0]
            break
        except RuntimeError as exc:
            why = why or str(exc)
    return force, time.perf_counter() - t0, why


def _design(name: str, path: Path | None) -> tuple[list[str], list[str], list[str]]:
    """Rows of the force table, the time table and the notes for one design."""
    spec = load_spec(path)
    design = derive(spec)
    body = mech.Body.from_design(design)
    mus = _band(design)
    depth = float(spec.calibration.scan_z_mm)
    depths = np.array([d for d in DEPTHS_MM if d <= depth + 1e-9])
    rows, notes, runs = [], [], {}
    for mesh in MESHES_MM:
        runs[("magfab", mesh)] = _ours(body, depths, mesh)
        runs[("FElupe", mesh)] = _theirs(body, depths, mesh)
    for (code, mesh), (_, _, why) in runs.items():
        if why:
            notes.append(f"- {name}, {code} on the {mesh:g} mm mesh stopped: {why}")
    if depth < max(DEPTHS_MM):
        notes.append(f"- {name}: the scan depth is {depth:g} mm; deeper columns are left empty")
    for material, mu in mus.items():
        for mesh in MESHES_MM:
            ours, theirs = runs[("magfab", mesh)][0], runs[("FElupe", mesh)][0]
            cells = [f"{a * mu * 1e-3:.4f} / {b * mu * 1e-3:.4f} ({100.0 * (b / a - 1.0):+.2f} %)"
                     if np.isfinite(a) and np.isfinite(b) else "-" for a, b in zip(ours, theirs)]
            cells += [""] * (len(DEPTHS_MM) - len(cells))
            rows.append(f"| {name} | {material} ({mu:g} kPa) | {mesh:g} | " + " | ".join(cells) + " |")
    base = runs[("magfab", 1.0)][1]
    times = [f"| {name} | " + " | ".join(f"{runs[(code, mesh)][1] / base:.2f}" for code in ("magfab", "FElupe")
                                          for mesh in MESHES_MM) + " |"]
    return rows, times, notes


def main() -> None:
    force_rows, time_rows, notes = [], [], []
    for name, path in DESIGNS:
        rows, times, why = _design(name, path)
        force_rows += rows
        time_rows += times
        notes += why
    print("Indenter force, magfab / FElupe in N (FElupe's difference from magfab), at indentation; neo-Hookean "
          "force is linear in mu, so each code solved once at mu = 1 and is scaled by each material's mu:\n")
    print("| design | material | mesh (mm) | " + " | ".join(f"{d:g} mm" for d in DEPTHS_MM) + " |")
    print("|---|---|---|" + "---|" * len(DEPTHS_MM))
    print("\n".join(force_rows))
    print("\nCold solve time (all depths, one mu) as a ratio to magfab's 1.0 mm solve of the same design:\n")
    print("| design | " + " | ".join(f"{code} {mesh:g} mm" for code in ("magfab", "FElupe") for mesh in MESHES_MM)
          + " |")
    print("|---|" + "---|" * (2 * len(MESHES_MM)))
    print("\n".join(time_rows))
    if notes:
        print("\n" + "\n".join(notes))


if __name__ == "__main__":
    main()
