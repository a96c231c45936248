"""The model step (magfab.inverse.propose) on synthetic problems whose truth is known: it learns a constraint from
infeasible designs, proposes designs that extend the evaluated front, and is repeatable. The problems are drawn
(their feasible boundary and optimum shifted) rather than fixed."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from optuna.trial import TrialState

from magfab.inverse.pareto import front_mask
from magfab.inverse.propose import MIN_DESIGNS, propose
from magfab.inverse.space import FRACTIONS, MAGNET_FRACTION, Space
from magfab.inverse.steps import CONSTRAINTS, OPTIMISM, PAIR_TRIES, pair_to_search
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


def _thin_problem(rng: np.random.Generator, pair: tuple[str, str]):
    """A drawn problem feasible in a band of f_cover centred at ``c0``: 0.6 wide in every pair but ``pair``, 0.14 wide
    in ``pair`` (the same trend, shifted: a stiffer silicone's resolution), and above a drawn edge in
    f_elastomer_diameter; about 8-11 % of ``pair``."""
    edge, c0 = rng.uniform(0.2, 0.4), rng.uniform(0.2, 0.8)

    def truth(p):
        x, c = p[FRACTIONS[1]], p[FRACTIONS[2]]
        values = (0.1 + x + (c - c0) ** 2, 1.1 - x + 2.0 * (c - c0) ** 2)
        half = 0.07 if (p["material"], p["tip"]) == pair else 0.3
        return values, [edge - p[FRACTIONS[0]], 10.0 * ((c - c0) ** 2 - half**2)]

    return truth


def test_a_proposal_held_to_a_pair_finds_its_thin_feasible_region():
    """Held to a pair whose feasible region is thin, on six drawn problems with forty uniform designs evaluated (about
    ten in that pair): every proposal is of that pair, and the model, stepping from the
    pair's near misses and the trend the other pairs show, proposes feasible designs there several times as often as
    draws within the pair hit them."""
    pair = ("dragon-skin-10", "flat")  # a flat tip's cover fraction is its cover in mm: the band is one in the model
    index = SPACE.pairs().index(pair)
    held = hit = drawn = 0
    for draw in range(6):
        rng = np.random.default_rng(100 + draw)
        truth = _thin_problem(rng, pair)
        params, values, constraints = _evaluated(truth, rng)
        near = sorted((i for i, p in enumerate(params) if (p["material"], p["tip"]) == pair),
                      key=lambda i: max(constraints[i]))[:3]
        parents = [params[i] for i in near] + _best(params, values, constraints)
        for seed in range(10):
            p = propose(SPACE, DIRECTIONS, params, values, constraints, parents, lambda _: True, (draw, seed),
                        pair=index)
            assert p is not None and (p["material"], p["tip"]) == pair
            held += max(truth(p)[1]) <= 0
            q = _uniform(rng) | {"material": pair[0], "tip": pair[1]}
            drawn += max(truth(q)[1]) <= 0
        hit += any(max(c) <= 0 for p, c in zip(params, constraints) if (p["material"], p["tip"]) == pair)
    assert held >= 0.25 * 60 and held >= 3 * drawn, (held, drawn, hit)  # measured: 19 against 4


@settings(max_examples=200, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 3), st.sampled_from(["ok", "miss", "failed", "running"])), max_size=80),
       st.integers(8, 40))
def test_the_pair_an_exploration_searches(drawn, n_first):
    """Over drawn studies (trials of any pair, feasible, missing, failed or still running): the pair an exploration
    trial searches with the model has no feasible design among the told trials and fewer trials than its share of
    the first phase plus PAIR_TRIES, and is the least-tried such pair (ties: the choices' order); None only when every
    pair has a feasible design or has had its trials."""
    pairs = SPACE.pairs()
    states = {"ok": TrialState.COMPLETE, "miss": TrialState.COMPLETE, "failed": TrialState.FAIL,
              "running": TrialState.RUNNING}
    listed = {"ok": [-1.0], "miss": [0.5]}  # the list tell stores, and Optuna's reading of it
    trials = [SimpleNamespace(params={"material": pairs[k][0], "tip": pairs[k][1]}, state=states[s],
                              system_attrs={CONSTRAINTS: listed[s]} if s in listed else {},
                              constraints={"0": listed[s][0]} if s in listed else {})
              for k, s in drawn]
    count = {p: sum(pairs[k] == p for k, _ in drawn) for p in pairs}
    feasible = {pairs[k] for k, s in drawn if s == "ok"}
    cap = n_first / len(pairs) + PAIR_TRIES
    open_pairs = [p for p in pairs if p not in feasible and count[p] < cap]
    chosen = pair_to_search(SPACE, trials, n_first)
    if chosen is None:
        assert not open_pairs
    else:
        assert chosen in open_pairs and count[chosen] == min(count[p] for p in open_pairs)
        assert chosen == next(p for p in open_pairs if count[p] == count[chosen])


def _cliff_problem(rng: np.random.Generator):
    """A drawn problem whose best designs sit past a cliff the evaluated designs never reached: both objectives fall
    with f_cover, the constraint rises as f_cover falls toward a drawn ``cliff`` (what the designs show) and drops
    to feasible past it (the stiff pad's resolution at the thinnest covers); Ecoflex only, a flat tip."""
    cliff = rng.uniform(0.25, 0.35)

    def truth(p):
        x, c = p[FRACTIONS[1]], p[FRACTIONS[2]]
        values = (0.1 + x + c, 1.1 - x + c)
        return values, [0.5 - c if c >= cliff else -0.1]

    return truth, cliff


def test_optimism_steps_past_what_the_designs_show():
    """On eight drawn cliff problems with forty designs evaluated above the cliff (the model, extrapolating them,
    predicts every design past it infeasible): with OPTIMISM, the proposal goes past the cliff, where every design
    is feasible and the objectives better, at half the seeds or more (measured: 48 of 80); without it, at none."""
    found = {0.0: 0, OPTIMISM: 0}
    for draw in range(8):
        rng = np.random.default_rng(200 + draw)
        truth, cliff = _cliff_problem(rng)
        params = [_uniform(rng) | {"material": "ecoflex-00-30", "tip": "flat",
                                   FRACTIONS[2]: float(rng.uniform(cliff + 0.05, 1.0))} for _ in range(40)]
        values, constraints = map(list, zip(*(truth(p) for p in params)))
        parents = _best(params, values, constraints)
        for seed in range(10):
            for optimism in found:
                p = propose(SPACE, DIRECTIONS, params, values, constraints, parents, lambda _: True, (draw, seed),
                            pair=SPACE.pairs().index(("ecoflex-00-30", "flat")), optimism=optimism)
                assert p is not None
                found[optimism] += p[FRACTIONS[2]] < cliff
    assert found[0.0] == 0 and found[OPTIMISM] >= 0.5 * 80, found  # measured: 0 and 48


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2**31 - 1), st.integers(1, 60), st.integers(0, 60))
def test_a_designs_coordinates_do_not_depend_on_its_company(seed, n, cached):
    """The model step keeps each evaluated design's coordinates (propose._physical_of's memo): a row mapped alone,
    in a batch or from the memo is the row the whole batch gives, bit for bit, in any order and with repeats."""
    from magfab.inverse.propose import _physical_of

    rng = np.random.default_rng(seed)
    rows = SPACE.latin_hypercube(n, seed)
    rows += [rows[int(i)] for i in rng.integers(n, size=n // 3)]  # repeats
    rows = [rows[int(i)] for i in rng.permutation(len(rows))]
    space = Space(TARGETS, load_spec(None))
    fresh = _physical_of(space, rows)
    assert fresh.shape[0] == len(rows)
    again = Space(TARGETS, load_spec(None))
    _physical_of(again, rows[:cached])  # some already in the memo, mapped in other company
    for i in rng.permutation(len(rows))[:5]:  # some alone
        _physical_of(again, [rows[int(i)]])
    np.testing.assert_array_equal(_physical_of(again, rows), fresh)
