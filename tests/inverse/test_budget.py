"""A study's limits (magfab.inverse.budget), each at its edge: just under passes, just over is refused in one line
naming the option or key, its value and what is allowed; generated plans near and past the edges."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab.inverse import budget
from magfab.inverse.space import grid
from magfab.inverse.study import StudyError
from magfab.inverse.targets import parse_targets

SMALL = """
[variables]
magnets = ["d5_h2"]
grades = ["N52"]
materials = ["ecoflex-00-30"]
tips = ["hemisphere"]
d_max_mm = [5.0, 7.0]
d_min_mm = [2.5, 3.0]
elastomer_diameter_mm = {values = [12.0]}
cover_mm = [1.5, 2.0]
[study]
trials = %d
"""


def test_the_grid_at_the_trial_limit_passes_and_one_over_is_refused():
    targets = parse_targets(SMALL % 8)  # 2 x 2 x 2 numeric levels of one magnet, material and tip
    assert budget.check_plan(targets, 2, None, 2) == 8 == len(list(grid(targets.variables, 2)))
    with pytest.raises(StudyError, match=r"--grid 3: 27 designs, more than study.trials = 8"):
        budget.check_plan(parse_targets(SMALL % 8), 3, None, 2)
    assert budget.check_plan(parse_targets(SMALL % 27), 3, None, 2) == 27


def test_the_samples_at_the_trial_limit_pass_and_one_over_is_refused():
    targets = parse_targets(SMALL % 40)
    assert budget.check_plan(targets, None, 40, 2) == 40
    with pytest.raises(StudyError, match=r"^--lhs 41: designs, more than study.trials = 40 "):
        budget.check_plan(targets, None, 41, 2)


def test_the_designs_at_the_memory_limit_pass_and_one_over_is_refused():
    most = budget.most_designs(2)
    assert most * budget.MB_PER_DESIGN + 2 * budget.MB_PER_WORKER + budget.STUDY_FIXED_MB <= budget.memory_mb()
    targets = parse_targets(SMALL % 1_000_000)
    assert budget.check_plan(targets, None, most, 2) == most
    with pytest.raises(StudyError, match=rf"^--lhs {most + 1}: designs, more than memory holds: at most {most:,}"):
        budget.check_plan(targets, None, most + 1, 2)
    budget.check_trials(parse_targets(SMALL % most), 2)
    with pytest.raises(StudyError, match=rf"^study.trials = {most + 1:,}: more than memory holds"):
        budget.check_trials(parse_targets(SMALL % (most + 1)), 2)


@pytest.mark.parametrize("cores", [1, 2, 64])
def test_the_workers_at_the_limit_pass_and_one_over_is_refused(monkeypatch, cores):
    monkeypatch.setattr(budget.os, "cpu_count", lambda: cores)
    most = budget.most_workers()
    assert most == min(cores, int((budget.memory_mb() - budget.STUDY_FIXED_MB) // budget.MB_PER_WORKER))
    assert budget.check_workers(most, None) == most == budget.check_workers(None, None)
    with pytest.raises(StudyError, match=rf"^--workers {most + 1}: more than this machine can run: at most {most} "):
        budget.check_workers(most + 1, None)
    assert budget.check_workers(most + 1, "tcp://127.0.0.1:8786") == 0  # an existing cluster: no local workers


@settings(max_examples=60, deadline=None)
@given(levels=st.integers(2, 60), samples=st.integers(1, 2_000_000), workers=st.integers(1, 300),
       trials=st.integers(1, 1_000_000), cores=st.integers(1, 128))
def test_generated_plans_are_refused_exactly_past_a_limit(levels, samples, workers, trials, cores):
    """Near and past every edge: a plan is accepted iff it is within the trials and memory, workers iff within the
    cores and memory; a refusal is one line naming the option."""
    targets = parse_targets(SMALL % trials)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(budget.os, "cpu_count", lambda: cores)
        _accepted_iff(workers <= budget.most_workers(), f"--workers {workers}:", budget.check_workers, workers, None)
    for lv, n, count in ((levels, None, budget.grid_size(targets.variables, levels)), (None, samples, samples)):
        _accepted_iff(count <= trials and count <= budget.most_designs(1), "--grid" if lv else "--lhs",
                      budget.check_plan, targets, lv, n, 1)


def _accepted_iff(within: bool, start: str, check, *args) -> None:
    if within:
        check(*args)
        return
    with pytest.raises(StudyError) as info:
        check(*args)
    assert str(info.value).startswith(start) and "\n" not in str(info.value)


@settings(max_examples=20, deadline=None)
@given(levels=st.integers(2, 4))
def test_the_grid_is_counted_as_it_is_listed(levels):
    variables = parse_targets(SMALL % 10).variables
    assert budget.grid_size(variables, levels) == len(list(grid(variables, levels))) == levels**3
    assert budget.grid_size(parse_targets("").variables, 50) > 10**9  # the default variables at --grid 50




# ---- a study's time -----------------------------------------------------------------------------------------------

def _sample(text: str, n: int, seed: int):
    from magfab.inverse.space import latin_hypercube
    from magfab.spec import load_spec

    targets = parse_targets(text)
    return targets, load_spec(None), latin_hypercube(targets.variables, n, seed)


def _models(points, base, targets, fidelity: str = "surrogate") -> list[str | None]:
    """Each point's model as the study's evaluate chooses it: "fe" outside the surrogate's region (or every point
    with the full chain, on the printer's step), "surrogate" inside, None for a point the spec refuses at once."""
    from magfab.check import preflight
    from magfab.design import derive
    from magfab.errors import InputError
    from magfab.inverse.evaluate import _elastomer_model, bench_point
    from magfab.inverse.space import candidate_spec

    out: list[str | None] = []
    for p in points:
        try:
            if fidelity == "fe":
                p = bench_point(p, base, targets)
            design = preflight(derive(candidate_spec(p, base, targets, "candidate")))
        except InputError:
            out.append(None)
            continue
        out.append("fe" if fidelity == "fe" or _elastomer_model(design)[0] is None else "surrogate")
    return out


@settings(max_examples=6, deadline=None)
@given(n=st.integers(1, 40), seed=st.integers(0, 2**16), workers=st.integers(1, 4))
def test_a_studys_estimate_grows_with_its_designs_and_shrinks_with_its_workers(n, seed, workers):
    """Priced design by design: the same designs twice cost twice, more workers divide them, the full chain (FE)
    takes every design the spec accepts and costs more than the surrogate, and a search's verified designs' chain
    and builds add to it."""
    targets, base, points = _sample("[study]\ntrials = 300\n", n, seed)
    models = _models(points, base, targets)
    one = budget.study_cost(points, n, base, targets, "surrogate", 1)
    assert one.designs == n and one.by_fe == models.count("fe") and one.verify_s == one.build_s == 0.0
    twice = budget.study_cost(points, 2 * n, base, targets, "surrogate", 1)
    assert twice.design_s == pytest.approx(2 * one.design_s) and twice.by_fe == 2 * one.by_fe
    spread = budget.study_cost(points, n, base, targets, "surrogate", workers)
    shared = budget.STUDY_START_S + one.design_s / workers
    assert shared - 1e-9 <= spread.seconds <= min(one.seconds, shared + one.longest_s) + 1e-9
    fe = budget.study_cost(points, n, base, targets, "fe", workers)
    assert fe.by_fe == _models(points, base, targets, "fe").count("fe")
    assert fe.design_s > one.design_s or fe.by_fe == one.by_fe
    search = budget.study_cost(points, n, base, targets, "surrogate", workers, verify=4)
    if models.count(None) < n:
        assert search.verify_s > 0 and search.build_s > 0
    assert search.seconds >= spread.seconds
    line = search.line()
    assert line.startswith("estimated ") and f"on {workers} worker" in line and f"{n:,} designs" in line
    assert "\n" not in line


def test_the_estimate_counts_the_designs_outside_the_surrogates_region():
    """Variables that reach bodies the surrogate does not cover (a small elastomer under a thick cover: c past the
    box's 1.05 R): those are priced at the FE's estimate, as the study evaluates them."""
    targets, base, points = _sample("[study]\ntrials = 300\n[variables]\nelastomer_diameter_mm = [6.0, 8.0]\n"
                                    "cover_mm = [2.0, 4.0]\n", budget.PRICED, 3)
    fe = _models(points, base, targets).count("fe")
    cost = budget.study_cost(points, len(points), base, targets, "surrogate", 2)
    assert cost.by_fe == fe > 0
    assert cost.design_s > len(points) * budget.SURROGATE_S


@settings(max_examples=4, deadline=None)
@given(trials=st.integers(20, 2000), workers=st.sampled_from([1, 2, 16, 256]))
def test_a_searchs_estimate_is_never_shorter_than_its_own_loop(trials, workers):
    """The search asks each design after the one before it is told, in the calling process: however many workers
    share the designs, its estimate is at least its trials at LOOP_S each; a sweep (no loop) is not bounded so."""
    from magfab.spec import load_spec

    targets = parse_targets(f"[study]\ntrials = {trials}\n")
    search = budget.search_cost(targets, load_spec(None), workers)
    assert search.loop_s == pytest.approx(trials * budget.LOOP_S)
    assert search.seconds >= budget.STUDY_START_S + trials * budget.LOOP_S + search.build_s - 1e-9
    sweep = budget.study_cost(budget.search_sample(targets, load_spec(None)), trials, load_spec(None), targets,
                              "surrogate", workers)
    assert sweep.loop_s == 0.0
