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

:func:`memory_mb` is the project's budget (:data:`magfab.limits.BUDGET_MB`), or less on a machine with less memory.
A refusal is one :class:`~magfab.inverse.study.StudyError` naming the option or key, its value and what is allowed.
"""

from __future__ import annotations

import math
import os

from ..limits import BUDGET_MB
from .space import NUMERIC, choices
from .study import StudyError
from .targets import Targets, Variables

__all__ = ["MB_PER_WORKER", "MB_PER_DESIGN", "STUDY_FIXED_MB", "memory_mb", "cores", "most_workers", "most_designs",
           "grid_size", "check_scheduler", "check_workers", "check_plan", "check_trials"]

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


def _error(message: str) -> StudyError:
    return StudyError(message)
