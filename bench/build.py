"""Build-time benchmark for magfab, with an OpenSCAD baseline for the mould.

Run from anywhere::

    python bench/build.py [--repeat N] [--out DIR]

What it measures (all times are wall-clock seconds, from :func:`time.perf_counter`):

1. **Cold**: fresh interpreters (the OS file cache is warm after the first run): ``python -c pass``,
   ``python -c "import magfab"``, ``python -c "import cadquery"``, ``magfab --help`` and the default build
   ``python -m magfab.cli build --out <tmp>``, each N times; median and min.
2. **Warm**: in one process, after importing magfab and cadquery, ``plan()`` of ``magfab.pipeline`` N times;
   the median of every stage it reports in ``BuildResult.timings_s``.
3. **Mould only**: the mould cup and lid (``magfab.mould``), tessellated with ``magfab.export.cad`` at the
   spec's tolerances and turned into STL bytes, warm in-process and as a cold process. If ``openscad``
   is on the PATH, the same mould is written as OpenSCAD scripts from the same ``Design`` numbers,
   rendered with ``openscad -o <part>.stl <part>.scad`` (CGAL), checked against magfab's STLs (volume,
   bounding box, centroid), and the OpenSCAD time is compared with magfab's.
4. **Side by side**: the default build as a cold process against OpenSCAD rendering the same mould (cup + lid),
   interleaved run by run so that a shared machine's load falls on both alike, as the ratio OpenSCAD / build.
   ``--compare DIR`` (repeatable) adds the build of another checkout of magfab (``PYTHONPATH=DIR``, e.g. the
   commit before a change) to the same rounds, so before and after are read against the same baseline.
   ``--only side-by-side`` runs this section alone.
5. A table on stdout, ``<out>/build_bench.json`` and, if matplotlib is importable, ``<out>/build_bench.png``.

Nothing here asserts on a time: the figures are for reading, not for failing.
"""

from __future__ import annotations

import argparse
import io
import json
import math
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from magfab.design import Design

BENCH_DIR = Path(__file__).resolve().parent
DEFAULT_OUT = BENCH_DIR / "out"
JSON_NAME = "build_bench.json"
CHART_NAME = "build_bench.png"

#: A cold process that builds and writes the mould with exactly the code the warm path times: it loads
#: this file as a module and calls :func:`write_mould_stls`. argv: this file, the output directory.
COLD_MOULD_SCRIPT = (
    "import importlib.util as u, sys\n"
    "s = u.spec_from_file_location('magfab_build_bench', sys.argv[1])\n"
    "m = u.module_from_spec(s)\n"
    "s.loader.exec_module(m)\n"
    "m.write_mould_stls(sys.argv[2])\n"
)


# ---- timing helpers -------------------------------------------------------------------------------


def summarise(samples_s: Sequence[float]) -> dict[str, object]:
    """Median, min and every sample of a list of durations, all in seconds."""
    return {
        "median_s": statistics.median(samples_s),
        "min_s": min(samples_s),
        "samples_s": list(samples_s),
    }


def time_command(cmd: Sequence[str], cwd: Path) -> float:
    """Run ``cmd`` as a subprocess in ``cwd``; return its wall time in seconds, raise if it fails."""
    t = time.perf_counter()
    proc = subprocess.run(list(cmd), cwd=cwd, stdin=subprocess.DEVNULL, capture_output=True, text=True)
    elapsed = time.perf_counter() - t
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited with {proc.returncode}:\n{proc.stderr.strip()}")
    return elapsed


def time_repeated(make_cmd: Callable[[int], Sequence[str]], repeat: int, cwd: Path) -> dict[str, object]:
    """Time ``make_cmd(i)`` for i in 0..repeat-1 as fresh processes; the summary is in seconds."""
    return summarise([time_command(make_cmd(i), cwd) for i in range(repeat)])


def time_calls(func: Callable[[], object], repeat: int) -> list[float]:
    """Wall time in seconds of ``repeat`` in-process calls of ``func``."""
    samples = []
    for _ in range(repeat):
        t = time.perf_counter()
        func()
        samples.append(time.perf_counter() - t)
    return samples


# ---- 1. cold processes ----------------------------------------------------------------------------


def magfab_command() -> list[str]:
    """The ``magfab`` console script of this interpreter's environment, else ``python -m magfab.cli``."""
    beside = Path(sys.executable).with_name("magfab")
    if beside.exists():
        return [str(beside)]
    found = shutil.which("magfab")
    return [found] if found else [sys.executable, "-m", "magfab.cli"]


def cold_figures(repeat: int, work: Path) -> dict[str, dict[str, object]]:
    """Fresh-process wall times (s) of start-up, imports, ``magfab --help`` and the default build.

    ``import cadquery`` is timed on its own because magfab imports it lazily, on the first solid.
    """
    builds = work / "cold-builds"
    return {
        "python_startup": time_repeated(lambda i: [sys.executable, "-c", "pass"], repeat, work),
        "import_magfab": time_repeated(lambda i: [sys.executable, "-c", "import magfab"], repeat, work),
        "import_cadquery": time_repeated(lambda i: [sys.executable, "-c", "import cadquery"], repeat, work),
        "magfab_help": time_repeated(lambda i: [*magfab_command(), "--help"], repeat, work),
        "build": time_repeated(
            lambda i: [sys.executable, "-m", "magfab.cli", "build", "--out", str(builds / f"run{i}")], repeat, work
        ),
    }


# ---- 2. warm, in-process --------------------------------------------------------------------------


def warm_plan_figures(repeat: int) -> dict[str, object]:
    """Per-stage seconds of ``magfab.pipeline.plan`` on the default spec, N times in one warm process."""
    import cadquery  # noqa: F401 - imported first so that no stage pays for it

    import magfab
    from magfab.pipeline import plan

    spec = magfab.load_spec(None)
    runs = [plan(spec).timings_s for _ in range(repeat)]
    stages = list(runs[0])
    medians = {k: statistics.median(r[k] for r in runs) for k in stages}
    excess = {k: runs[0][k] - medians[k] for k in stages if k != "total"}
    return {
        "stages_median_s": medians,
        "stages_min_s": {k: min(r[k] for r in runs) for k in stages},
        "first_call_total_s": runs[0]["total"],
        "first_call_slowest_stage": max(excess, key=excess.get),  # where one-time lazy imports land
        "runs_s": runs,
    }


# ---- 3a. the mould with magfab --------------------------------------------------------------------


def mould_parts() -> list[tuple[str, Callable]]:
    """(file stem, builder) of the mould's parts, taken from ``magfab.pipeline.PARTS``."""
    from magfab.mould import cup_solid, lid_solid
    from magfab.pipeline import PARTS

    return [(part.stem, part.make) for part in PARTS if part.make in (cup_solid, lid_solid)]


def mould_stls(design: Design) -> dict[str, bytes]:
    """Build, tessellate (at the spec's tolerances) and encode the mould parts; STL bytes by file stem."""
    from magfab.export.cad import stl_bytes, tessellate

    spec = design.spec
    tol, ang = spec.mould.tessellation_tolerance_mm, spec.mould.angular_tolerance_deg
    return {stem: stl_bytes(tessellate(make(design), tol, ang), f"{spec.name} {stem}")
            for stem, make in mould_parts()}


def write_mould_stls(out_dir: str | Path) -> None:
    """What the cold mould process does: the default design's mould STLs into ``out_dir``."""
    import magfab

    for stem, data in mould_stls(magfab.derive(magfab.load_spec(None))).items():
        (Path(out_dir) / f"{stem}.stl").write_bytes(data)


def warm_mould_figures(repeat: int, design: Design) -> tuple[dict[str, object], dict[str, bytes]]:
    """Warm in-process wall times (s) of the mould's build + tessellation + STL encoding, and the STLs."""
    import cadquery  # noqa: F401

    stls: dict[str, bytes] = {}

    def once() -> None:
        stls.update(mould_stls(design))

    return summarise(time_calls(once, repeat)), stls


def cold_mould_figures(repeat: int, work: Path) -> dict[str, object]:
    """Wall times (s) of a fresh process that imports magfab, builds the mould and writes its STLs."""
    def cmd(i: int) -> list[str]:
        target = work / f"cold-mould-{i}"
        target.mkdir(parents=True, exist_ok=True)
        return [sys.executable, "-c", COLD_MOULD_SCRIPT, str(Path(__file__).resolve()), str(target)]

    return time_repeated(cmd, repeat, work)


def exact_volumes_mm3(design: Design) -> dict[str, float]:
    """Volume of each exact (B-rep) mould solid, mm^3, by file stem."""
    return {stem: make(design).val().Volume() for stem, make in mould_parts()}


# ---- 3b. the same mould as OpenSCAD ---------------------------------------------------------------


def segments_for(radius_mm: float, sweep_rad: float, tol_mm: float, ang_tol_deg: float) -> int:
    """Chords needed on an arc of ``radius_mm`` sweeping ``sweep_rad`` to honour both tolerances.

    A chord spanning angle a deviates from its arc by the sagitta r (1 - cos(a / 2)), so it stays within
    ``tol_mm`` if a <= 2 acos(1 - tol / r); the mesher's angular tolerance (degrees between neighbouring
    facet normals) also caps a at ``ang_tol_deg``. The tighter of the two decides.
    """
    step = math.radians(ang_tol_deg)
    if radius_mm > tol_mm:
        step = min(step, 2.0 * math.acos(1.0 - tol_mm / radius_mm))
    return max(1, math.ceil(abs(sweep_rad) / step - 1e-9))


def fn_for(radius_mm: float, tol_mm: float, ang_tol_deg: float) -> int:
    """OpenSCAD ``$fn`` for a full circle (or a revolve) of ``radius_mm``: see :func:`segments_for`."""
    return max(3, segments_for(radius_mm, 2.0 * math.pi, tol_mm, ang_tol_deg))


Point = tuple[float, float]


def circle_through(a: Point, b: Point, c: Point) -> tuple[Point, float]:
    """Centre and radius (mm) of the circle through three (r, z) points."""
    (ax, ay), (bx, by), (cx, cy) = a, b, c
    d = 2.0 * (ax * (by - cy) + bx * (cy - ay) + cx * (ay - by))
    ux = ((ax * ax + ay * ay) * (by - cy) + (bx * bx + by * by) * (cy - ay) + (cx * cx + cy * cy) * (ay - by)) / d
    uy = ((ax * ax + ay * ay) * (cx - bx) + (bx * bx + by * by) * (ax - cx) + (cx * cx + cy * cy) * (bx - ax)) / d
    return (ux, uy), math.hypot(ax - ux, ay - uy)


def arc_points(start: Point, through: Point, end: Point, tol_mm: float, ang_tol_deg: float) -> list[Point]:
    """The three-point arc start -> through -> end as chords within the tolerances; excludes ``start``.

    The last point is ``end`` exactly, so a profile that returns to the axis stays at r = 0.
    """
    (cx, cz), r = circle_through(start, through, end)
    a0, am, a1 = (math.atan2(p[1] - cz, p[0] - cx) for p in (start, through, end))
    sweep = (a1 - a0) % (2.0 * math.pi)
    if (am - a0) % (2.0 * math.pi) > sweep:  # the arc runs clockwise
        sweep -= 2.0 * math.pi
    n = segments_for(r, sweep, tol_mm, ang_tol_deg)
    angles = (a0 + sweep * k / n for k in range(1, n))
    return [(max(0.0, cx + r * math.cos(a)), cz + r * math.sin(a)) for a in angles] + [tuple(end)]


def cavity_profile(design: Design, tol_mm: float, ang_tol_deg: float) -> list[Point]:
    """(r, z) outline of a cavity tool, mm: the envelope with its base pushed below z = 0, as mould.py cuts it.

    For a hemisphere tip, ``design.envelope_profile`` gives the arc by three points (indices 2, 3, 4);
    it is sampled here with :func:`arc_points`.
    """
    from magfab.mould import OVERLAP_MM  # how far mould.py's tools reach past the faces they open

    prof = [(r, -OVERLAP_MM if i < 2 else z) for i, (r, z) in enumerate(design.envelope_profile)]
    if len(prof) == 5:
        prof = prof[:3] + arc_points(prof[2], prof[3], prof[4], tol_mm, ang_tol_deg)
    return prof


def core_profile(design: Design) -> list[Point]:
    """(r, z) outline of a lid core, mm: ``design.core_profile`` extended into the lid plate (as mould.py)."""
    below = design.core_root_mm
    prof = design.core_profile
    return [(0.0, -below), (prof[1][0], -below), *prof[1:]]


def _num(x: float) -> str:
    """A float as OpenSCAD text: 12 significant digits, no negative zero."""
    return f"{x + 0.0:.12g}"


def _vec(values: Iterable[float]) -> str:
    """An OpenSCAD vector of numbers (mm or degrees)."""
    return "[" + ", ".join(_num(v) for v in values) + "]"


def _polygon(profile: list[Point]) -> str:
    """An OpenSCAD polygon() of (r, z) points in mm."""
    return "polygon(points=[" + ", ".join(_vec(p) for p in profile) + "])"


def _radius_max(profile: list[Point]) -> float:
    """The largest radius (mm) of an (r, z) profile: where a revolve's chords deviate most."""
    return max(r for r, _z in profile)


def scad_cup(design: Design, tol_mm: float, ang_tol_deg: float) -> str:
    """OpenSCAD source of the mould cup (print pose, mm): box minus the inverted cavities, plus the pins."""
    from magfab.mould import OVERLAP_MM

    lx, ly, h = design.cup_size_mm
    cavity = cavity_profile(design, tol_mm, ang_tol_deg)
    pin_r = design.pin_diameter_mm / 2.0
    pin_h = design.pin_height_mm
    lines = [
        "// magfab mould cup, generated by bench/build.py from magfab.derive(load_spec(None)); mm",
        f"// $fn: chords within {_num(tol_mm)} mm and {_num(ang_tol_deg)} deg of each circle (bench/build.py fn_for)",
        "union() {",
        "  difference() {",
        f"    translate({_vec((-lx / 2, -ly / 2, 0))}) cube({_vec((lx, ly, h))});",
    ]
    fn = fn_for(_radius_max(cavity), tol_mm, ang_tol_deg)
    for x in design.cavity_centres_x_mm:
        lines.append(f"    translate({_vec((x, 0, h))}) rotate([180, 0, 0]) "
                     f"rotate_extrude($fn={fn}) {_polygon(cavity)};")
    lines.append("  }")
    for x in design.pin_positions_x_mm:
        lines.append(f"  translate({_vec((x, 0, h - OVERLAP_MM))}) cylinder(h={_num(pin_h + OVERLAP_MM)}, "
                     f"r={_num(pin_r)}, $fn={fn_for(pin_r, tol_mm, ang_tol_deg)});")
    lines.append("}")
    return "\n".join(lines) + "\n"


def scad_lid(design: Design, tol_mm: float, ang_tol_deg: float) -> str:
    """OpenSCAD source of the mould lid (print pose, mm): plate plus cores, minus holes and sprue countersinks."""
    from magfab.mould import COUNTERSINK_MM, OVERLAP_MM

    h, t = design.cup_size_mm[2], design.lid_thickness_mm
    lx, ly, _ = design.lid_size_mm
    core = core_profile(design)
    fn_core = fn_for(_radius_max(core), tol_mm, ang_tol_deg)
    lines = [
        "// magfab mould lid, generated by bench/build.py from magfab.derive(load_spec(None)); mm",
        f"// $fn: chords within {_num(tol_mm)} mm and {_num(ang_tol_deg)} deg of each circle (bench/build.py fn_for)",
        f"translate({_vec((0, 0, h + t))}) rotate([180, 0, 0]) difference() {{",
        "  union() {",
        f"    translate({_vec((-lx / 2, -ly / 2, h))}) cube({_vec((lx, ly, t))});",
    ]
    for x in design.cavity_centres_x_mm:
        lines.append(f"    translate({_vec((x, 0, h))}) rotate([180, 0, 0]) "
                     f"rotate_extrude($fn={fn_core}) {_polygon(core)};")
    lines.append("  }")
    for x, y, d in design.lid_holes:
        lines.append(f"  translate({_vec((x, y, h - OVERLAP_MM))}) cylinder(h={_num(t + 2 * OVERLAP_MM)}, "
                     f"r={_num(d / 2)}, $fn={fn_for(d / 2, tol_mm, ang_tol_deg)});")
    r = design.sprue_diameter_mm / 2.0
    r_top = r + COUNTERSINK_MM + OVERLAP_MM  # 45-degree countersink, reaching past the top face
    for x in design.cavity_centres_x_mm:
        lines.append(f"  translate({_vec((x, design.sprue_offset_mm, h + t - COUNTERSINK_MM))}) "
                     f"cylinder(h={_num(COUNTERSINK_MM + OVERLAP_MM)}, r1={_num(r)}, r2={_num(r_top)}, "
                     f"$fn={fn_for(r_top, tol_mm, ang_tol_deg)});")
    lines.append("}")
    return "\n".join(lines) + "\n"


def openscad_version(exe: str) -> str:
    """``openscad --version`` (it prints on stderr), e.g. 'OpenSCAD version 2021.01'."""
    proc = subprocess.run([exe, "--version"], capture_output=True, text=True)
    return (proc.stderr or proc.stdout).strip() or "OpenSCAD (unknown version)"


def render_openscad(exe: str, scad: Path, stl: Path, repeat: int) -> dict[str, object]:
    """Render ``scad`` to ``stl`` with ``openscad -o`` ``repeat`` times; wall seconds per fresh process."""
    return time_repeated(lambda i: [exe, "-o", str(stl), str(scad)], repeat, scad.parent)


def load_stl(data: bytes):
    """A trimesh mesh from STL bytes (binary or ASCII)."""
    import trimesh

    return trimesh.load(io.BytesIO(data), file_type="stl", force="mesh")


def mesh_agreement(ours: bytes, theirs: bytes, exact_mm3: float) -> dict[str, object]:
    """How closely two STLs of one part agree: volumes (mm^3), relative difference, bbox and centroid (mm)."""
    a, b = load_stl(ours), load_stl(theirs)
    return {
        "exact_volume_mm3": exact_mm3,
        "magfab_volume_mm3": float(a.volume),
        "openscad_volume_mm3": float(b.volume),
        "rel_diff_openscad_vs_magfab": float(b.volume / a.volume - 1.0),
        "rel_diff_magfab_vs_exact": float(a.volume / exact_mm3 - 1.0),
        "rel_diff_openscad_vs_exact": float(b.volume / exact_mm3 - 1.0),
        "bbox_max_diff_mm": float(abs(a.bounds - b.bounds).max()),
        "centroid_distance_mm": float(math.dist(a.center_mass, b.center_mass)),
        "magfab_triangles": len(a.faces),
        "openscad_triangles": len(b.faces),
        "openscad_watertight": bool(b.is_watertight),
    }


def openscad_figures(exe: str, design: Design, repeat: int, out: Path, ours: dict[str, bytes],
                     exact: dict[str, float]) -> dict[str, object]:
    """Write, render and check the OpenSCAD mould; times in seconds, files in ``out/openscad``."""
    spec = design.spec
    tol, ang = spec.mould.tessellation_tolerance_mm, spec.mould.angular_tolerance_deg
    folder = out / "openscad"
    folder.mkdir(parents=True, exist_ok=True)
    sources = {"mould_cup": scad_cup(design, tol, ang), "mould_lid": scad_lid(design, tol, ang)}
    renders, agreement = {}, {}
    for stem, source in sources.items():
        scad, stl = folder / f"{stem}.scad", folder / f"{stem}.stl"
        scad.write_text(source, encoding="utf-8")
        renders[stem] = render_openscad(exe, scad, stl, repeat)
        agreement[stem] = mesh_agreement(ours[stem], stl.read_bytes(), exact[stem])
    cavity = cavity_profile(design, tol, ang)
    return {
        "version": openscad_version(exe),
        "render": renders,
        "total_median_s": sum(r["median_s"] for r in renders.values()),
        "agreement": agreement,
        "sampling": {
            "rule": "chord angle a <= min(2*acos(1 - tol/r), angular tolerance): sagitta r*(1 - cos(a/2)) <= tol",
            "tolerance_mm": tol,
            "angular_tolerance_deg": ang,
            "cavity_fn": fn_for(_radius_max(cavity), tol, ang),
            "cavity_radius_mm": _radius_max(cavity),
            "tip_arc_points": max(0, len(cavity) - 3),
            "core_fn": fn_for(_radius_max(core_profile(design)), tol, ang),
            "pin_fn": fn_for(design.pin_diameter_mm / 2.0, tol, ang),
        },
    }


def mould_figures(repeat: int, work: Path, out: Path) -> dict[str, object]:
    """Mould-only comparison: magfab warm and cold, and OpenSCAD if available; seconds and mm^3."""
    import magfab

    design = magfab.derive(magfab.load_spec(None))
    warm, ours = warm_mould_figures(repeat, design)
    folder = out / "magfab"
    folder.mkdir(parents=True, exist_ok=True)
    for stem, data in ours.items():
        (folder / f"{stem}.stl").write_bytes(data)
    result: dict[str, object] = {"magfab_warm": warm, "magfab_cold": cold_mould_figures(repeat, work), "openscad": None}
    exe = shutil.which("openscad")
    if exe is None:
        result["openscad_note"] = "openscad not on PATH: no baseline"
        return result
    try:
        scad = openscad_figures(exe, design, repeat, out, ours, exact_volumes_mm3(design))
    except RuntimeError as exc:  # a failed render: keep magfab's figures, say why there is no baseline
        result["openscad_note"] = f"OpenSCAD failed, no baseline: {exc}"
        return result
    result["openscad"] = scad
    total = scad["total_median_s"]
    result["speedup_openscad_over_magfab"] = {
        "cold_process": total / result["magfab_cold"]["median_s"],
        "warm": total / warm["median_s"],
    }
    return result


# ---- 4. side by side: the build against OpenSCAD, in the same rounds ---------------------------------


def time_build(tree: Path | None, out: Path, work: Path) -> tuple[float, dict[str, float]]:
    """Wall seconds of a cold ``magfab build --json`` of the default spec with magfab from ``tree`` (None: this
    interpreter's own), and the stage timings the build reports (``timings_s``, seconds)."""
    env = dict(os.environ)
    if tree is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(tree)] + [p for p in [env.get("PYTHONPATH")] if p])
    cmd = [sys.executable, "-m", "magfab.cli", "build", "--json", "--out", str(out)]
    t = time.perf_counter()
    proc = subprocess.run(cmd, cwd=work, env=env, stdin=subprocess.DEVNULL, capture_output=True, text=True)
    elapsed = time.perf_counter() - t
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)} exited with {proc.returncode}:\n{proc.stderr.strip()}")
    return elapsed, json.loads(proc.stdout).get("timings_s", {})


def side_by_side(repeat: int, work: Path, out: Path, trees: Sequence[Path]) -> dict[str, object]:
    """Rounds of: the default build (this magfab, then each of ``trees``), OpenSCAD's cup, OpenSCAD's lid; seconds.

    The ratio of each build is OpenSCAD's cup + lid (sum of medians) over the build's median: above 1, the whole
    build is faster than OpenSCAD rendering the mould alone.
    """
    import magfab

    builds: dict[str, list[float]] = {"this": []} | {str(t): [] for t in trees}
    stages: dict[str, list[dict[str, float]]] = {k: [] for k in builds}
    exe = shutil.which("openscad")
    scad: dict[str, Path] = {}
    if exe is not None:
        design = magfab.derive(magfab.load_spec(None))
        tol, ang = design.spec.mould.tessellation_tolerance_mm, design.spec.mould.angular_tolerance_deg
        folder = out / "openscad"
        folder.mkdir(parents=True, exist_ok=True)
        for stem, source in (("mould_cup", scad_cup(design, tol, ang)), ("mould_lid", scad_lid(design, tol, ang))):
            scad[stem] = folder / f"{stem}.scad"
            scad[stem].write_text(source, encoding="utf-8")
    renders: dict[str, list[float]] = {stem: [] for stem in scad}
    for i in range(repeat):
        for k, name in enumerate(builds):
            elapsed, timings = time_build(None if name == "this" else Path(name), work / f"side-{i}-{k}", work)
            builds[name].append(elapsed)
            stages[name].append(timings)
        for stem, path in scad.items():
            renders[stem].append(time_command([exe, "-o", str(path.with_suffix(".stl")), str(path)], path.parent))
    result: dict[str, object] = {"builds": {k: summarise(v) | {"stages_s": stages[k]} for k, v in builds.items()}}
    if scad:
        total = sum(statistics.median(v) for v in renders.values())
        result["openscad"] = {"version": openscad_version(exe), "render": {k: summarise(v) for k, v in renders.items()},
                              "total_median_s": total}
        result["ratio_openscad_over_build"] = {k: total / statistics.median(v) for k, v in builds.items()}
    else:
        result["openscad_note"] = "openscad not on PATH: no baseline"
    return result


def format_side_by_side(sbs: dict[str, object]) -> list[str]:
    """The side-by-side section of the table."""
    out = ["", "side by side (cold processes, interleaved round by round)"]
    for name, fig in sbs["builds"].items():
        out.append(_cold_line(f"magfab build, {'this checkout' if name == 'this' else name}", fig))
    scad = sbs.get("openscad")
    if scad is None:
        return [*out, "  " + sbs.get("openscad_note", "no OpenSCAD baseline")]
    out += [_cold_line(f"OpenSCAD render {part} (cold process)", r) for part, r in scad["render"].items()]
    out.append(_line("OpenSCAD cup + lid (sum of medians)", _ms(scad["total_median_s"])))
    for name, ratio in sbs["ratio_openscad_over_build"].items():
        out.append(_line(f"OpenSCAD / build, {'this checkout' if name == 'this' else name}", f"{ratio:8.3g} x"))
    return out


# ---- 5. report ------------------------------------------------------------------------------------


def environment() -> dict[str, object]:
    """Versions and machine, for reading the figures later."""
    import cadquery
    import trimesh

    import magfab

    return {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "cpu_count": os.cpu_count(),
        "magfab": magfab.__version__,
        "cadquery": cadquery.__version__,
        "trimesh": trimesh.__version__,
    }


def _ms(seconds: float) -> str:
    """Seconds as right-aligned milliseconds."""
    return f"{seconds * 1000:9.1f} ms"


def _line(label: str, text: str) -> str:
    return f"  {label:<50} {text}"


def _cold_line(label: str, fig: dict[str, object]) -> str:
    return _line(label, f"median {_ms(fig['median_s'])}   min {_ms(fig['min_s'])}")


def format_report(res: dict[str, object]) -> str:
    """The human-readable table of every figure."""
    n = res["repeat"]
    env = res["environment"]
    out = [f"magfab {env['magfab']} build benchmark: {n} repeats, median (min); cadquery {env['cadquery']}, "
           f"Python {env['python']}, {env['cpu_count']} CPUs"]
    if "side_by_side" in res:
        out += format_side_by_side(res["side_by_side"])
    if "cold" not in res:
        return "\n".join(out)
    out += ["", "cold (fresh process each time; OS file cache warm)"]
    cold = res["cold"]
    out += [_cold_line("python -c pass", cold["python_startup"]),
            _cold_line('python -c "import magfab"', cold["import_magfab"]),
            _cold_line('python -c "import cadquery"', cold["import_cadquery"]),
            _cold_line("magfab --help", cold["magfab_help"]),
            _cold_line("magfab build (default spec, STL + STEP)", cold["build"])]
    out += ["", "warm (in-process plan(), magfab and cadquery already imported): median per stage"]
    warm = res["warm_plan"]
    for stage, s in warm["stages_median_s"].items():
        out.append(_line(stage, _ms(s)))
    slow = warm["first_call_slowest_stage"]
    out.append(_line("total, first call only", f"{_ms(warm['first_call_total_s'])}   (its {slow} took "
                     f"{_ms(warm['runs_s'][0][slow]).strip()}: lazy imports on first use)"))
    m = res["mould"]
    out += ["", "mould only (cup + lid: model, tessellate, STL bytes)",
            _cold_line("magfab warm, in-process", m["magfab_warm"]),
            _cold_line("magfab cold process (incl. imports, writes STLs)", m["magfab_cold"])]
    scad = m["openscad"]
    if scad is None:
        out.append("  " + m.get("openscad_note", "no OpenSCAD baseline"))
        return "\n".join(out)
    s = scad["sampling"]
    out += [_cold_line(f"OpenSCAD render {part} (cold process)", r) for part, r in scad["render"].items()]
    out += [_line("OpenSCAD cup + lid (sum of medians)", _ms(scad["total_median_s"])),
            "", f"  sampling: $fn from chord sagitta <= {s['tolerance_mm']} mm and <= {s['angular_tolerance_deg']} deg "
            f"per chord: cavity r={s['cavity_radius_mm']:.3g} mm $fn={s['cavity_fn']} ({s['tip_arc_points']} tip-arc "
            f"chords), core $fn={s['core_fn']}, pins $fn={s['pin_fn']}",
            "  same part? (OpenSCAD STL vs magfab STL)"]
    for part, a in scad["agreement"].items():
        out.append(_line(part, f"volume OpenSCAD {a['openscad_volume_mm3']:.2f} vs magfab "
                               f"{a['magfab_volume_mm3']:.2f} mm^3: {a['rel_diff_openscad_vs_magfab']:+.4%} "
                               f"(exact solid {a['exact_volume_mm3']:.2f})"))
        out.append(_line("", f"bbox within {a['bbox_max_diff_mm']:.4f} mm, centroids "
                             f"{a['centroid_distance_mm']:.4f} mm apart, "
                             f"{a['openscad_triangles']} vs {a['magfab_triangles']} triangles"))
    sp = m["speedup_openscad_over_magfab"]
    out += ["", f"  baseline: {scad['version']} CGAL render of the same mould (cup + lid) = 1.00",
            _line("(a) magfab cold process: OpenSCAD / magfab", f"{sp['cold_process']:8.3g} x  "
                  f"(magfab takes {1 / sp['cold_process']:.3f} of the baseline's time)"),
            _line("(b) magfab warm:         OpenSCAD / magfab", f"{sp['warm']:8.3g} x  "
                  f"(magfab takes {1 / sp['warm']:.4f} of the baseline's time)")]
    return "\n".join(out)


def _rounded(obj: object) -> object:
    """Floats to 6 decimals (microseconds, 1e-6 mm^3) so the JSON reads easily."""
    if isinstance(obj, float):
        return round(obj, 6)
    if isinstance(obj, dict):
        return {k: _rounded(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_rounded(v) for v in obj]
    return obj


def write_json(res: dict[str, object], path: Path) -> None:
    """All figures as JSON (seconds, mm, mm^3)."""
    path.write_text(json.dumps(_rounded(res), indent=2) + "\n", encoding="utf-8")


def write_chart(res: dict[str, object], path: Path) -> bool:
    """Bar chart of the warm stages and the mould comparison (seconds); False if matplotlib is missing."""
    try:
        import matplotlib
    except ImportError:
        return False
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    stages = res["warm_plan"]["stages_median_s"]
    m = res["mould"]
    bars = {"magfab warm": m["magfab_warm"]["median_s"], "magfab cold process": m["magfab_cold"]["median_s"]}
    if m["openscad"] is not None:
        for part, r in m["openscad"]["render"].items():
            bars[f"OpenSCAD {part}"] = r["median_s"]
        bars["OpenSCAD cup + lid"] = m["openscad"]["total_median_s"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(12, 4.8))
    _barh(left, stages, "warm plan(): median per stage", ["#4c72b0"] * len(stages))
    colours = ["#dd8452" if k.startswith("OpenSCAD") else "#4c72b0" for k in bars]
    _barh(right, bars, "mould cup + lid: magfab vs OpenSCAD CGAL (median)", colours)
    fig.tight_layout()
    fig.savefig(path, dpi=110, metadata={"Software": None})
    plt.close(fig)
    return True


def _barh(ax, values: dict[str, float], title: str, colours: list[str]) -> None:
    """Horizontal bars of durations in seconds, each labelled with its value."""
    labels = list(values)
    ax.barh(labels, [values[k] for k in labels], color=colours)
    ax.set_xlim(0, 1.2 * max(values.values()))
    ax.invert_yaxis()
    ax.set_title(title)
    ax.set_xlabel("wall time, s")
    for i, k in enumerate(labels):
        ax.annotate(f" {values[k]:.3g} s", (values[k], i), va="center", fontsize=8)


# ---- main -----------------------------------------------------------------------------------------


def run(repeat: int, out: Path, trees: Sequence[Path] = (), only: str | None = None) -> dict[str, object]:
    """Every figure of the benchmark (``only="side-by-side"``: that section alone), as a JSON-ready dict (seconds,
    mm, mm^3); ``trees`` are other checkouts whose build joins the side-by-side rounds."""
    res: dict[str, object] = {"repeat": repeat, "environment": environment()}
    with tempfile.TemporaryDirectory(prefix="magfab-bench-") as tmp:
        work = Path(tmp)
        res["side_by_side"] = side_by_side(repeat, work, out, trees)
        if only is None:
            res["cold"] = cold_figures(repeat, work)
            res["warm_plan"] = warm_plan_figures(repeat)
            res["mould"] = mould_figures(repeat, work, out)
    return res


def main(argv: Sequence[str] | None = None) -> int:
    """Command line: run the benchmark, print the table, write the JSON and the chart; exit status."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="runs per figure (default 3)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="output folder (default bench/out)")
    parser.add_argument("--compare", type=Path, action="append", default=[], metavar="DIR",
                        help="another checkout of magfab whose build joins the side-by-side rounds (repeatable)")
    parser.add_argument("--only", choices=["side-by-side"], help="run that section alone")
    args = parser.parse_args(argv)
    if args.repeat < 1:
        parser.error("--repeat must be at least 1")
    out = args.out.resolve()
    out.mkdir(parents=True, exist_ok=True)
    res = run(args.repeat, out, [t.resolve() for t in args.compare], args.only)
    print(format_report(res))
    write_json(res, out / JSON_NAME)
    print(f"\nwrote {out / JSON_NAME}")
    if "warm_plan" not in res:
        pass  # the chart draws the warm stages and the mould section: not run
    elif write_chart(res, out / CHART_NAME):
        print(f"wrote {out / CHART_NAME}")
    else:
        print("matplotlib is not importable: no chart (nothing was installed)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
