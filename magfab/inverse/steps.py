"""The search's steps after its first phase (:func:`magfab.inverse.study.run_study`): what each trial asks.

Before each ask, the first of these with a trial to give gives it: :func:`explore` (one trial in
:data:`EXPLORE_EVERY` held to a (material, tip) pair), :func:`model_step` (the model's proposal,
:mod:`magfab.inverse.propose`), :func:`refine` (a step from the study's best designs); with none, the sampler draws.
Each takes the study's trials as asked and returns a trial's params (all of them, or a pair's for the sampler to draw
the rest), or None. Each is seeded with the study's seed and the trial's number, so a study repeats.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .evaluate import constraint_names
from .pareto import front_mask
from .propose import propose
from .space import FRACTIONS, MAGNET_FRACTION, POINT, Space
from .targets import Targets

# Optuna's trial states are imported lazily, inside the functions that use them: importing Optuna takes a noticeable
# time, and importing this module should not.

__all__ = ["CONSTRAINTS", "explore", "model_step", "refine", "pair_to_search", "constraint_row", "violation", "elite",
           "asked_designs", "design_key", "EXPLORE_EVERY", "OPTIMISM", "OPTIMISTIC_EVERY", "PAIR_TRIES"]


#: The system attribute Optuna's constrained samplers read a trial's constraints from, as a list (each feasible when
#: <= 0; optuna.study._constrained_optimization), here in
#: :func:`~magfab.inverse.evaluate.constraint_names`' order (:func:`~magfab.inverse.study.tell` stores it).
CONSTRAINTS = "constraints"
#: Of the trials after the first phase, one in this many has its (material, tip) fixed to the pair the study has
#: tried least (the sampler draws the rest of it): the categories stay explored however the models narrow.
EXPLORE_EVERY = 4
#: A refinement's step over the unit fractions (the magnet's and each numeric variable's), when the model step
#: (:mod:`magfab.inverse.propose`) has no proposal: this much right after the first phase, narrowing to a fifth of it
#: by the study's last trial.
REFINE_SIGMA = 0.2
#: Steps drawn for one refinement before it gives up on finding a design the study has not evaluated (a space of
#: listed values or few magnets has few neighbours); the sampler then draws that trial.
REFINE_DRAWS = 8
#: Trials past its share of the first phase that a (material, tip) pair with no feasible design yet may take from
#: the exploration trials (:func:`pair_to_search`): enough for the model to step from its near misses into a thin
#: feasible region, few enough that a pair with none leaves the rest of the study its trials.
PAIR_TRIES = 8
#: The last entry of a pair-held proposal's seed, so that its draws are not the model step's of the same trial.
PAIR_SEED = 7
#: Of the model steps (not held to a pair), those asked at a trial number divisible by this are optimistic: their
#: proposal's local steps may miss a constraint by :data:`OPTIMISM` times their distance from the designs evaluated
#: (:func:`magfab.inverse.propose.propose`); the others by nothing.
OPTIMISTIC_EVERY = 2
#: The optimistic model steps' allowance per unit of distance in the model's coordinates (the constraints are
#: relative: 2 lets a step 0.1 from every design evaluated miss a requirement by 20 % of it). Chosen on
#: bench/design_search.py's stiff pad, 300 trials against a 3,000-design sweep (figures: propose's module doc): 2 at
#: every second model step over seeds 0-19; 4 at every third failed five seeds of twenty, 4 at every second each of
#: the four seeds it was tried on.
OPTIMISM = 2.0


def explore(space: Space, targets: Targets, n_first: int, trials: list) -> dict[str, Any] | None:
    """Before an ask past the first phase (none waiting): one trial in :data:`EXPLORE_EVERY` goes to a (material,
    tip) pair on purpose: its params (all of them, or only the pair's for the sampler to draw the rest), or None.
    ``trials``: the study's trials, as asked.

    - While a pair has no feasible design and fewer trials than :func:`pair_to_search` allows, the least-tried
      such pair gets the model's proposal held to it (:func:`magfab.inverse.propose.propose`'s ``pair``): its local
      steps start from the pair's designs that miss by least and from the study's best designs carried into the
      pair, and it is ranked by how far the model predicts it misses until the model predicts a feasible design
      there. A thin feasible region (the fingertip bench set's Dragon Skin 10 hemisphere: 13 feasible designs in a
      500-design sweep of the pair) is found from its near misses, where a draw would hit it by chance.
    - Otherwise (every pair feasible or given up, or no proposal), the pair the study has tried least (ties: the
      choices' order), its magnet and fractions left to the sampler.

    bench/design_search.py (300 trials against a 3,000-design sweep, seeds 0-19, 2 workers), against the least-tried
    pair with the sampler's draw alone: the fingertip set's worst seed rose from 0.753 of the sweep's hypervolume to
    1.011 (the pair it missed is found at every seed), the stiff pad's from 0.763 to 0.827, with seeds below 0.95
    from 1 and 2 to 0 and 1, and the stiff pad's seeds where a sweep design dominates the chosen one from 5 to 4; the
    taxel set's worst is 1.026. Medians moved from 1.302 to 1.242 (fingertip) and 1.239 to 1.193 (stiff pad)."""
    if (len(trials) - n_first) % EXPLORE_EVERY != EXPLORE_EVERY - 1:
        return None
    pair = pair_to_search(space, trials, n_first)
    params = model_step(space, targets, n_first, trials, pair=pair) if pair is not None else None
    if params is not None:
        return params
    tried = [(t.params.get("material"), t.params.get("tip")) for t in trials]
    material, tip = min(space.pairs(), key=lambda p: tried.count(p))
    return {"material": material, "tip": tip}


def pair_to_search(space: Space, trials: list, n_first: int) -> tuple[str, str] | None:
    """The (material, tip) pair an exploration trial searches with the model (:func:`explore`): the least-tried
    (ties: the choices' order) of those with no feasible design among the told trials and fewer trials than their
    share of the first phase plus :data:`PAIR_TRIES`; None when there is none. The cap keeps a pair with no feasible
    design at all (the stiff pad's Ecoflex 00-50 with a hemisphere tip) from taking every exploration trial."""
    from optuna.trial import TrialState

    pairs = space.pairs()
    tried = [(t.params.get("material"), t.params.get("tip")) for t in trials]
    feasible = {p for p, t in zip(tried, trials) if t.state is TrialState.COMPLETE and violation(t) <= 0.0}
    cap = n_first / len(pairs) + PAIR_TRIES
    open_pairs = [p for p in pairs if p not in feasible and tried.count(p) < cap]
    return min(open_pairs, key=lambda p: tried.count(p)) if open_pairs else None


def _listed(trial) -> list | None:
    """The constraint list :func:`~magfab.inverse.study.tell` stores, read from the trial's system attributes directly
    (None for a trial without it: not told, or told by an earlier version by name). Optuna's ``trial.constraints``
    parses every system attribute at each read, and the steps read every trial's at every ask (0.38 s of an 11 s
    profiled study of the example targets, 58,000 reads)."""
    return trial.system_attrs.get(CONSTRAINTS)


def constraint_row(trial, names: list[str]) -> list[float]:
    """A told trial's constraints in ``names``' order: from the list :func:`tell` stores, or by name (a study an earlier
    version stored with ``trial.set_constraint``); 0 for one it lacks."""
    listed = _listed(trial)
    if listed is not None:
        return [float(listed[i]) if i < len(listed) else 0.0 for i in range(len(names))]
    c = trial.constraints
    return [float(c[n]) if n in c else float(c.get(str(i), 0.0)) for i, n in enumerate(names)]


def violation(trial) -> float:
    """How far a told trial misses its constraints: the sum of their positive values."""
    listed = _listed(trial)
    return sum(max(float(v), 0.0) for v in (listed if listed is not None else (trial.constraints or {}).values()))


def elite(trials: list, targets: Targets) -> list:
    """The study's best designs so far: its feasible front (no feasible design better on every objective), or, while
    none is feasible, the three that miss their constraints by least (the sum of their violations)."""
    feasible = [t for t in trials if violation(t) <= 0.0]
    if feasible:
        return [t for t, keep in zip(feasible, front_mask(np.array([t.values for t in feasible]),
                                                          targets.directions())) if keep]
    return sorted(trials, key=lambda t: (violation(t), t.number))[:3]


def asked_designs(trials: list) -> set:
    """The designs the study has asked (evaluated or in flight), as :func:`design_key` s."""
    return {design_key(t.user_attrs[POINT]) for t in trials if POINT in t.user_attrs}


def model_step(space: Space, targets: Targets, n_first: int, trials: list,
               pair: tuple[str, str] | None = None) -> dict[str, Any] | None:
    """Before an ask past the first phase (none waiting): each trial that :func:`explore` leaves is the model's
    proposal (:func:`magfab.inverse.propose.propose`: from every design the study has evaluated, its local steps from
    the study's best designs, seeded with the study's seed and the trial's number): its params, or None. ``pair``:
    the proposal held to this (material, tip) pair, its local steps also from the pair's three designs that miss by
    least (:func:`explore`; another seed stream)."""
    from optuna.trial import TrialState

    done = [t for t in trials if t.state is TrialState.COMPLETE]
    names = constraint_names(targets)
    seen = asked_designs(trials)
    parents = [t.params for t in elite(done, targets)]
    seed: tuple[int, ...] = (targets.study.seed, len(trials))
    held: int | None = None
    if pair is not None:
        mine = [t for t in done if (t.params.get("material"), t.params.get("tip")) == pair]
        parents = [t.params for t in sorted(mine, key=lambda t: (violation(t), t.number))[:3]] + parents
        held, seed = space.pairs().index(pair), (*seed, PAIR_SEED)
    return propose(space, targets.directions(), [t.params for t in done], [t.values for t in done],
                   [constraint_row(t, names) for t in done], parents,
                   lambda p: design_key(space.point(p)) not in seen, seed, pair=held,
                   optimism=OPTIMISM if pair is None and len(trials) % OPTIMISTIC_EVERY == 0 else 0.0)


def refine(space: Space, targets: Targets, n_first: int, trials: list) -> dict[str, Any] | None:
    """Before an ask the model step left (past the first phase, none waiting): a step from one of the study's best
    designs (:func:`elite`, drawn with the study's seed and the trial's number): its categories kept, its
    magnet's and numeric fractions moved by a normal step of :data:`REFINE_SIGMA` (narrowing as the study goes on),
    clipped to the unit interval: the step is buildable too. A step onto a design the study has asked is drawn again,
    up to :data:`REFINE_DRAWS` times; then (None) the sampler draws the trial. Its params, or None."""
    from optuna.trial import TrialState

    number, past = len(trials), len(trials) - n_first
    best = elite([t for t in trials if t.state is TrialState.COMPLETE], targets)
    if not best:
        return None
    seen = asked_designs(trials)
    rng = np.random.default_rng([targets.study.seed, number])
    sigma = REFINE_SIGMA * (1.0 - 0.8 * min(1.0, past / max(1, targets.study.trials - n_first)))
    for _ in range(REFINE_DRAWS):
        params = dict(best[int(rng.integers(len(best)))].params)
        for name in (MAGNET_FRACTION, *FRACTIONS):
            if name in params:
                params[name] = float(np.clip(float(params[name]) + sigma * rng.standard_normal(), 0.0, 1.0))
        if design_key(space.point(params)) not in seen:
            return params
    return None


def design_key(point: Mapping[str, Any]) -> tuple:
    """A design's identity: its point's items, in name order."""
    return tuple(sorted(point.items()))
