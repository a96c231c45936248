"""The elastomer FE's surrogate: the scaling it rests on, its shipped table reproducible by the FE, its error on
MagOne against the build's own FE, its region covering the example targets' whole box (both tips, every silicone),
its error at random points of that box against the FE, and its refusal outside the region it was validated on."""

from __future__ import annotations

import numpy as np
import pytest

from magfab.models import mechanics as mech
from magfab.models.mechanics import fe_surrogate as S
from magfab.models.predict import indentation_grid, shear_probe_depths
from magfab.spec import Tip


def _whole_box_bodies(n: int, seed: int) -> list[mech.Body]:
    """The bodies of the designs the spec accepts among ``n`` hypercube points over the example targets' whole box:
    their ranges and magnets, both tips, every silicone of the catalogue (bench/design.py's ``whole_box``)."""
    from importlib import resources

    from magfab.design import derive
    from magfab.errors import InputError, ModelLimitError
    from magfab.inverse.space import candidate_spec, latin_hypercube
    from magfab.inverse.targets import parse_targets
    from magfab.spec import load_spec

    targets = parse_targets(resources.files("magfab.examples").joinpath("targets.toml").read_text(encoding="utf-8"))
    variables = targets.variables.model_copy(update={"tips": [Tip.HEMISPHERE, Tip.FLAT], "materials": None})
    targets = targets.model_copy(update={"variables": variables})
    base = load_spec(None)
    out = []
    for p in latin_hypercube(variables, n, seed=seed):
        try:
            out.append(mech.Body.from_design(derive(candidate_spec(p, base, targets, "box"))))
        except (InputError, ModelLimitError):
            continue
    return out


def test_the_region_covers_the_example_targets_whole_box():
    """Every design the spec accepts over the example targets' whole box, of either tip, is in the surrogate's region
    (none falls back to the FE for its geometry)."""
    bodies = _whole_box_bodies(300, seed=123)
    assert {b.tip for b in bodies} == {Tip.HEMISPHERE, Tip.FLAT}
    assert len(bodies) > 100
    outside = [(b, S._refusal(b)) for b in bodies if not S.in_region(b)]
    assert not outside, outside[:3]


@pytest.mark.parametrize("name", ["fingertip", "taxel", "stiff_pad"])
def test_the_region_covers_each_bench_target_sets_search(name):
    """Every design of a hypercube of the search's coordinates on each bench target set (bench/targets/: a small
    taxel's magnet nearly as wide as its body, a stiff pad's thick cover), of either tip, is in the surrogate's
    region: the search evaluates none of them with the FE for its geometry."""
    from pathlib import Path

    from magfab.design import derive
    from magfab.inverse.space import Space, candidate_spec
    from magfab.inverse.targets import load_targets

    targets, base = load_targets(Path(__file__).resolve().parents[2] / "bench" / "targets" / f"{name}.toml")
    space = Space(targets, base)
    bodies = [mech.Body.from_design(derive(candidate_spec(space.point(q), base, targets, "box")))
              for q in space.latin_hypercube(300, 5)]
    assert {b.tip for b in bodies} == {Tip.HEMISPHERE, Tip.FLAT}
    outside = [(S.ratios(b), S._refusal(b)) for b in bodies if not S.in_region(b)]
    assert not outside, outside[:3]


def _force_errors(x: dict[str, float], tip: Tip, up_to: float) -> np.ndarray:
    """Relative errors of the surrogate's force against the FE's normal curve (the table's mesh, no shear probe) at
    the table's grid points up to ``up_to`` R that both reach, for the body of ratios ``x`` at the table's radius."""
    body = S.body_of(x, tip=tip)
    d = S.GRID[1:][S.GRID[1:] <= up_to] * S.R_TABLE
    truth = mech.fe(body, 1.0, d, mesh_mm=S.MESH_TABLE, on_failure="truncate")
    n = len(truth.force_N)
    guess = S.curve(body, 1.0, d)
    n = min(n, len(guess.force_N))
    assert n >= 3
    return np.abs(guess.force_N[:n] - truth.force_N[:n]) / truth.force_N[:n]


def _random_points(tip: Tip, n: int, seed: int) -> list[dict[str, float]]:
    """Ratios of random designs of the whole box with tip ``tip`` (not the table's nodes: another sampler, seed)."""
    rng = np.random.default_rng(seed)
    bodies = [b for b in _whole_box_bodies(40 * n, seed=seed) if b.tip == tip]
    return [S.ratios(b) for b in rng.choice(np.array(bodies, dtype=object), size=n, replace=False)]


@pytest.mark.parametrize("tip", [Tip.HEMISPHERE, Tip.FLAT])
def test_error_at_a_random_design_of_the_box_is_within_the_stated_one(tip):
    """At a random design of the whole box (its ratios at the table's radius), the surrogate's force over the first
    third of R of indentation is within the held-out maximum its data file states."""
    x = _random_points(tip, 1, seed=2024)[0]
    err = _force_errors(x, tip, 0.35)
    assert err.max() <= S.held_out_error(tip)["force_max"], (x, err)


@pytest.mark.slow
@pytest.mark.parametrize("tip", [Tip.HEMISPHERE, Tip.FLAT])
def test_error_at_random_designs_of_the_box_is_within_the_stated_one(tip):
    """Eight random designs of the whole box per tip, over every depth both reach: the median and 90th percentile of
    the force error within twice the stated ones, the largest within 1.25 times the stated maximum (a tail statistic:
    the hemispherical tip's eight reached 18.7 % against the 18.6 % of its 67 held-out runs, at the deepest point)."""
    errs = np.concatenate([_force_errors(x, tip, S.GRID[-1]) for x in _random_points(tip, 8, seed=7)])
    e = S.held_out_error(tip)
    assert np.median(errs) <= 2.0 * e["force_median"] + 1e-3
    assert np.percentile(errs, 90) <= 2.0 * e["force_p90"]
    assert errs.max() <= 1.25 * e["force_max"]


def test_the_fe_scales_as_the_surrogate_assumes():
    """The same shape at 1.5x the size and twice the modulus: forces x 4.5, travel x 1.5, stretch equal (FE, coarse
    mesh scaled with the body)."""
    x = {"a": 0.42, "h": 0.33, "z": 0.72, "c": 0.3}
    d = np.array([0.1, 0.3])  # indentation over R
    small = mech.fe(S.body_of(x, 6.0), 20.0, d * 6.0, mesh_mm=1.0)
    large = mech.fe(S.body_of(x, 9.0), 40.0, d * 9.0, mesh_mm=1.5)
    assert large.force_N == pytest.approx(small.force_N * 2.0 * 1.5**2, rel=2e-3)
    assert large.magnet_displacement_mm == pytest.approx(small.magnet_displacement_mm * 1.5, rel=2e-3)
    assert large.max_stretch == pytest.approx(small.max_stretch, rel=2e-3)


@pytest.mark.parametrize("tip", [Tip.HEMISPHERE, pytest.param(Tip.FLAT, marks=pytest.mark.slow)])
def test_the_shipped_table_is_what_the_fe_gives(tip):
    """A held-out body of the shipped file, rerun with the FE now: the same numbers (the file is reproducible), and
    the surrogate's error on it within the file's stated maximum."""
    data = S._shipped(tip)[1]
    kept = data["held_out"][0]
    again = S.run(kept["x"], tip)
    for key in ("force", "travel", "disp"):
        np.testing.assert_allclose(again[key], kept[key], rtol=1e-6, equal_nan=True)
    err = S._errors(S._shipped(tip)[0], [kept])
    assert err["force_max"] <= data["held_out_error"]["force_max"] + 1e-12


def test_magone_against_the_builds_fe(magone_neo_hookean):
    """The surrogate's MagOne curve over the working range (the deepest preloads, past the range, are off by up to
    11 %) and rest shear response against the build's FE (the prediction's), within the held-out error the file
    states (its 90th percentile, doubled for a single design)."""
    magone_design, magone_prediction = magone_neo_hookean  # the neo-Hookean law, whose table this is
    body = mech.Body.from_design(magone_design)
    assert S.in_region(body)
    fe = magone_prediction.curves["nominal"]
    ind = indentation_grid(magone_design)
    curve, resp = S.normal_and_shear(body, fe.mu_kPa, ind, 3.0, shear_probe_depths(magone_design, ind), 0.05)
    used = fe.force_N <= 1.5 * magone_prediction.normal.range_by_material_N["nominal"]  # the working range
    assert len(curve.force_N) > np.count_nonzero(used)  # the surrogate's curve (to its reach) spans it
    n = np.count_nonzero(used)
    band = 2.0 * S.held_out_error()["force_p90"]
    np.testing.assert_allclose(curve.force_N[1:n], fe.force_N[1:n], rtol=max(band, 0.02))
    e = S.held_out_error()
    np.testing.assert_allclose(curve.magnet_displacement_mm[3:n], fe.magnet_displacement_mm[3:n],
                               rtol=2.0 * e["travel_p90"])
    np.testing.assert_allclose(curve.max_stretch[1:n] - 1.0, fe.max_stretch[1:n] - 1.0, rtol=2.0 * e["stretch_p90"])
    np.testing.assert_allclose(curve.stiffness_N_per_mm[3:n], fe.stiffness_N_per_mm[3:n], rtol=max(band, 0.02))
    assert resp.displacement_mm_per_N[0] == pytest.approx(
        magone_prediction.shear.stiffness_N_per_mm["nominal"] ** -1,
        rel=max(2.0 * S.held_out_error()["disp_p90"], 0.03))


@pytest.mark.parametrize("change, words", [
    ({"tip": "flat", "base_height_mm": 7.9, "magnet_z_mm": 0.3}, "ratio z"),
    ({"magnet_radius_mm": 0.0, "magnet_height_mm": 0.0, "magnet_edge_radius_mm": 0.0}, "with a magnet only"),
    ({"magnet_height_mm": 0.3, "magnet_edge_radius_mm": 0.05}, "ratio h"),
])
def test_outside_the_region_it_refuses(magone_design, change, words):
    from dataclasses import replace

    body = replace(mech.Body.from_design(magone_design), **change)
    assert not S.in_region(body)
    with pytest.raises(S.OutsideRegion, match=words):
        S.normal_and_shear(body, 20.0, np.array([0.0, 1.0]), 3.0, np.array([0.0]), 0.05)


@pytest.mark.parametrize("key", ["ecoflex-00-10", "ecoflex-00-30", "ecoflex-00-50", "dragon-skin-10",
                                 "dragon-skin-20", "dragon-skin-30"])
def test_the_yeoh_blend_against_the_fe_at_each_silicones_law(magone_design, key):
    """MagOne's body with each recipe's Yeoh law (k2 0.013-0.057, none of them the tables' 0 or 0.06): the FE run
    now against the surrogate's blend of the two tables, on the grid points before the surrogate's reach (2.7-2.9 mm
    here: the last point, at its interpolated end, is 5-8 % off, as the neo-Hookean table's is), within the blend's
    stated held-out error (its 90th percentile, doubled for a single design; at least 2 %; travel from the fourth
    point, as for the neo-Hookean table). Measured: force within 1.8 %, travel within 1.4 % from there."""
    from magfab.recipes.resolve import material

    law = material(key).yeoh
    body = mech.Body.from_design(magone_design)
    ind = np.linspace(0.0, 3.0, 13)
    fe = mech.fe(body, law.mu_kPa, ind, mesh_mm=S.MESH_TABLE, on_failure="truncate", material="yeoh",
                 yeoh_ratios=(law.k2, law.k3))
    curve, _ = S.normal_and_shear(body, law.mu_kPa, ind, 3.0, ind[:3], 0.05, law.k2)
    assert len(fe.force_N) == ind.size and curve.indentation_mm[-1] >= 2.5  # the FE to 3 mm, the blend past 2.5
    n = int(np.count_nonzero(ind < curve.indentation_mm[-1] - 1e-9))  # the grid points before the blend's end
    e = S.held_out_error(Tip.HEMISPHERE, yeoh=True)
    np.testing.assert_allclose(curve.force_N[1:n], fe.force_N[1:n], rtol=max(2.0 * e["force_p90"], 0.02))
    np.testing.assert_allclose(curve.magnet_displacement_mm[3:n], fe.magnet_displacement_mm[3:n],
                               rtol=max(2.0 * e["travel_p90"], 0.02))
    neo, _ = S.normal_and_shear(body, law.mu_kPa, ind, 3.0, ind[:3], 0.05)
    assert curve.force_N[-1] > neo.force_N[-1]  # the blend stiffens as the law does


def test_the_shipped_yeoh_table_is_what_the_fe_gives():
    """A held-out body of the Yeoh file, rerun with the FE at its k2 now: the same numbers."""
    data = S._shipped(Tip.HEMISPHERE, True)[1]
    assert data["k2"] == S.YEOH_K2 and data["held_out_k2"] == S.YEOH_HELD_OUT_K2
    kept = data["held_out"][0]
    again = S.run(kept["x"], Tip.HEMISPHERE, S.YEOH_HELD_OUT_K2)
    for key in ("force", "travel", "disp"):
        np.testing.assert_allclose(again[key], kept[key], rtol=1e-6, equal_nan=True)
    assert data["held_out_error"]["force_rms"] <= 0.05


def test_each_shipped_table_is_built_once_however_it_is_asked_for():
    """A two-tip Yeoh search asks for every table, by enum and by name, with the law given or left out: each of the
    four tables is built once and then served from memory (a cache keyed on the spelling rebuilt one on most
    designs, 0.2 s each, ten times the design itself)."""
    S._loaded.cache_clear()
    for _ in range(3):
        for tip in (Tip.HEMISPHERE, Tip.FLAT):
            for ask in ((tip,), (tip, False), (tip.value, False), (tip, True), (tip.value, True)):
                S._shipped(*ask)
            S.held_out_error(tip, yeoh=True)
    assert S._loaded.cache_info().misses == 4
    assert S._shipped(Tip.FLAT) is S._shipped("flat", False)
