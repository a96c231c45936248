"""The search's coordinates: every point of the unit cube is a geometry the build accepts, the mapping round-trips,
and (slow) the study's front against a ten times larger sweep on each bench target set."""

from __future__ import annotations

import sys
from importlib import resources
from pathlib import Path

import pytest

from magfab.check import preflight
from magfab.design import derive
from magfab.errors import InputError
from magfab.inverse.space import Space, base_point, candidate_spec, latin_hypercube
from magfab.inverse.targets import parse_targets
from magfab.spec import load_spec

BASE = load_spec(None)
BENCH = Path(__file__).resolve().parents[2] / "bench"


def _refused(point, targets) -> bool:
    try:
        preflight(derive(candidate_spec(point, BASE, targets, "probe")))
    except InputError:
        return True
    return False


def test_every_point_of_the_search_is_buildable():
    """On the example targets a Latin hypercube of the raw mm ranges is mostly impossible; of the search's
    coordinates, none is."""
    targets = parse_targets(resources.files("magfab.examples").joinpath("targets.toml").read_text(encoding="utf-8"))
    space = Space(targets, BASE)
    raw = sum(_refused(p, targets) for p in latin_hypercube(targets.variables, 60, 2))
    ours = [space.point(p) for p in space.latin_hypercube(60, 2)]
    assert raw > 20  # what the search sampled before
    assert sum(_refused(p, targets) for p in ours) == 0
    assert {(p["material"], p["tip"]) for p in ours} == {(m, "hemisphere") for m in targets.variables.material_keys()}
    for p in ours:  # the mm point and its fractions round-trip
        assert _close(space.point(space.params(p)), p)


@pytest.mark.parametrize("name", ["fingertip", "taxel", "stiff_pad"])
def test_no_point_of_the_search_saturates_the_chip_and_the_floor_is_tight(name):
    """Every point of the search on each bench set builds (the build's preflight), and d_min starts where the
    grade's strongest magnet saturates the chip: magpylib's cylinder (not the models' field) puts Bz at each point's
    d_min within the chip's full scale, and 0.05 mm nearer than the floor above it."""
    import magpylib

    from magfab.inverse.evaluate import bench_point
    from magfab.inverse.targets import load_targets
    from magfab.models.chip import chip_setting
    from magfab.models.field import Magnet

    targets, base = load_targets(BENCH / "targets" / f"{name}.toml")
    space = Space(targets, base)

    def bz_G(m: Magnet, d_mm: float) -> float:  # below the lower face on the axis; lengths in mm, B in T
        cyl = magpylib.magnet.Cylinder(polarization=(0, 0, m.remanence_T), dimension=(2 * m.radius_mm, m.height_mm))
        return 1e4 * float(cyl.getB((0.0, 0.0, -m.height_mm / 2.0 - d_mm))[2])

    at_floor = 0
    for p in (space.point(q) for q in space.latin_hypercube(120, 4)):
        design = derive(candidate_spec(p, base, targets, "probe"))
        preflight(design)  # every point builds: the build's own refusals
        strongest, full = Magnet.from_design(design, "high"), chip_setting(design).full_scale_z_G
        d_min, floor = float(p["d_min_mm"]), space.saturation_floor(f"{p['magnet']}:{p['grade']}")
        assert bz_G(strongest, d_min) <= full * (1 + 1e-6), p
        bench = bench_point(p, base, targets)  # on the printer's step, as verified and written: builds, reads
        preflight(derive(candidate_spec(bench, base, targets, "bench")))
        assert bz_G(strongest, float(bench["d_min_mm"])) <= full * (1 + 1e-6), (p, bench)
        if floor > space.stack:  # the floor is the chip's, not the stack's
            assert bz_G(strongest, floor - 0.05) > full, p
            at_floor += d_min < floor + 0.1
    assert at_floor > 0  # the sampler reaches the closest, best-resolving distances


@pytest.mark.parametrize("name", ["fingertip", "taxel", "stiff_pad"])
def test_the_edges_of_the_search_evaluate(name):
    """Points on the search cube's edges, where the geometry's bounds are met exactly: every fraction at 0 or 1 (a
    corner), and d_max at its lowest under the largest d_min (the thinnest travel). Each builds and the cheap chain
    gives it figures, the FE where the surrogate cannot (a hemisphere's height once fell a rounding short of its
    radius there, and the surrogate's log-log curves, negative at the first indentations, extrapolated to 1e58 mm)."""
    from magfab.inverse.evaluate import evaluate
    from magfab.inverse.space import FRACTIONS, MAGNET_FRACTION
    from magfab.inverse.targets import load_targets

    targets, base = load_targets(BENCH / "targets" / f"{name}.toml")
    space = Space(targets, base)
    args = (base.model_dump_json(), targets.model_dump_json())
    edges = [{**q, **{k: float(round(q[k])) for k in (*FRACTIONS, MAGNET_FRACTION)}}
             for q in space.latin_hypercube(24, 21)]
    edges += [{**q, "f_d_max": 0.0, "f_d_min": 1.0} for q in space.latin_hypercube(24, 8)]
    for q in edges:
        result = evaluate(space.point(q), *args, "surrogate", "edge")
        assert result["state"] != "failed", (space.point(q), result["reason"])


def _close(a, b) -> bool:
    return all(a[k] == b[k] if isinstance(b[k], str) else abs(a[k] - b[k]) < 1e-9 for k in b)


def test_the_base_point_round_trips():
    # MagOne's disc in N52, 3 mm at the closest (its 2.5 mm would saturate the chip with the grade's strongest)
    stock = BASE.model_copy(update={"magnet": BASE.magnet.model_copy(update={"grade": "N52"}),
                                    "sensor": BASE.sensor.model_copy(update={"d_min_mm": 3.0})})
    targets = parse_targets("")
    point = base_point(stock, targets.variables)
    space = Space(targets, BASE)
    assert point is not None and _close(space.point(space.params(point)), point)


#: The stiff pad's known failures over twenty seeds (bench/design_search.py, this code, the flat tip's surrogate table
#: with its fourth hypercube): at seeds 0, 4, 11, 15 and 17 one sweep design dominates the chosen one (the sweep's
#: highest range, 43.0 N at 17.5 mN: Dragon Skin 20, flat, 8 x 3 mm N45, a 0.6 mm cover; those studies stop at
#: 34.7-42.8 N on another magnet, most often 10 x 3 mm N42 under a thick cover), and at seeds 0, 4 and 17 the front
#: holds 0.882, 0.938 and 0.879 of the sweep's hypervolume; Ecoflex 00-50 with a flat tip, two feasible designs in
#: the sweep's 3,000, is missed at 5 seeds of 20. Over 40 seeds: 12 dominated, 7 under 0.95 (with the table before
#: the fourth hypercube, which judged the thin-cover designs less well against the FE: 6 and 2).
STIFF_PAD_SEEDS = ("stiff pad, 20 seeds: the chosen design dominated by the sweep's one 43.0 N design at seeds 0, 4, "
                   "11, 15, 17; the hypervolume under 0.95 at seeds 0, 4, 17")


@pytest.mark.slow
@pytest.mark.parametrize(("name", "seeds", "whole"), [
    ("fingertip", 20, True), ("taxel", 20, True),
    pytest.param("stiff_pad", 20, True, marks=pytest.mark.xfail(strict=True, reason=STIFF_PAD_SEEDS))])
def test_the_study_finds_the_sweeps_front_at_every_seed(name, seeds, whole):
    """bench/design_search.py on each bench set at the study's default size: 300 trials against a 3,000-design sweep,
    seeds 0 to ``seeds`` - 1; every seed's feasible front holds 0.95 of the sweep's hypervolume or more and, with
    ``whole``, no sweep design dominates the chosen one and every (material, tip) pair with a feasible sweep design
    has one in the study (about 6 s a seed on two cores; the stiff pad's known failures: :data:`STIFF_PAD_SEEDS`)."""
    sys.path.insert(0, str(BENCH))
    import design_search as ds

    from magfab.inverse.study import client, evaluate_all, records, run_study

    targets, base = ds._load(name, 300, all_tips=True)
    space = Space(targets, base)
    with client(None, 2) as c:
        sweep = evaluate_all([space.point(p) for p in space.latin_hypercube(3000, 12345)], targets, base, c,
                             "surrogate")
        rows = []
        for seed in range(seeds):
            t = targets.model_copy(update={"study": targets.study.model_copy(update={"seed": seed})})
            recs = records(run_study(t, base, Path(ds.tempfile.mkdtemp()) / "study.log", c))
            rows.append(ds.compare(recs, sweep, t))
    assert min(r["hypervolume_ratio"] for r in rows) >= 0.95, [r["hypervolume_ratio"] for r in rows]
    if whole:
        assert all(r["sweep_dominating_chosen"] == 0 for r in rows), [r["sweep_dominating_chosen"] for r in rows]
        assert not any(r["pairs_missed"] for r in rows), [r["pairs_missed"] for r in rows]
