"""What a study may ask of this machine, checked before any of its work (before a grid is listed, a cluster started or
a folder made): the designs a sweep or search evaluates, and the local cluster's worker processes.

=====================  ==============================================  ==============================================
limit                  allowed                                         why
=====================  ==============================================  ==============================================
``--workers``          at most the cores (``os.cpu_count()``) and       one thread per worker and NumPy-bound models:
                       what memory holds: MB_PER_WORKER each beside     more workers than cores only share them; each
                       STUDY_FIXED_MB within :func:`memory_mb`          worker process is MB_PER_WORKER at its peak
``--grid LEVELS``      the grid's designs (counted, never listed) at   ``[study] trials`` is the most designs a
``--lhs SAMPLES``      most ``[study] trials`` and what memory holds   study evaluates; the sweep keeps each design's
``[study] trials``     at most what memory holds (MB_PER_DESIGN each)  record, the search each trial, in memory
=====================  ==============================================  ==============================================

A study's time is the user's to choose (its designs, its workers), so it is estimated, not limited: before any
work, :func:`study_cost` prices a sample of its designs as they will be evaluated (the surrogate chain at
SURROGATE_S each; a design outside the surrogate's region, or any with ``--models fe``, at the FE estimate of
:mod:`magfab.limits` plus FE_CHAIN_S; a search's verified designs also at their build's estimate), and the CLI
prints the total over the workers before it starts.

:func:`memory_mb` is the project's budget (:data:`magfab.limits.BUDGET_MB`), or less on a machine with less memory.
A refusal is one :class:`~magfab.inverse.study.StudyError` naming the option or key, its value and what is allowed.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

from ..check import preflight
from ..design import derive
from ..errors import InputError
from ..limits import BUDGET_MB, estimate
from .evaluate import FE, _elastomer_model, bench_point
from .space import NUMERIC, Space, candidate_spec, choices
from .study import StudyError
from .targets import Targets, Variables

__all__ = ["MB_PER_WORKER", "MB_PER_DESIGN", "STUDY_FIXED_MB", "memory_mb", "cores", "most_workers", "most_designs",
           "grid_size", "check_scheduler", "check_workers", "check_plan", "check_trials", "PRICED", "StudyCost",
           "search_cost", "search_sample", "study_cost"]

#: A local cluster's worker process (one thread) at its peak: measured 137 MB idle and 224 MB after evaluating
#: designs with the surrogate (the models and the surrogate's table loaded); the full chain's FE adds up to ~200 MB
#: (limits.MB_PER_FE_TRIANGLE over a design's finest mesh). 400 MB with a margin.
MB_PER_WORKER = 400.0
#: The calling process: magfab, Optuna and the Dask client and scheduler (a local cluster's scheduler runs in it):
#: measured 138 MB after a sweep; 500 MB with a margin for the tables written at the end.
STUDY_FIXED_MB = 500.0
#: One design kept by the calling process: its point, record and table row (a sweep: 5.3 KB per design measured over
#: 50,000 designs, CSV and Parquet written), or an Optuna trial with its stored result (the search). 20 KB with a
#: margin for Optuna's trial objects.
MB_PER_DESIGN = 0.02


def memory_mb() -> float:
    """The memory a study may take, MB: the project's budget, or less on a machine that has less."""
    try:
        physical = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") / 2**20
    except (ValueError, OSError, AttributeError):
        physical = math.inf
    return min(BUDGET_MB, physical)


def cores() -> int:
    return os.cpu_count() or 1


def most_workers() -> int:
    """The most local worker processes: the cores, and what memory holds beside the calling process."""
    return max(1, min(cores(), int((memory_mb() - STUDY_FIXED_MB) // MB_PER_WORKER)))


def most_designs(workers: int) -> int:
    """The most designs one run may keep (a sweep's points, a search's trials) beside ``workers`` workers."""
    return max(1, int((memory_mb() - STUDY_FIXED_MB - workers * MB_PER_WORKER) // MB_PER_DESIGN))


def check_workers(workers: int | None, scheduler: str | None) -> int:
    """The local cluster's worker processes (``--workers``, default the most this machine holds); a count past
    :func:`most_workers` is refused. With ``scheduler`` (an existing cluster) no local worker starts: 0."""
    if scheduler:
        return 0
    most = most_workers()
    if workers is None:
        return most
    if workers > most:
        raise _error(f"--workers {workers}: more than this machine can run: at most {most} (one per core, "
                     f"os.cpu_count() = {cores()}, each up to {MB_PER_WORKER:g} MB within {memory_mb():.0f} MB)")
    return workers


def check_scheduler(address: str) -> None:
    """A ``--scheduler`` address Dask can dial (``[PROTOCOL://]HOST:PORT``, the port 1-65535), else one line."""
    from distributed.comm.addressing import parse_address, parse_host_port  # lazy: Dask is slow to import

    try:
        _, port = parse_host_port(parse_address(address)[1])
    except (ValueError, TypeError) as exc:
        port, why = None, str(exc)
    if port is None or not 0 < int(port) < 65536:
        why = why if port is None else f"port {port} is not 1-65535"
        shown = address if address.isprintable() else repr(address)  # a newline in it must not split the line
        raise _error(f"--scheduler {shown}: not a Dask scheduler's address ({why!r}); give PROTOCOL://HOST:PORT, "
                     "e.g. tcp://127.0.0.1:8786")


def grid_size(variables: Variables, levels: int) -> int:
    """The designs of :func:`magfab.inverse.space.grid` at ``levels``, counted without listing them."""
    axes = [len(c) for c in choices(variables).values()]
    axes += [len(c) if isinstance(c, list) else levels for c in (getattr(variables, k) for k in NUMERIC)]
    return math.prod(axes)


def check_plan(targets: Targets, levels: int | None, samples: int | None, workers: int) -> int:
    """The designs a sweep evaluates (``--grid`` or ``--lhs``), refused past ``[study] trials`` or what memory holds
    beside ``workers`` workers. Returns the count."""
    option, value = ("--grid", levels) if levels else ("--lhs", samples or 100)
    count = grid_size(targets.variables, levels) if levels else samples or 100
    trials = targets.study.trials
    what = f"{count:,} designs" if levels else "designs"
    if count > trials:
        raise _error(f"{option} {value}: {what}, more than study.trials = {trials:,} (at most that many; raise "
                     f"study.trials or lower {option})")
    most = most_designs(workers)
    if count > most:
        raise _error(f"{option} {value}: {what}, more than memory holds: at most {most:,} beside {workers} "
                     f"workers ({MB_PER_DESIGN * 1000:g} KB each within {memory_mb():.0f} MB)")
    return count


def check_trials(targets: Targets, workers: int) -> None:
    """``[study] trials`` of a search, refused past what memory holds beside ``workers`` workers."""
    most = most_designs(workers)
    if targets.study.trials > most:
        raise _error(f"study.trials = {targets.study.trials:,}: more than memory holds: at most {most:,} beside "
                     f"{workers} workers ({MB_PER_DESIGN * 1000:g} KB each within {memory_mb():.0f} MB)")


# ---- a study's time -----------------------------------------------------------------------------------------

#: One design by the surrogate chain on one worker (the exact field, the elastomer surrogate, the design checks):
#: bench/study_time.py's sweeps of 120 designs on 2 workers took 10.4 s (the example targets' variables) and 14 s (the
#: default ones, 4 of them by the FE), about 0.1 s a design after the cluster's start; 1.5x that.
SURROGATE_S = 0.15
#: One design by the full chain beyond its FE estimate (:mod:`magfab.limits`: the field model, its table for a new
#: magnet, the design checks), on one worker: 7 designs evaluated one by one took 2.7-11.4 s against FE estimates of
#: 5.5-6.0 s (in all 1.05x); with this added, about 1.4x their time. (3.0 s left bench/adversarial.py's sweep of 17
#: designs by the full chain at 1.05x its estimate on the machine under a load of 2-3.)
FE_CHAIN_S = 4.0
#: The search's own loop per trial in the calling process: Optuna's ask and tell, the journal's writes and the model
#: step (magfab.inverse.propose, its candidates mapped to mm). Three bench sets x 10 seeds of 300 trials on 2 workers
#: took 551 s, 61 ms a trial, bound by the loop (the designs' share there is about 15 ms a trial); 1.4x that.
LOOP_S = 0.085
#: A local cluster's start and the tables written at the end (a sweep of 30 designs by the surrogate: 8.6 s in all).
STUDY_START_S = 8.0
#: The designs priced one by one; a larger study is priced by this many spread over its list.
PRICED = 64


@dataclass(frozen=True)
class StudyCost:
    """A study's estimated time: its designs and how many of them the FE evaluates (estimated from a sample), the
    seconds of one worker they take, and a search's verified designs: their full chain on the workers, then their
    builds one after another in the calling process."""

    designs: int
    by_fe: int
    design_s: float  # all the designs, one worker's seconds
    verify_s: float  # the verified designs' full chain, one worker's seconds
    build_s: float  # their builds, in the calling process
    workers: int  # 0: an existing cluster (its workers unknown)
    full_chain: bool = False  # every design by the full chain (``--models fe``)
    longest_s: float = 0.0  # the costliest design priced (one worker's seconds)
    loop_s: float = 0.0  # a search's own loop in the calling process (asks, tells, the model step): LOOP_S a trial

    @property
    def seconds(self) -> float:
        """The start, the designs shared by the workers as they come free (at most their sum over the workers plus
        (1 - 1 / workers) of the longest one, Graham's bound for a list schedule) or, when it is longer, the search's
        own loop, which asks each design after the one before it is told, and the builds."""
        w = max(self.workers, 1)
        shared = (self.design_s + self.verify_s) / w + (1.0 - 1.0 / w) * self.longest_s
        return STUDY_START_S + max(shared, self.loop_s) + self.build_s

    def line(self) -> str:
        """One line for the user before the work starts."""
        where = f"on {self.workers} worker{'s' * (self.workers != 1)}" if self.workers else \
            "with one worker (the cluster's workers divide the designs' share)"
        refused = self.designs - self.by_fe
        fe = (", by the full chain (FE)" + (f", about {refused:,} of them refused at once" if refused else "")) \
            if self.full_chain else \
            f", about {self.by_fe:,} of them by the FE (outside the surrogate's region or law)" if self.by_fe else ""
        then = ", then the verified designs' full chain and builds" if self.build_s else ""
        return f"estimated {_duration(self.seconds)} {where}: {self.designs:,} designs{fe}{then}"


def _duration(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min" if seconds < 7200 else \
        f"{seconds / 3600:.1f} h"


def _priced(point: dict[str, Any], base: Any, targets: Targets, fidelity: str) -> tuple[float, bool, float, float]:
    """One design as the study evaluates it: (one worker's seconds, whether by the FE, its full chain's seconds, its
    build's estimated seconds); a point the spec refuses at once costs SURROGATE_S and no FE or build."""
    try:
        if fidelity == FE:
            point = bench_point(point, base, targets)
        design = preflight(derive(candidate_spec(point, base, targets, "candidate")))
    except InputError:
        return SURROGATE_S, False, 0.0, 0.0
    cost = estimate(design)
    full = FE_CHAIN_S + cost.parts_s["fe"]
    fe = fidelity == FE or _elastomer_model(design)[0] is None  # evaluate's own choice of model
    return (full if fe else SURROGATE_S), fe, full, cost.seconds


def search_sample(targets: Targets, base: Any) -> list[dict[str, Any]]:
    """The points a search's cost is priced on: :data:`PRICED` of a Latin hypercube in the search's own coordinates
    (every one buildable, as the search's are)."""
    space = Space(targets, base)
    return [space.point(p) for p in space.latin_hypercube(PRICED, targets.study.seed)]


def search_cost(targets: Targets, base: Any, workers: int) -> StudyCost:
    """The time of ``magfab design`` on ``targets``: its trials priced on :func:`search_sample`, then its verified
    designs (the full chain, unless the search ran it already, and their builds)."""
    fidelity = targets.study.models.value
    cost = study_cost(search_sample(targets, base), targets.study.trials, base, targets, fidelity, workers,
                      targets.study.verify, fidelity != FE)
    return replace(cost, loop_s=targets.study.trials * LOOP_S)


def study_cost(points: Sequence[dict[str, Any]], count: int, base: Any, targets: Targets, fidelity: str,
               workers: int, verify: int = 0, verify_chain: bool = True) -> StudyCost:
    """The time of a study of ``count`` designs like ``points`` (its list, or a sample of its space; up to
    :data:`PRICED` of them spread over it are priced) on ``workers`` workers (0: an existing cluster), with
    ``verify`` designs then built, after the full chain has verified them (``verify_chain``: a search by the
    surrogate; one by the FE has verified them already)."""
    step = max(1, len(points) // PRICED)
    priced = [_priced(p, base, targets, fidelity) for p in points[::step][:PRICED]]
    if not priced:
        return StudyCost(count, 0, 0.0, 0.0, 0.0, workers)
    n = len(priced)
    buildable = [p for p in priced if p[3] > 0.0]
    full = sum(p[2] for p in buildable) / len(buildable) if buildable else 0.0
    build = sum(p[3] for p in buildable) / len(buildable) if buildable else 0.0
    return StudyCost(count, round(count * sum(p[1] for p in priced) / n), count * sum(p[0] for p in priced) / n,
                     verify * full * verify_chain, verify * build, workers, fidelity == FE,
                     max([p[0] for p in priced] + [full * verify_chain * (verify > 0)]))


def _error(message: str) -> StudyError:
    return StudyError(message)
