"""The search: Optuna asks, Dask evaluates, the storage keeps every result as it arrives.

The loop runs in the calling process (ask-and-tell): it keeps two designs per worker in flight on the Dask cluster,
tells Optuna each result as it completes and asks for the next. The storage (:func:`storage_of`) is Optuna's journal
file in the study folder, or a database URL that several machines' runs share. Each result is committed when it
arrives, so an interrupted study resumes where it stopped: trials left running are marked failed ("interrupted")
and their points asked again. A design that fails is recorded with its reason and the study goes on.

Clusters: ``scheduler=None`` starts a local cluster of ``workers`` processes on this machine (one thread each: the
models are NumPy-bound); an address connects to an existing Dask scheduler unchanged (its workers need magfab).
"""

from __future__ import annotations

import contextlib
import itertools
import math
import os
import signal
import socket
import warnings
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..fork import blas_threads
from ..spec import Spec
from .evaluate import SURROGATE, evaluate, warm_up
from .journal import journal
from .space import POINT, Space, base_point, point_of
from .steps import CONSTRAINTS, asked_designs, design_key, explore, model_step, refine
from .targets import Sampler, Targets

# Imported lazily, inside the functions that use them, for speed: Dask, Optuna and SQLAlchemy take a
# noticeable time to import, and importing this module should not.

__all__ = ["Record", "tally", "StudyError", "client", "open_study", "run_study", "warm", "tell", "evaluate_all",
           "records"]

#: Designs kept in flight per worker: enough to hide the scheduler's round trip, few enough that the sampler sees
#: recent results.
IN_FLIGHT_PER_WORKER = 2
#: The user attribute a trial carries its evaluation in (one write per trial: each attribute is a storage round trip).
RESULT = "result"
#: What of an evaluation the storage keeps.
KEPT = ("state", "reason", "model", "metrics", "constraints", "errors")


class StudyError(InputError):
    """A study that cannot run as asked: another targets file's study in the same storage, an unreachable scheduler."""


@dataclass
class Record:
    """One evaluated design, as tables and plots take it."""

    number: int
    point: dict[str, Any]
    state: str  # ok, infeasible, failed
    reason: str
    model: str
    metrics: dict[str, Any]
    constraints: list[float] = field(default_factory=list)
    errors: list[str] = field(default_factory=list)

    @classmethod
    def of(cls, number: int, point: dict[str, Any], result: Mapping[str, Any]) -> Record:
        """A record from an evaluation's result (or what the store kept of it: :data:`KEPT`)."""
        return cls(number, point, result.get("state") or "failed", result.get("reason") or "",
                   result.get("model") or "", result.get("metrics") or {}, result.get("constraints") or [],
                   result.get("errors") or [])


def tally(records: Iterable[Record]) -> dict[str, int]:
    """How many records are feasible ("ok"), infeasible and failed."""
    states = [r.state for r in records]
    return {s: states.count(s) for s in ("ok", "infeasible", "failed")}


@contextlib.contextmanager
def client(scheduler: str | None, workers: int | None) -> Iterator[Any]:
    """A Dask client: on a new local cluster (``workers`` processes, default the cores) or on ``scheduler``. The local
    workers start with SIGINT blocked and set it to its default (:mod:`magfab.inverse.worker`): a Ctrl-C ends them
    quietly while magfab's own handler ends the run."""
    import dask
    from distributed import Client, LocalCluster

    with dask.config.set({"logging.distributed": "error"}):
        if scheduler:
            try:
                c = Client(scheduler, timeout="3s")
            except (OSError, ValueError, TypeError, OverflowError) as exc:
                raise StudyError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler there ({exc})") from None
            with c:
                yield c
            return
        # The scheduler's HTTP endpoint moves to a free port when 8787 is taken (another cluster): nothing to report.
        warnings.filterwarnings("ignore", message="Port 8787 is already in use", category=UserWarning)
        with dask.config.set({"distributed.worker.preload": ["magfab.inverse.worker"]}), _sigint_blocked():
            cluster = LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                                   dashboard_address=None, silence_logs=50)
        with cluster, Client(cluster) as c:
            yield c


@contextlib.contextmanager
def _sigint_blocked() -> Iterator[None]:
    """SIGINT blocked in this thread while the cluster starts: the event loop's thread and every worker process it
    starts (then or later) inherit the mask; a Ctrl-C meanwhile is delivered here when it ends."""
    try:
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def first_phase(targets: Targets) -> int:
    """Trials of the space-filling first phase (:meth:`Space.latin_hypercube`): a third of the study, 10 to 100, and
    at least two per (material, tip) pair; never more than the study."""
    pairs = len(targets.variables.material_keys()) * len(targets.variables.tips)
    return min(targets.study.trials, max(10, 2 * pairs, min(targets.study.trials // 3, 100)))


def _sampler(targets: Targets):
    """The study's sampler, seeded with study.seed. Its startup is the first phase (and the base point), so it
    models from the start; both samplers read each trial's constraints (the list :func:`tell` stores under
    :data:`~magfab.inverse.steps.CONSTRAINTS`), an infeasible design ranked by how far it misses."""
    import optuna

    s = targets.study
    if s.sampler is Sampler.NSGA2:
        population = max(8, min(50, s.trials // 10))
        return optuna.samplers.NSGAIISampler(population_size=population, seed=s.seed)
    return optuna.samplers.TPESampler(seed=s.seed, multivariate=True, constant_liar=True,
                                      n_startup_trials=first_phase(targets) + 1)


def storage_of(where: str | Path):
    """Optuna's storage at ``where``: a database URL (``sqlite:///...``, ``postgresql://...``: its RDB storage, for a
    server many machines share) or a file path (its journal storage, an append-only log: the default). The journal
    file is the default by measurement (bench/design.py): the search loop's own cost per trial was 22 ms on it against
    120 ms on an SQLite file (60 ms with WAL) and 7 ms in memory, on this 2-core machine in one run. The file is
    synced once per told trial (:mod:`magfab.inverse.journal`), not at every write."""
    if isinstance(where, str) and "://" in where:
        return where
    from optuna.storages import JournalStorage

    return JournalStorage(journal(str(where)))


def open_study(targets: Targets, where: str | Path):
    """The study at ``where`` (:func:`storage_of`; created, or loaded to resume). A study of the same name made from
    other targets is refused rather than mixed."""
    import optuna
    from sqlalchemy.exc import SQLAlchemyError

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    try:
        study = optuna.create_study(study_name=targets.name, storage=storage_of(where), directions=targets.directions(),
                                    sampler=_sampler(targets), load_if_exists=True)
    except (SQLAlchemyError, ImportError, OSError, ValueError) as exc:
        raise StudyError(f"study.storage {where}: cannot open it ({type(exc).__name__}: {str(exc).splitlines()[0]})") \
            from None
    storage = where
    made_from = study.user_attrs.get("targets_sha256")
    if made_from is None:
        study.set_user_attr("targets_sha256", targets.sha256())
    elif made_from != targets.sha256():
        raise StudyError(f"the study {targets.name!r} in {storage} was made from other targets; give another name "
                         "or --out folder to start a new one")
    return study


#: The study's user attribute saying its first phase is enqueued in the storage (by an earlier version of this module:
#: the first phase is now planned in memory from the seed, :func:`_plan`).
PLANNED = "first_phase_enqueued"
#: The user attribute naming the run (host:pid) that asked a trial.
RUNNER = "runner"


def _runner() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _dead(runner: str | None) -> bool:
    """True for a run on this host whose process is gone (a run elsewhere, sharing the storage, is left alone)."""
    host, _, pid = (runner or "").rpartition(":")
    if host != socket.gethostname() or not pid.isdigit():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return True
    except PermissionError:
        return False
    return False


def _recover(study) -> int:
    """Trials a killed run on this host left RUNNING: failed as "interrupted", their points asked again (runs on
    other machines sharing the storage keep theirs). Returns how many."""
    from optuna.trial import TrialState

    stale = [t for t in study.get_trials(deepcopy=False, states=(TrialState.RUNNING,))
             if _dead(t.user_attrs.get(RUNNER)) or RUNNER not in t.user_attrs]
    for t in stale:
        study._storage.set_trial_user_attr(t._trial_id, RESULT, {"state": "failed", "reason": "interrupted"})
        study._storage.set_trial_state_values(t._trial_id, state=TrialState.FAIL)
        if t.params:  # not skip_if_exists: the stale trial itself has these params, so it would always skip
            study.enqueue_trial(t.params)
    return len(stale)


def tell(study, trial, result: dict[str, Any], targets: Targets) -> None:
    """Record a result: its figures and reason as user attributes, its constraints (which Optuna's samplers read:
    feasible when all <= 0) and its objective values; a failed design as a failed trial."""
    from optuna.trial import TrialState

    kept = {k: result.get(k) for k in KEPT}
    values = [float(result["metrics"][o.value]) for o in targets.objectives] if result["state"] != "failed" else []
    if values and not all(math.isfinite(v) for v in values):
        kept.update(state="failed", reason="a figure is not finite")
    trial.set_user_attr(RESULT, kept)
    if kept["state"] == "failed":
        study.tell(trial, state=TrialState.FAIL)
    else:  # one write for all: a list, in constraint_names' order (trial.set_constraint: a read and a write for each)
        study._storage.set_trial_system_attr(trial._trial_id, CONSTRAINTS, [float(v) for v in result["constraints"]])
        study.tell(trial, values)
    _sync(study)


def _sync(study) -> None:
    """The study's journal file on the disk (:func:`~magfab.inverse.journal.journal`'s ``sync()``): each told result is
    durable before the next trial is asked. A database's storage commits each write itself."""
    sync = getattr(getattr(study._storage, "_backend", None), "sync", None)
    if sync is not None:
        sync()


def run_study(targets: Targets, base: Spec, storage: str | Path, dask_client,
              progress: Callable[[int, int], None] | None = None, study: Any = None) -> Any:
    """Run the study to ``targets.study.trials`` evaluated designs (counting those a previous run stored, not repeats:
    :data:`REPEAT`); ``study``: the one :func:`open_study` opened at ``storage`` already.

    A new study starts with :func:`_plan`'s trials (the base design, a space-filling first phase over every pair),
    then asks what :func:`_next_params` gives. Repeatable: results are told in ask order, whatever order the workers
    finish in, and the next trial is asked right after each is told: the same targets, seed and workers give the same
    trials."""
    from distributed import as_completed

    warming = warm(dask_client, targets)  # first: the workers load while this process plans
    study = study if study is not None else open_study(targets, storage)
    space = Space(targets, base)
    _recover(study)
    done = _counted(study)
    pending = _plan(study, space, targets, base)  # the first phase's trials not yet asked, then draws (_draw_next)
    total = targets.study.trials
    args = (base.model_dump_json(), targets.model_dump_json())
    workers = max(1, len(dask_client.scheduler_info().get("workers", {})) or 1)
    order: list[_Asked] = []  # in the order asked
    results: dict[Any, dict[str, Any]] = {}  # by future (or a repeat's told design's key)
    known = _told(study)  # each design told so far, by its key: what a repeat of it is told
    queue = as_completed()
    runner = _runner()
    n_first = first_phase(targets) + 1
    repeats = 0

    def submit() -> None:
        nonlocal repeats
        params = _next_params(study, space, targets, n_first, pending)
        trial, point = _ask(study, space, params, runner)
        key = design_key(point)
        earlier = next((a.source for a in order if a.key == key), key if key in known else None)
        if earlier is not None and repeats < REPEATS_PER_TRIAL * total:  # a design asked before: its result
            repeats += 1
            trial.set_user_attr(REPEAT, True)
            order.append(_Asked(trial, earlier, key, counts=False))
            pending.append(_draw_next(space, targets, trial.number))
            return
        fut = dask_client.submit(evaluate, point, *args, targets.study.models.value, f"{targets.name}-{trial.number}",
                                 pure=False)
        order.append(_Asked(trial, fut, key, counts=True))
        queue.add(fut)

    def flush() -> None:  # tell in ask order every trial whose result is in; ask again for each evaluation told
        nonlocal done
        while order and (order[0].source in results or order[0].source in known):
            asked = order.pop(0)
            result = results.get(asked.source) or known[asked.source]
            tell(study, asked.trial, result, targets)
            known[asked.key] = result
            if asked.counts:
                done += 1
                if progress:
                    progress(done, total)
            if not any(a.source == asked.source for a in order):
                results.pop(asked.source, None)
            fill()

    def fill() -> None:  # ask while trials are left to count and a worker's slot is free
        while done + sum(a.counts for a in order) < total and len(order) < IN_FLIGHT_PER_WORKER * workers:
            submit()

    # One BLAS thread for the loop: OpenBLAS's spare threads spin while they wait, and beside the workers on the same
    # cores they took as much CPU as the loop itself (the example targets, 2 workers: the main process's CPU 8.7 s
    # against 4.7 s, the search 6.7-7.2 s against 4.7-4.8 s). The workers run one already (Dask's nanny sets it).
    with blas_threads(1):
        fill()
        if progress:
            progress(done, total)
        flush()
        for fut in queue:
            results[fut] = fut.result()
            flush()
    del warming
    return study


def warm(dask_client, targets: Targets) -> list:
    """Each worker's once-a-process loads for the targets' designs (:func:`~magfab.inverse.evaluate.warm_up`), sent
    to every worker now, ahead of any design; the futures, which the caller keeps until its designs are in (a released
    future's task may be dropped). Each task's key names its tips and worker, so a second call while the first's
    futures are held (``magfab design`` warms before it prices the search, then :func:`run_study` warms) is given the
    same tasks, not new ones."""
    tips = [t.value for t in targets.variables.tips]
    return [dask_client.submit(warm_up, tips, workers=[w], key=f"magfab-warm-up-{'-'.join(tips)}-{w}")
            for w in dask_client.scheduler_info().get("workers", {})]


def _next_params(study, space: Space, targets: Targets, n_first: int,
                 pending: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The next trial's params (all, a pair's, or None for the sampler's draw): a trial waiting in the storage first
    (enqueued by :func:`_recover`: None, ``study.ask`` takes it), then ``pending`` (:func:`_plan`'s and
    :func:`_draw_next`'s), then past the first phase the first of :mod:`magfab.inverse.steps` with a trial to give:
    one in :data:`~magfab.inverse.steps.EXPLORE_EVERY` held to a pair (:func:`~magfab.inverse.steps.explore`), the
    model's proposal (:func:`~magfab.inverse.steps.model_step`), a step from the best designs
    (:func:`~magfab.inverse.steps.refine`)."""
    from optuna.trial import TrialState

    trials = study.get_trials(deepcopy=False)  # once per ask: every step reads the same list
    if any(t.state is TrialState.WAITING for t in trials):
        return None
    if pending:
        return pending.pop(0)
    if len(trials) < n_first:
        return None
    steps = (explore, model_step, refine)
    return next((p for p in (step(space, targets, n_first, trials) for step in steps) if p is not None), None)


def _counted(study) -> int:
    """The study's told trials that count against study.trials: all but the repeats (:data:`REPEAT`)."""
    from optuna.trial import TrialState

    told = study.get_trials(deepcopy=False, states=(TrialState.COMPLETE, TrialState.FAIL))
    return sum(not t.user_attrs.get(REPEAT) for t in told)


def _plan(study, space: Space, targets: Targets, base: Spec) -> list[dict[str, Any]]:
    """A study's first trials not yet asked, in order: the base spec's design (when it is a point of the space), then
    the first phase's Latin hypercube (drawn from the seed, so a resumed study plans the same); none for a study
    whose first phase an earlier version enqueued in the storage (:data:`PLANNED`)."""
    from optuna.trial import TrialState

    if study.user_attrs.get(PLANNED):
        return []
    start = base_point(base, targets.variables)
    plan = ([space.params(start)] if start is not None else []) + space.latin_hypercube(first_phase(targets),
                                                                                        targets.study.seed)
    asked = asked_designs(study.get_trials(deepcopy=False))
    asked |= {design_key(space.point(t.system_attrs["fixed_params"])) for t in study.get_trials(
        deepcopy=False, states=(TrialState.WAITING,)) if set(space.param_names()) <= t.system_attrs.get(
            "fixed_params", {}).keys()}
    return [p for p in plan if design_key(space.point(p)) not in asked]


def _draw_next(space: Space, targets: Targets, number: int) -> dict[str, Any]:
    """After trial ``number`` asked a repeat, the params of a uniform draw, seeded with the study's seed and that
    number (the sampler, converged on a small space, would ask the same design again): what the study asks next."""
    draw = int(np.random.default_rng([targets.study.seed, number]).integers(2**31))
    return space.latin_hypercube(1, draw)[0]


def _ask(study, space: Space, params: dict[str, Any] | None, runner: str) -> tuple[Any, dict[str, Any]]:
    """A new trial and its mm point: with every param given, made in one storage write, running, its params and
    point (:data:`POINT`) in it (what ``study.ask`` and a suggest a param would take a dozen writes for, each a lock and
    an append to the journal file); with some (a pair held, the sampler drawing the rest: :func:`explore`) or none,
    asked of the sampler, the trials waiting in the storage first."""
    from optuna.trial import FrozenTrial, Trial, TrialState

    names = space.param_names()
    if params is None or not set(names) <= params.keys():
        if params is not None:
            study.enqueue_trial(params)
        trial = study.ask()
        trial.set_user_attr(RUNNER, runner)
        return trial, space.suggest(trial)
    point = space.point(params)
    distributions = space.distributions()
    template = FrozenTrial(number=0, state=TrialState.RUNNING, value=None, datetime_start=datetime.now(UTC),
                           datetime_complete=None, params={k: params[k] for k in names}, distributions=distributions,
                           user_attrs={RUNNER: runner, POINT: point}, system_attrs={}, intermediate_values={},
                           trial_id=0)
    return Trial(study, study._storage.create_new_trial(study._study_id, template_trial=template)), point


#: The user attribute marking a trial that asked a design the study had already asked: told that design's result,
#: and neither counted against study.trials nor listed by :func:`records` (TPE's draws can repeat a design, most of
#: all over listed values); the next trial is then a uniform draw.
REPEAT = "repeat"
#: Repeats a study may ask per trial of study.trials before a repeat counts as a trial: a bound on the asks (a few tens
#: of milliseconds each) when the space holds fewer designs than the trials asked.
REPEATS_PER_TRIAL = 4


@dataclass
class _Asked:
    """A trial asked and not yet told: ``source`` is its evaluation's future, or for a repeat the future or design key
    its result comes from; ``counts``: against study.trials."""

    trial: Any
    source: Any
    key: tuple
    counts: bool


def _told(study) -> dict[tuple, dict[str, Any]]:
    """The result each design the study has told carries (a resumed study's too), by the design's key."""
    from optuna.trial import TrialState

    return {design_key(t.user_attrs[POINT]): t.user_attrs[RESULT] for t in study.get_trials(
        deepcopy=False, states=(TrialState.COMPLETE, TrialState.FAIL))
        if POINT in t.user_attrs and RESULT in t.user_attrs and t.user_attrs[RESULT].get("reason") != "interrupted"}


def records(study) -> list[Record]:
    """Every finished trial as a :class:`Record`, in trial order."""
    from optuna.trial import TrialState

    out = []
    for t in study.get_trials(deepcopy=False, states=(TrialState.COMPLETE, TrialState.FAIL)):
        if (POINT not in t.user_attrs and "magnet" not in t.params) or t.user_attrs.get(REPEAT):
            continue  # asked, never given a point (cut short), or a repeat of a design listed already
        point = t.user_attrs.get(POINT) or point_of(t.params)  # a study stored before the fractions: mm params
        out.append(Record.of(t.number, point,
                             t.user_attrs.get(RESULT) or {"state": "failed", "reason": "no result stored"}))
    return out


#: Most cheap designs one task of :func:`evaluate_all` evaluates: a cheap design takes a few tens of milliseconds, about
#: what the scheduler and this process spend on a task on a small machine, so one design per task left the workers
#: waiting for a third of the time (bench/design.py).
CHUNK = 8


def _evaluate_chunk(points: list[dict[str, Any]], base_json: str, targets_json: str, fidelity: str,
                    names: list[str]) -> list[dict[str, Any]]:
    """:func:`evaluate` of each point in turn: one task's work."""
    return [evaluate(p, base_json, targets_json, fidelity, n) for p, n in zip(points, names)]


def evaluate_all(points: Iterable[dict[str, Any]], targets: Targets, base: Spec, dask_client, fidelity: str,
                 progress: Callable[[int, int], None] | None = None, prefix: str = "") -> list[Record]:
    """Evaluate ``points`` on the cluster (a sweep, or the re-verification of the front), in their order: the cheap
    models' designs up to :data:`CHUNK` to a task while that leaves every worker eight tasks or more, the full
    chain's (a second or more each) one to a task."""
    from distributed import as_completed

    points = list(points)
    args = (base.model_dump_json(), targets.model_dump_json())
    workers = max(1, len(dask_client.scheduler_info().get("workers", {})) or 1)
    size = max(1, min(CHUNK, len(points) // (8 * workers))) if fidelity == SURROGATE else 1
    chunks = iter(range(0, len(points), size))
    futures: dict[Any, int] = {}
    queue = as_completed()

    def submit() -> None:  # a bounded number in flight, as the search keeps: the cluster holds no whole plan
        for i in itertools.islice(chunks, 1):
            part = points[i:i + size]
            names = [f"{targets.name}-{prefix}{k}" for k in range(i, i + len(part))]
            fut = dask_client.submit(_evaluate_chunk, part, *args, fidelity, names, pure=False)
            futures[fut] = i
            queue.add(fut)

    if progress:  # the phase's start: its time and count are taken from here
        progress(0, len(points))
    for _ in range(IN_FLIGHT_PER_WORKER * workers):
        submit()
    results: dict[int, dict[str, Any]] = {}
    for fut in queue:
        i = futures.pop(fut)
        results.update(zip(itertools.count(i), fut.result()))
        submit()
        if progress:
            progress(len(results), len(points))
    return [Record.of(i, points[i], r) for i, r in sorted(results.items())]
