"""The search's coordinates: every point of the unit cube is a geometry the build accepts, the mapping round-trips,
and (slow) the study's front against a ten times larger sweep on a bench target set."""

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


def _close(a, b) -> bool:
    return all(a[k] == b[k] if isinstance(b[k], str) else abs(a[k] - b[k]) < 1e-9 for k in b)


def test_the_base_point_round_trips():
    stock = BASE.model_copy(update={"magnet": BASE.magnet.model_copy(update={"grade": "N52"})})
    targets = parse_targets("")
    point = base_point(stock, targets.variables)
    space = Space(targets, BASE)
    assert point is not None and _close(space.point(space.params(point)), point)


@pytest.mark.slow
def test_the_study_finds_the_sweeps_front_on_the_fingertip_set():
    """bench/design_search.py on the fingertip set, small: 60 trials against a 600-design sweep, one seed."""
    sys.path.insert(0, str(BENCH))
    import design_search as ds

    from magfab.inverse.study import client, evaluate_all, records, run_study

    targets, base = ds._load("fingertip", 60, all_tips=False)
    space = Space(targets, base)
    with client(None, 2) as c:
        sweep = evaluate_all([space.point(p) for p in space.latin_hypercube(600, 12345)], targets, base, c,
                             "surrogate")
        recs = records(run_study(targets, base, Path(ds.tempfile.mkdtemp()) / "study.log", c))
    row = ds.compare(recs, sweep, targets)
    assert row["hypervolume_ratio"] >= 0.9, row
    assert row["sweep_dominating_chosen"] == 0, row
