"""``magfab design`` and ``magfab sweep``: from TARGETS.toml to a study folder.

``design``: the search (:mod:`.study`) with the cheap models, then the designs near the front re-verified by the
full chain (FE), each of them that meets the requirements built as ``magfab build`` builds it (:mod:`.verify`: a
refused build fails the verification), the front of the verified designs, and the files::

    DIR/study.log                 the Optuna storage (its journal file; resumed by running the command again)
    DIR/trials.csv, .parquet      every design the search evaluated, with its state and reason
    DIR/pareto.csv, .parquet      the verified designs: full-chain figures, each requirement's distance against its
                                  margin, the spec's path, the cheap models' figures beside them (none verified: the
                                  search's nearest designs, marked verified false)
    DIR/pareto.svg, .png          the front
    DIR/index.html, README.md     the page: targets, front, the chosen design and how to build it
    DIR/designs/NAME.toml         each verified design as a spec `magfab build` accepts (on the printer's step)
    DIR/designs/NAME.json         its full-chain figures
    DIR/chosen.toml               the chosen design's spec (the best verified one on the first objective)
    DIR/builds/NAME/              each verified design's build (what `magfab build` writes)

``sweep``: every design of a grid or a Latin hypercube of the same variables, in ``DIR/sweep.csv`` (.parquet).
"""

from __future__ import annotations

import contextlib
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from .budget import StudyCost, check_plan, check_scheduler, check_trials, check_workers, search_cost, study_cost
from .evaluate import FE, SURROGATE, bench_point
from .page import write_outputs
from .pareto import front_mask, pick_for_verification, values_of
from .result import DesignResult
from .space import grid, latin_hypercube
from .study import KEPT, Record, client, design_key, evaluate_all, open_study, records, run_study, warm
from .tables import rows, write_table
from .targets import Models, Targets, load_targets
from .verify import built

__all__ = ["design", "sweep", "default_folder"]

Progress = Callable[[str, int, int], None]
Estimate = Callable[[StudyCost], None]


def default_folder(targets: Targets) -> Path:
    return Path("design") / targets.name


def _storage(targets: Targets, folder: Path) -> str | Path:
    return targets.study.storage or folder / "study.log"


def _check_folder(folder: Path) -> None:
    if folder.exists() and not folder.is_dir():
        raise InputError(f"--out {folder}: exists and is not a folder")
    if folder.is_dir() and any(folder.iterdir()) and not (folder / "study.log").exists() \
            and not (folder / "sweep.csv").exists():
        raise InputError(f"--out {folder}: a folder that is not a magfab study (no study.log or sweep.csv); "
                         "give an empty or new folder")


def _cluster(scheduler: str | None, workers: int | None) -> int | None:
    """The local cluster's workers (None with ``scheduler``), refused before any work past what the machine holds
    (:mod:`.budget`), as a malformed ``scheduler`` is."""
    if scheduler:
        check_scheduler(scheduler)
    return check_workers(workers, scheduler) or None


@contextlib.contextmanager
def _made(folder: Path) -> Iterator[None]:
    """Make ``folder`` (and its missing parents); if the block is refused (an InputError), remove what was made:
    a refusal leaves nothing behind."""
    new = next((p for p in reversed((folder, *folder.parents)) if not p.exists()), None)
    folder.mkdir(parents=True, exist_ok=True)
    try:
        yield
    except InputError:
        if new is not None:
            shutil.rmtree(new, ignore_errors=True)
        raise


def design(targets_path: Path, out: Path | None = None, scheduler: str | None = None, workers: int | None = None,
           progress: Progress | None = None, estimate: Estimate | None = None) -> DesignResult:
    """Run ``magfab design`` (module doc); ``estimate`` is given the study's estimated time before the work."""
    targets, base = load_targets(targets_path)
    workers = _cluster(scheduler, workers)
    check_trials(targets, workers or 0)
    folder = out or default_folder(targets)
    _check_folder(folder)
    say = progress or (lambda *_: None)
    with client(scheduler, workers) as c:
        warming = warm(c, targets)  # the workers load while this process prices the search
        if estimate:  # the search's points are its own: priced on a sample of the space it searches
            estimate(search_cost(targets, base, workers or 0))
        with _made(folder):  # once the cluster is there (a bad --scheduler writes nothing); a refused storage: none
            opened = open_study(targets, _storage(targets, folder))
        study = run_study(targets, base, _storage(targets, folder), c, lambda n, t: say("search", n, t), opened)
        trials = records(study)
        picks = _near_front(trials, targets, lambda r: _written(r, base, targets))
        screened = [trials[i] for i in picks]
        if targets.study.models.value == FE:  # the search ran the full chain already
            verified = screened
        else:
            verified = _verified(study, screened, targets, base, c, lambda n, t: say("verify (full chain)", n, t))
        del warming
    names = [f"{targets.name}-{r.number}" for r in screened]
    # each design that meets the requirements is built (CAD, board, bundle): a refused build is a failed verification
    verified = built(study, verified, names, targets, base, folder, lambda n, t: say("verify (build)", n, t))
    result = DesignResult(targets, folder, trials, verified, screened, [], None, names)
    _front(result)
    result.files = write_outputs(result, base)
    return result


def _verified(study, screened: list[Record], targets: Targets, base, dask_client, progress) -> list[Record]:
    """The full chain's results for ``screened``: those a previous run stored in the study (its user attributes
    "verified:N"), the rest evaluated now on the cluster and stored."""
    kept = dict(study.user_attrs)
    todo = [r for r in screened if f"verified:{r.number}" not in kept]
    for r, v in zip(todo, evaluate_all([r.point for r in todo], targets, base, dask_client, FE, progress, prefix="v")):
        kept[f"verified:{r.number}"] = stored = {k: getattr(v, k) for k in KEPT}
        study.set_user_attr(f"verified:{r.number}", stored)
    return [Record.of(r.number, r.point, kept[f"verified:{r.number}"]) for r in screened]


#: A design the cheap chain finds short of a requirement by at most this (relative) is "near-feasible": twice the
#: surrogate's 90th-percentile held-out force error, so the full chain may well find it meets the requirement.
NEAR_MARGIN = 0.06
#: The share of the verification budget kept for near-feasible designs (when there are any).
NEAR_SHARE = 1.0 / 3.0


def _near_front(trials: list[Record], targets: Targets, design: Callable[[Record], Any] | None = None) -> list[int]:
    """Indices of up to ``study.verify`` trials for the full chain: the cheap chain's feasible front (spread along
    it, then the next ranks), and, with a third of the budget, the front of the near-feasible designs, those short of
    a requirement by at most :data:`NEAR_MARGIN` (the best designs often sit on a requirement's boundary, where the
    cheap chain's error decides which side they fall). ``design``: a trial's design as it is written and verified
    (default: the trial itself); two trials that write the same design (the search's points differ by less than the
    printer's step) take one place."""
    ok = [i for i, r in enumerate(trials) if r.state == "ok"]
    near = [i for i, r in enumerate(trials) if _near_feasible(r)]
    k = targets.study.verify
    k_near = min(len(near), round(k * NEAR_SHARE)) if ok else min(len(near), k)
    known: dict[int, Any] = {}

    def written(i: int) -> Any:
        if i not in known:
            known[i] = design(trials[i]) if design else i
        return known[i]

    taken: set = set()
    return (_picks(trials, ok, targets, k - k_near, written, taken)
            + _picks(trials, near, targets, k_near, written, taken))


def _written(r: Record, base, targets: Targets) -> tuple:
    """The design a trial is written and verified as: the :func:`design_key` of its point on the printer's step
    (:func:`bench_point`), or of the point as searched where the step cannot be taken (verify.built reports such a
    design)."""
    try:
        return design_key(bench_point(r.point, base, targets))
    except InputError:
        return design_key(r.point)


def _near_feasible(r: Record) -> bool:
    """Infeasible only by requirement margins within NEAR_MARGIN (the last constraint counts error findings; the
    one a resolution requirement adds, resolution-short, is that requirement again)."""
    if r.state != "infeasible" or not r.constraints:
        return False
    other_errors = [e for e in r.errors if not e.startswith("resolution-short")]
    return not other_errors and all(c <= NEAR_MARGIN for c in r.constraints[:-1])


def _picks(trials: list[Record], idx: list[int], targets: Targets, k: int, written: Callable[[int], Any],
           taken: set) -> list[int]:
    """Up to ``k`` of ``idx`` spread along their front (:func:`pick_for_verification`), each writing a design not in
    ``taken`` (then added to it): a pick that writes a design already taken is dropped and the picks made again
    without it."""
    idx = list(idx)
    while idx and k > 0:
        values = values_of([trials[i] for i in idx], [o.value for o in targets.objectives])
        picks = [idx[j] for j in pick_for_verification(values, targets.directions(), k)]
        seen, dropped = set(taken), []
        for i in picks:
            if written(i) in seen:
                dropped.append(i)
            seen.add(written(i))
        if not dropped:
            taken |= seen
            return picks
        idx = [i for i in idx if i not in dropped]
    return []


def _front(result: DesignResult) -> None:
    """The front of the verified designs that meet every requirement by the full chain, and the chosen one: the best
    on the first objective (ties: the next)."""
    ok = [i for i, r in enumerate(result.verified) if r.state == "ok"]
    if not ok:
        return
    values = result.objective_values([result.verified[i] for i in ok])
    mask = front_mask(values, result.targets.directions())
    result.front = [ok[i] for i in np.nonzero(mask)[0]]
    keys = [tuple(v) for v in (values[mask] * np.where(np.array(result.targets.directions()) == "minimize", 1, -1))]
    result.chosen = result.front[min(range(len(keys)), key=lambda i: keys[i])]


def sweep(targets_path: Path, out: Path | None = None, scheduler: str | None = None, workers: int | None = None,
          levels: int | None = None, samples: int | None = None, fidelity: str = SURROGATE,
          progress: Progress | None = None, estimate: Estimate | None = None) -> tuple[Path, list[Record]]:
    """Evaluate every design of a grid (``levels`` per numeric range) or a Latin hypercube (``samples``);
    ``estimate`` is given the sweep's estimated time before the work."""
    targets, base = load_targets(targets_path)
    if fidelity not in {m.value for m in Models}:
        raise InputError(f"--models {fidelity}: must be one of " + ", ".join(m.value for m in Models))
    workers = _cluster(scheduler, workers)
    check_plan(targets, levels, samples, workers or 0)  # counted before any is listed
    points = list(grid(targets.variables, levels)) if levels else latin_hypercube(targets.variables, samples or 100,
                                                                                    targets.study.seed)
    folder = out or default_folder(targets)
    _check_folder(folder)
    if estimate:
        estimate(study_cost(points, len(points), base, targets, fidelity, workers or 0))
    say = progress or (lambda *_: None)
    with client(scheduler, workers) as c:
        recs = evaluate_all(points, targets, base, c, fidelity, lambda n, t: say("sweep", n, t), prefix="s")
    write_table(folder, "sweep", rows(recs))
    return folder, recs
