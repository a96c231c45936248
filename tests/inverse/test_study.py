"""The search on a local Dask cluster of two workers: its front against brute force on a small grid, a study that
resumes after an interruption, and failed designs recorded with their reason while the study goes on."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab.inverse.pareto import front_mask
from magfab.inverse.space import grid
from magfab.inverse.study import client, evaluate_all, open_study, records, run_study
from magfab.inverse.targets import parse_targets
from magfab.spec import load_spec

BASE = load_spec(None)
#: 2 magnets (as sold: 5 x 2 mm N52, 4 x 2 mm N45) x 2 silicones x 3 rest distances x 2 diameters = 24 designs.
SMALL = """
name = "small"
objectives = ["normal_resolution_mN", "normal_range_N"]
[variables]
magnets = ["d5_h2", "d4_h2"]
materials = ["ecoflex-00-30", "dragon-skin-10"]
tips = ["hemisphere"]
d_max_mm = {values = [4.5, 6.0, 7.5]}
d_min_mm = {values = [3.0]}
elastomer_diameter_mm = {values = [10.0, 12.0]}
cover_mm = {values = [1.5]}
[study]
trials = %d
seed = 3
"""


@pytest.fixture(scope="module")
def cluster():
    with client(None, 2) as c:
        yield c


def _key(point) -> tuple:
    return tuple(sorted(point.items()))


def _same(a: dict, b: dict) -> bool:
    """Equal figures, a NaN (a figure the prediction lacks) equal to a NaN."""
    return a.keys() == b.keys() and all(a[k] == b[k] or (a[k] != a[k] and b[k] != b[k]) for k in a)


def _front(recs, targets) -> set:
    ok = [r for r in recs if r.state == "ok"]
    v = np.array([[r.metrics[o.value] for o in targets.objectives] for r in ok])
    return {_key(r.point) for r, on in zip(ok, front_mask(v, targets.directions())) if on}


def test_front_against_brute_force(cluster, tmp_path):
    """Every design of the grid evaluated (the brute force), then a study of twice as many trials on the same space:
    the study's front holds only true front designs, and all of them."""
    targets = parse_targets(SMALL % 48)
    everything = evaluate_all(grid(targets.variables, 2), targets, BASE, cluster, "surrogate")
    assert len(everything) == 24 and all(r.model == "surrogate" for r in everything)
    assert sum(r.state == "ok" for r in everything) >= 6, [r.reason for r in everything]
    truth = _front(everything, targets)
    assert 2 <= len(truth) < 24
    study = run_study(targets, BASE, tmp_path / "study.log", cluster)
    recs = records(study)
    assert len(recs) == 48
    found = _front(recs, targets)
    assert found <= truth  # no dominated design is claimed
    assert found == truth, f"the study missed {len(truth - found)} of {len(truth)} front designs"
    # the same design gets the same figures from the study as from the brute force (deterministic evaluation)
    by_point = {_key(r.point): r.metrics for r in everything}
    for r in recs:
        if r.state == "ok":
            assert _same(r.metrics, by_point[_key(r.point)])


def test_a_repeated_design_does_not_spend_a_trial(cluster, tmp_path):
    """On the 24-design grid, a study of 20 trials evaluates 20 different designs: a trial that asks a design asked
    before is told that design's result, marked a repeat, and neither counted nor listed."""
    from optuna.trial import TrialState

    from magfab.inverse.study import REPEAT, RESULT

    study = run_study(parse_targets(SMALL % 20), BASE, tmp_path / "study.log", cluster)
    recs = records(study)
    assert len(recs) == 20 == len({_key(r.point) for r in recs})
    repeats = [t for t in study.get_trials(deepcopy=False) if t.user_attrs.get(REPEAT)]
    assert repeats, "no repeat was asked: the test no longer exercises one"
    first = {_key(r.point): r for r in recs}
    for t in repeats:
        assert t.state in (TrialState.COMPLETE, TrialState.FAIL)
        assert t.user_attrs[RESULT]["metrics"] == first[_key(t.user_attrs["point"])].metrics or \
            _same(t.user_attrs[RESULT]["metrics"], first[_key(t.user_attrs["point"])].metrics)


def test_an_interrupted_study_resumes(cluster, tmp_path):
    """A trial left running (the process was killed while a design was out) is failed as "interrupted" and its
    point asked again; the study then runs to its new total, counting what the first run stored."""
    from magfab.inverse.space import Space
    from magfab.inverse.study import StudyError

    storage = tmp_path / "study.log"
    first = parse_targets(SMALL % 6)
    run_study(first, BASE, storage, cluster)
    study = open_study(first, storage)
    orphan = study.ask()  # asked, never told: what a kill leaves behind
    point = Space(first, BASE).suggest(orphan)
    study = run_study(parse_targets(SMALL % 10), BASE, storage, cluster)  # more trials: the same study, extended
    recs = records(study)
    assert len(recs) == 10
    interrupted = [r for r in recs if r.reason == "interrupted"]
    assert len(interrupted) == 1 and interrupted[0].point == point
    assert [r for r in recs if r.point == point and r.state != "failed"], "the interrupted design was not asked again"
    other = parse_targets((SMALL % 6).replace('"normal_range_N"]', '"diameter_mm"]'))
    with pytest.raises(StudyError, match="other targets"):
        open_study(other, storage)


def _refusing(point, *args, **kwargs):
    """The evaluation, refusing designs at d_max = 7.5 mm as the geometry refuses a design it cannot build (the
    search's coordinates no longer propose those, so the test makes its own)."""
    from magfab.inverse.evaluate import evaluate

    if point["d_max_mm"] == 7.5:
        return {"state": "failed", "reason": "sensor.d_max_mm = 7.5: refused by the test", "model": "surrogate",
                "metrics": {}, "constraints": [], "errors": []}
    return evaluate(point, *args, **kwargs)


def test_failed_designs_are_recorded_and_the_study_goes_on(cluster, tmp_path, monkeypatch):
    import sys

    import cloudpickle

    from magfab.inverse import study as st

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the workers run this module's function
    monkeypatch.setattr(st, "evaluate", _refusing)
    try:
        study = run_study(parse_targets(SMALL % 12), BASE, tmp_path / "study.log", cluster)
    finally:
        cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    recs = records(study)
    assert len(recs) == 12
    failed = [r for r in recs if r.point["d_max_mm"] == 7.5]
    assert failed and all(r.state == "failed" and r.reason.startswith("sensor.d_max_mm") for r in failed)
    assert any(r.state != "failed" for r in recs)


def test_the_same_seed_gives_the_same_study(cluster, tmp_path):
    """Twice with one seed on two workers (who finish in whatever order): the same trials in the same order, the same
    figures and the same best design; another seed, another study."""
    text = _continuous(24)
    targets = parse_targets(text)

    def run(where: str, t=targets):
        recs = records(run_study(t, BASE, tmp_path / where, cluster))
        ok = [r for r in recs if r.state == "ok"]
        best = min(ok, key=lambda r: r.metrics["normal_resolution_mN"]) if ok else None
        return [(r.number, r.point, r.state) for r in recs], best and (best.number, best.point)

    first, again = run("a.log"), run("b.log")
    assert len(first[0]) == 24 and first == again
    other = run("c.log", parse_targets(text.replace("seed = 3", "seed = 4")))
    assert other[0] != first[0]


def _continuous(trials: int) -> str:
    """SMALL with two ranges in place of listed values: a space the model step proposes in."""
    return SMALL.replace("d_max_mm = {values = [4.5, 6.0, 7.5]}", "d_max_mm = [4.0, 8.0]").replace(
        "elastomer_diameter_mm = {values = [10.0, 12.0]}", "elastomer_diameter_mm = [9.0, 13.0]") % trials


def test_a_trial_costs_a_few_storage_writes(cluster, tmp_path):
    """Each write to the journal file is a lock and an append: a trial whose params the study chose itself (the first
    phase, the model's proposals) is made in one write with its params and point, and told in three (its result, its
    constraints, its values); one the sampler draws takes a write a param. An earlier loop took about 18 a trial."""
    import json

    from optuna.trial import TrialState

    from magfab.inverse.evaluate import constraint_names
    from magfab.inverse.steps import constraint_row
    from magfab.inverse.study import CONSTRAINTS

    storage = tmp_path / "study.log"
    targets = parse_targets(_continuous(30))
    study = run_study(targets, BASE, storage, cluster)
    trials = study.get_trials(deepcopy=False)
    lines = storage.read_text(encoding="utf-8").splitlines()
    assert len(trials) >= 30 and all(json.loads(line)["op_code"] is not None for line in lines)
    assert len(lines) <= 6 * len(trials), (len(lines), len(trials))
    names = constraint_names(targets)
    for t in trials:
        if t.state is TrialState.COMPLETE:  # the constraints as one list, read back in the names' order
            assert len(t.system_attrs[CONSTRAINTS]) == len(names)
            assert constraint_row(t, names) == [float(v) for v in t.user_attrs["result"]["constraints"]]


def test_each_told_trial_is_synced_once_and_optuna_reads_the_file(cluster, tmp_path, monkeypatch):
    """The journal file takes an fsync per told trial, not per write: when a trial is told its every write is on the
    disk, and the trials asked since the last tell are not synced yet. What it writes is Optuna's journal: Optuna's
    own file backend reads the same trials back."""
    import os

    import optuna
    from optuna.storages import JournalStorage
    from optuna.storages.journal import JournalFileBackend

    from magfab.inverse import journal
    from magfab.inverse import study as study_module

    synced: list[int] = []
    real_fsync = os.fsync
    monkeypatch.setattr(journal.os, "fsync", lambda fd: (synced.append(fd), real_fsync(fd))[1])
    told: list[bool] = []
    real_tell = study_module.tell

    def tell(study, trial, result, targets):  # the backend's state right after each tell
        real_tell(study, trial, result, targets)
        told.append(study._storage._backend._unsynced)

    monkeypatch.setattr(study_module, "tell", tell)
    storage = tmp_path / "study.log"
    targets = parse_targets(_continuous(30))
    study = run_study(targets, BASE, storage, cluster)
    trials = study.get_trials(deepcopy=False)
    lines = storage.read_text(encoding="utf-8").splitlines()
    assert len(told) == len(trials) >= 30 and not any(told), "a told trial's writes were left unsynced"
    assert len(synced) == len(told) < len(lines), (len(synced), len(told), len(lines))
    again = optuna.load_study(study_name=targets.name, storage=JournalStorage(JournalFileBackend(str(storage))))
    theirs = again.get_trials(deepcopy=False)
    assert [(t.number, t.state, t.params, t.values, t.user_attrs, t.system_attrs) for t in theirs] == \
        [(t.number, t.state, t.params, t.values, t.user_attrs, t.system_attrs) for t in trials]


def test_the_loop_runs_on_one_blas_thread(cluster, tmp_path):
    """While the search loop runs (its model step's fits beside the workers on the same cores), every OpenBLAS this
    process loaded runs one thread, and after it the counts are as they were: OpenBLAS's spare threads spin while
    they wait, which took as much CPU as the loop itself (the example targets on 2 workers: the main process's CPU
    time 8.7 s with the spinning threads, 4.7 s on one)."""
    from magfab.fork import _BLAS_GETTERS, _call_first, _loaded_blas

    def counts() -> list[int | None]:
        return [_call_first(lib, _BLAS_GETTERS) for lib in _loaded_blas()]

    import scipy.linalg  # noqa: F401  (its OpenBLAS loaded before the loop, as a study's fits load it)

    before = counts()
    seen: list[list[int | None]] = []
    run_study(parse_targets(_continuous(14)), BASE, tmp_path / "study.log", cluster,
              progress=lambda done, total: seen.append(counts()))
    assert before and seen and all(c == [1] * len(before) for c in seen), (before, seen[:3])
    assert counts() == before


def test_a_study_an_earlier_version_stored_resumes(cluster, tmp_path):
    """A study stored the earlier way (its first phase enqueued in the storage, each constraint set by name) runs on
    to its new total: its waiting trials are asked, its named constraints read in order, no first phase planned
    again."""
    from optuna.trial import TrialState

    from magfab.inverse.evaluate import constraint_names, evaluate
    from magfab.inverse.space import Space
    from magfab.inverse.steps import constraint_row
    from magfab.inverse.study import PLANNED, RESULT

    storage = tmp_path / "study.log"
    old = parse_targets(_continuous(12))
    space, study = Space(old, BASE), open_study(old, storage)
    plan = space.latin_hypercube(14, 5)
    for params in plan:
        study.enqueue_trial(params)
    study.set_user_attr(PLANNED, True)
    args = (BASE.model_dump_json(), old.model_dump_json())
    names = constraint_names(old)
    for _ in range(12):  # told as the earlier loop told them: a named constraint each
        trial = study.ask()
        result = evaluate(space.suggest(trial), *args, "surrogate", "old")
        trial.set_user_attr(RESULT, {k: result.get(k) for k in ("state", "reason", "model", "metrics",
                                                                 "constraints", "errors")})
        if result["state"] == "failed":
            study.tell(trial, state=TrialState.FAIL)
            continue
        for name, value in zip(names, result["constraints"]):
            trial.set_constraint(name, float(value))
        study.tell(trial, [float(result["metrics"][o.value]) for o in old.objectives])
    told = [t for t in study.get_trials(deepcopy=False) if t.state is TrialState.COMPLETE]
    assert told and all(constraint_row(t, names) == [float(v) for v in t.user_attrs[RESULT]["constraints"]]
                        for t in told)
    study = run_study(parse_targets(_continuous(24)), BASE, storage, cluster)
    recs = records(study)
    assert len(recs) == 24
    waiting = {_key(space.point(p)) for p in plan[12:]}
    assert waiting <= {_key(r.point) for r in recs}, "the earlier plan's waiting trials were not asked"
    assert not any(t.state is TrialState.WAITING for t in study.get_trials(deepcopy=False))


def test_the_workers_load_before_the_first_design(cluster):
    """warm sends each worker the once-a-process loads of the targets' tips (both laws' surrogate tables) ahead of any
    design, so a study's first designs do not wait for them."""
    from distributed import wait

    from magfab.inverse.study import warm
    from magfab.models.mechanics import fe_surrogate

    targets = parse_targets(SMALL.replace('tips = ["hemisphere"]', 'tips = ["flat"]') % 10)
    cluster.run(fe_surrogate._loaded.cache_clear)
    futures = warm(cluster, targets)
    wait(futures)
    assert len(futures) == len(cluster.scheduler_info()["workers"]) == 2
    assert all(n == 2 for n in cluster.run(lambda: fe_surrogate._loaded.cache_info().currsize).values())


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-1e6, 1e6), min_size=1, max_size=8), st.integers(0, 3))
def test_a_trials_constraints_read_directly_are_optunas(values, extra):
    """violation and constraint_row read the list tell stores straight from the trial's system attributes; they give
    what Optuna's own reading of it gives (and a row of more names than values is padded with 0 as before)."""
    import optuna

    from magfab.inverse.steps import CONSTRAINTS, constraint_row, violation

    t = optuna.trial.create_trial(value=0.0, system_attrs={CONSTRAINTS: values})
    names = [f"c{i}" for i in range(len(values) + extra)]
    c = t.constraints
    assert violation(t) == sum(max(float(v), 0.0) for v in c.values())
    assert constraint_row(t, names) == [float(c.get(str(i), 0.0)) for i in range(len(names))]
