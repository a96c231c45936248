"""TARGETS files and the search space: clear one-line errors, and points that become buildable specs."""

from __future__ import annotations

import numpy as np
import pytest

from magfab import derive, load_spec
from magfab.errors import SpecError
from magfab.inverse.pareto import front_mask, pick_for_verification, ranks
from magfab.inverse.space import base_point, candidate_spec, grid, latin_hypercube
from magfab.inverse.targets import parse_targets
from magfab.spec import default_spec_text, parse_spec

MAGONE = load_spec(None)
#: MagOne with the grade its 5 x 2 mm magnet is sold in from stock (recipes/magnet_stock.toml has no N35 one).
STOCK = parse_spec(default_spec_text().replace('grade = "N35"', 'grade = "N52"'))


def test_example_targets_parse():
    from importlib import resources

    text = resources.files("magfab.examples").joinpath("targets.toml").read_text()
    t = parse_targets(text)
    assert t.name == "fingertip" and t.require.max_diameter_mm == 14.0
    assert t.directions() == ["minimize", "maximize", "minimize"]


@pytest.mark.parametrize("text, key, words", [
    ('objectives = ["resolution"]', "objectives", "is not one of"),
    ('[variables]\nd_max_mm = [9.0, 3.0]', "variables.d_max_mm", "low <= high"),
    ('[variables]\nmaterials = ["ecoflex-00-31"]', "variables.materials", "recipes/materials.toml"),
    ('[variables]\nmagnets = ["d99_h99"]', "variables.magnets", "recipes/magnet_stock.toml"),
    ('[require]\nnormal_range_N = -1.0', "require.normal_range_N", "greater than 0"),
    ('[require]\nmax_diameter_mm = 6.0\n[variables]\nelastomer_diameter_mm = [8.0, 12.0]',
     "variables.elastomer_diameter_mm", "max_diameter_mm"),
    ('[study]\ntrails = 10', "study.trails", "unknown key"),
])
def test_bad_targets_name_the_key(text, key, words):
    with pytest.raises(SpecError) as err:
        parse_targets(text)
    assert err.value.key == key and words in str(err.value), str(err.value)
    assert "\n" not in str(err.value)


def test_magone_is_a_point_and_its_spec_is_magone():
    """The base spec as a point of the space, put back into a spec, is the same design (geometry and figures)."""
    t = parse_targets("")
    assert base_point(MAGONE, t.variables) is None  # no stock 5 x 2 mm disc in N35
    point = base_point(STOCK, t.variables)
    assert point is not None and point["grade"] == "N52" and point["material"] == "ecoflex-00-30"
    spec = candidate_spec(point, MAGONE, t, "again")
    assert spec.magnet.grade == "N52"
    a, b = derive(MAGONE), derive(spec)
    for name in ("d_rest_mm", "elastomer_height_mm", "elastomer_radius_mm", "magnet_radius_mm", "cover_mm",
                 "z_magnet_low_mm", "pad_radius_mm"):
        assert getattr(b, name) == pytest.approx(getattr(a, name), abs=1e-9), name


def test_pad_grows_with_the_elastomer():
    t = parse_targets("")
    point = dict(base_point(STOCK, t.variables), elastomer_diameter_mm=14.0)
    d = derive(candidate_spec(point, MAGONE, t, "wide"))
    assert d.pad_radius_mm > d.lip_outer_radius_mm + 1.0


def test_a_point_that_cannot_be_a_spec_names_the_key():
    t = parse_targets("")
    point = dict(base_point(STOCK, t.variables), d_min_mm=7.0)
    with pytest.raises(SpecError) as err:
        derive(candidate_spec(point, MAGONE, t, "bad"))
    assert err.value.key == "sensor.d_min_mm"


def test_grid_and_hypercube_cover_the_variables():
    t = parse_targets('[variables]\nmagnets = ["d5_h2", "d4_h2"]\ngrades = ["N45", "N52"]\n'
                      'materials = ["ecoflex-00-30"]\n'
                      'tips = ["hemisphere"]\nd_max_mm = [4.0, 8.0]\nd_min_mm = {values = [2.5]}\n'
                      'elastomer_diameter_mm = [10.0, 12.0]\ncover_mm = {values = [1.0, 2.0]}')
    g = list(grid(t.variables, 3))
    assert len(g) == 2 * 3 * 1 * 3 * 2  # (5x2 N52, 4x2 N45) x d_max x d_min x D_e x cover
    assert {p["d_max_mm"] for p in g} == {4.0, 6.0, 8.0}
    lhs = latin_hypercube(t.variables, 20, seed=1)
    assert len(lhs) == 20 and all(4.0 <= p["d_max_mm"] <= 8.0 and p["cover_mm"] in (1.0, 2.0) for p in lhs)
    assert {(p["magnet"], p["grade"]) for p in lhs} == {("d5_h2", "N52"), ("d4_h2", "N45")}  # both, as sold
    assert latin_hypercube(t.variables, 20, seed=1) == lhs


def test_front_and_ranks_against_a_hand_example():
    v = np.array([[1.0, 5.0], [2.0, 4.0], [2.0, 6.0], [3.0, 3.0], [3.0, 3.0], [4.0, 4.0]])
    dirs = ["minimize", "minimize"]
    assert front_mask(v, dirs).tolist() == [True, True, False, True, True, False]  # equal rows do not dominate
    assert ranks(v, dirs).tolist() == [1, 1, 2, 1, 1, 2]
    assert front_mask(v, ["minimize", "maximize"]).tolist() == [True, False, True, False, False, False]
    assert pick_for_verification(v, dirs, 3) == [0, 3, 1]  # both extremes, then the farthest from them
    assert pick_for_verification(v, dirs, 5) == [0, 1, 3, 4, 2]  # the whole front, then the next rank


def test_verification_takes_near_feasible_designs_too():
    """A third of the verification budget goes to designs the cheap chain finds just short of a requirement (within
    NEAR_MARGIN); far misses and other error findings (a design constraint, docs/models.md M9: chip saturation) are
    never verified."""
    from magfab.inverse.run import _near_front
    from magfab.inverse.study import Record

    t = parse_targets('objectives = ["normal_resolution_mN", "normal_range_N"]\n[require]\nnormal_range_N = 1.0\n'
                      '[study]\nverify = 3')

    def rec(n, state, res, rng, errors=()):
        constraints = [(1.0 - rng) / 1.0, float(len(errors))]
        return Record(n, {}, state, "", "surrogate", {"normal_resolution_mN": res, "normal_range_N": rng},
                      constraints, list(errors))

    trials = [rec(0, "ok", 3.0, 1.2), rec(1, "ok", 2.5, 1.1), rec(2, "ok", 3.5, 1.0),
              rec(3, "infeasible", 2.0, 0.97),  # 3 % short: near
              rec(4, "infeasible", 1.0, 0.80),  # 20 % short: far
              rec(5, "infeasible", 1.5, 0.99, ["chip-saturates: ..."])]  # a design-constraint error: never
    picks = _near_front(trials, t)
    assert sorted(picks) == [0, 1, 3]


def test_verification_never_spends_two_places_on_one_written_design():
    """Trials whose points differ by less than the printer's step write one design (designs/NAME.toml, on the step):
    drawn fronts with drawn groups of such trials, any budget; the picks write distinct designs, as many as the budget
    or the distinct designs allow (a taxel study once verified 6 trials that wrote 3 designs)."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from magfab.inverse.run import _near_front
    from magfab.inverse.study import Record

    @settings(max_examples=60, deadline=None)
    @given(st.lists(st.tuples(st.floats(0.1, 10.0), st.floats(0.1, 10.0), st.integers(0, 5)), min_size=1,
                    max_size=25), st.integers(1, 8))
    def check(rows, verify):
        t = parse_targets('objectives = ["normal_resolution_mN", "normal_range_N"]\n[study]\nverify = '
                          f"{verify}")
        trials = [Record(n, {}, "ok", "", "surrogate", {"normal_resolution_mN": res, "normal_range_N": rng}, [0.0],
                         []) for n, (res, rng, _) in enumerate(rows)]
        group = {n: g for n, (_, _, g) in enumerate(rows)}
        picks = _near_front(trials, t, lambda r: group[r.number])
        written = [group[i] for i in picks]
        assert len(set(written)) == len(written) == min(verify, len(set(group.values()))), (picks, written)

    check()


def test_the_findings_constraint_is_graded_where_a_finding_has_a_measure():
    """The sampler reads how far a design is from feasible: a saturating chip by how far the field at d_min exceeds
    full scale (more saturation, a larger violation), the resolution asked for by its own requirement only (not
    counted twice), every other error as one; a design evaluated by the real chain agrees with its own figures."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from magfab.inverse.evaluate import findings_violation

    asks = parse_targets("[require]\nnormal_resolution_mN = 4.0")
    free = parse_targets("")
    sat, short, other = "chip-saturates: ...", "resolution-short: ...", "pocket-thin: ..."

    @settings(max_examples=50, deadline=None)
    @given(a=st.floats(1.0, 50.0, exclude_min=True), b=st.floats(1.0, 50.0, exclude_min=True))
    def graded(a, b):
        va, vb = (findings_violation(asks, {"saturation": x}, [sat]) for x in (a, b))
        assert va > 0 and vb > 0 and (va < vb) == (a < b)
        assert findings_violation(asks, {"saturation": a}, [sat, short]) == va  # the requirement grades it
        assert findings_violation(free, {"saturation": a}, [sat, short]) == va + 1.0  # none asked: it counts
        assert findings_violation(asks, {"saturation": a}, [sat, other]) == va + 1.0

    graded()
    assert findings_violation(asks, {}, []) == 0.0


def test_a_saturating_design_is_infeasible_by_how_far_it_saturates():
    """The real chain: the same design with d_min closer saturates more, and its findings violation grows."""
    import json

    from magfab.inverse.evaluate import evaluate

    targets = parse_targets("")
    point = base_point(STOCK, targets.variables)
    assert point is not None
    out = []
    for d_min in (2.4, 1.9):
        p = {**point, "d_min_mm": d_min}
        r = evaluate(p, STOCK.model_dump_json(), targets.model_dump_json())
        assert r["state"] == "infeasible" and any(e.startswith("chip-saturates") for e in r["errors"]), r
        out.append((r["metrics"]["saturation"], r["constraints"][-1]))
    assert 1.0 < out[0][0] < out[1][0] and 0.0 < out[0][1] < out[1][1], out
    assert json.dumps(out)  # plain numbers
