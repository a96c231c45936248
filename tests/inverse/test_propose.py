"""The model step (magfab.inverse.propose) on synthetic problems whose truth is known: it learns a constraint from
infeasible designs, proposes designs that extend the evaluated front, and is repeatable. The problems are drawn
(their feasible boundary and optimum shifted) rather than fixed."""

from __future__ import annotations

import numpy as np

from magfab.inverse.pareto import front_mask
from magfab.inverse.propose import MIN_DESIGNS, propose
from magfab.inverse.space import FRACTIONS, MAGNET_FRACTION, Space
from magfab.inverse.targets import parse_targets
from magfab.spec import load_spec

TARGETS = parse_targets("""
name = "synthetic"
objectives = ["normal_resolution_mN", "normal_range_N"]
[variables]
magnets = ["d5_h2", "d4_h2"]
materials = ["ecoflex-00-30", "dragon-skin-10"]
tips = ["flat", "hemisphere"]
d_max_mm = [4.0, 8.0]
d_min_mm = [2.5, 3.5]
elastomer_diameter_mm = [10.0, 14.0]
cover_mm = [1.0, 2.5]
""")
SPACE = Space(TARGETS, load_spec(None))
DIRECTIONS = ("minimize", "minimize")


def _problem(rng: np.random.Generator):
    """A drawn problem: two objectives in conflict along f_d_max, a bowl in f_cover centred at ``c0``, feasible where
    f_elastomer_diameter >= ``edge`` and never with dragon-skin-10."""
    edge, c0 = rng.uniform(0.2, 0.6), rng.uniform(0.2, 0.8)

    def truth(p):
        x, c = p[FRACTIONS[1]], p[FRACTIONS[2]]
        values = (0.1 + x + (c - c0) ** 2, 1.1 - x + 2.0 * (c - c0) ** 2)
        constraint = (edge - p[FRACTIONS[0]]) if p["material"] == "ecoflex-00-30" else 1.0
        return values, [constraint]

    return truth


def _uniform(rng: np.random.Generator) -> dict:
    p = {"material": SPACE.choices["material"][int(rng.integers(2))], "tip": SPACE.choices["tip"][int(rng.integers(2))],
         MAGNET_FRACTION: float(rng.random())}
    p.update({f: float(rng.random()) for f in FRACTIONS})
    return p


def _evaluated(truth, rng, n=40):
    params = [_uniform(rng) for _ in range(n)]
    values, constraints = zip(*(truth(p) for p in params))
    return params, list(values), list(constraints)


def _best(params, values, constraints) -> list:
    feasible = [i for i, c in enumerate(constraints) if max(c) <= 0]
    keep = front_mask(np.array([values[i] for i in feasible]), DIRECTIONS)
    return [params[i] for i, k in zip(feasible, keep) if k]


def _non_dominated(value, values, constraints) -> bool:
    feasible = [values[i] for i, c in enumerate(constraints) if max(c) <= 0]
    return not any(all(a <= b for a, b in zip(f, value)) and f != tuple(value) for f in map(tuple, feasible))


def test_proposals_are_feasible_and_extend_the_front():
    """Twenty proposals (twenty seeds) from forty uniform designs, on each of eight drawn problems: against uniform
    draws on the same problems, they are feasible far more often (the model learned the constraint from the
    infeasible designs) and land on the front of the designs evaluated far more often."""
    feasible = on_front = uniform_feasible = uniform_front = 0
    for draw in range(8):
        rng = np.random.default_rng(draw)
        truth = _problem(rng)
        params, values, constraints = _evaluated(truth, rng)
        parents = _best(params, values, constraints)
        for seed in range(20):
            p = propose(SPACE, DIRECTIONS, params, values, constraints, parents, lambda _: True, (draw, seed))
            assert p is not None
            value, constraint = truth(p)
            feasible += max(constraint) <= 0
            on_front += max(constraint) <= 0 and _non_dominated(value, values, constraints)
            q = _uniform(rng)
            value, constraint = truth(q)
            uniform_feasible += max(constraint) <= 0
            uniform_front += max(constraint) <= 0 and _non_dominated(value, values, constraints)
    assert feasible >= 0.8 * 160 and feasible >= 2.5 * uniform_feasible, (feasible, uniform_feasible)
    assert on_front >= 0.5 * 160 and on_front >= 3 * uniform_front, (on_front, uniform_front)


def test_a_proposal_is_repeatable_and_new():
    rng = np.random.default_rng(9)
    truth = _problem(rng)
    params, values, constraints = _evaluated(truth, rng)
    parents = _best(params, values, constraints)
    args = (SPACE, DIRECTIONS, params, values, constraints, parents)
    first = propose(*args, lambda _: True, (1, 2))
    assert first == propose(*args, lambda _: True, (1, 2))
    refused = []

    def is_new(p):
        refused.append(p)
        return len(refused) > 3

    second = propose(*args, is_new, (1, 2))
    assert second == refused[3] and second != first  # the fourth best, the first three already evaluated
    assert propose(*args, lambda _: False, (1, 2)) is None


def test_no_proposal_from_too_few_designs_or_old_params():
    rng = np.random.default_rng(4)
    truth = _problem(rng)
    params, values, constraints = _evaluated(truth, rng, MIN_DESIGNS - 1)
    assert propose(SPACE, DIRECTIONS, params, values, constraints, [], lambda _: True, (0,)) is None
    params, values, constraints = _evaluated(truth, rng, 30)
    params[5] = {k: v for k, v in params[5].items() if k != MAGNET_FRACTION} | {"magnet": "d5_h2:N52"}
    assert propose(SPACE, DIRECTIONS, params, values, constraints, [], lambda _: True, (0,)) is None
