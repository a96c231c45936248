"""The search's model step: a ParEGO proposal on radial-basis-function models of every design the study evaluated.

After the first phase most trials are proposed here rather than drawn by the sampler (:mod:`magfab.inverse.study`).
Each proposal:

1. fits one radial-basis-function model (scipy's ``RBFInterpolator``, thin-plate spline with a linear term) of every
   objective and every constraint over the designs the study has evaluated, feasible or not, in physical
   coordinates (:func:`_physical`): each design's magnet as its log moment, disc diameter and height, and its
   numeric variables in mm, each scaled over what the space spans; each silicone and tip an indicator scaled by
   :data:`CATEGORY_SCALE`, so designs of another pair inform a pair's model without standing in for it;
2. scores candidates (:data:`CANDIDATES` drawn uniformly over every pair and the search's fractions, and as many
   steps of :data:`LOCAL_SIGMA` from the study's best designs: drawn in the search's coordinates, so each is
   buildable, and mapped to their mm points for the model) by the model: those it predicts feasible by the
   objectives' augmented Chebyshev scalarisation under one random weight (ParEGO, Knowles 2006, IEEE Trans. Evol.
   Comput. 10(1):50-66), or, while it predicts none feasible, by how far it predicts they miss;
3. returns the best-scored candidate the study has not evaluated.

An optimistic proposal (``optimism`` > 0: every second model step of a study, :data:`magfab.inverse.steps.OPTIMISM`)
lets each local step miss each constraint by ``optimism`` times its distance, in the model's coordinates, to the
nearest design evaluated. The fit has no error estimate of its own, and far from its data it is often wrong on the
side of caution: on the stiff pad bench set it predicted 38 mN of resolution at a thin-cover design that gave 19.2
(the requirement: 20), so no proposal went past the thinnest cover the study had tried, and which basin a study
pushed to its bounds decided the seed. The distance stands in for the missing error estimate, as the distance
criterion of Regis and Shoemaker's stochastic RBF method does for the objective (INFORMS J. Comput. 19(4):497-509,
2007): the allowance is nothing at the designs evaluated and grows away from them, so the study steps past what its
designs show and learns from what it finds there. Only the local steps take it, so the optimism is spent near the
front rather than on uniform candidates far from every design.
bench/design_search.py, 300 trials against a 3,000-design sweep, seeds 0-19, against the same search without it: the
stiff pad's worst seed rose from 0.827 of the sweep's hypervolume to 0.977, the seeds where a sweep design dominates
the chosen one fell from four to two (each dominated by the sweep's one 43.0 N design), its median went from 1.193
to 1.173; the fingertip's worst from 1.011 to 1.043 (median 1.242 to 1.178), the taxel's 1.026 to 1.024 (median
1.055 to 1.047). All 60 studies hold 0.95 of their sweep's hypervolume or more. With the flat tip's surrogate table
widened to thin bodies with wide magnets (bench/fe_surrogate.py's fourth flat hypercube, which judges the stiff pad's
thin-cover designs nearer the FE: 59.2 N at 17.7 mN by the FE, 56.3 at 18.9 by it, 52.6 at 23.0 before), the same
bench: the fingertip's worst seed 1.023, the taxel's 1.010, none dominated; the stiff pad's worst 0.879, its chosen
design dominated at 5 seeds of 20 (12 of 40; 6 of 40 with the table before), its studies settling on another
magnet's basin (tests/inverse/test_search_space.py's strict xfail says which).

The random weight moves the proposal along the whole front trial by trial; the model learns the constraints from
infeasible designs, so a region the first phase met once is followed where TPE, which models the good and the bad
designs apart, left it. bench/design_search.py, 150 trials against a 1,500-design sweep, seeds 0-9: the worst
seed's hypervolume ratio rose from 0.38 to 0.85 on the stiff pad, 0.53 to 0.68 on the fingertip, 0.75 to 0.78 on the
taxel, and the median from 1.09, 1.16 and 0.92 to 1.09, 1.28 and 0.99, when this step took the trials that TPE's
draws and the steps from the best designs had shared.

Why physical coordinates: the search's fractions are nested (a fraction of d_max is of the interval the magnet, tip
and diameter leave), so one fraction is a different mm value under each magnet and the objectives are rough in
them; in mm they are smooth. The same bench at the study's default of 300 trials against a 3,000-design sweep,
seeds 0-9, one session: the worst seed's hypervolume ratio went from 0.738 to 0.966 on the fingertip and 0.792 to
0.961 on the stiff pad (the taxel 0.955 to 1.000), the median from 1.063 to 1.316 and 1.059 to 1.116, every seed
of all three sets at 0.95 or more; the loop's cost a trial rose from 43 to 61 ms (the candidates' mm points).

Pure and seeded: the same designs, values and seed give the same proposal.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from .space import FRACTION_OF, MAGNET_FRACTION, NUMERIC, Space, magnet_moment, stock_disc

__all__ = ["propose", "CANDIDATES", "LOCAL_SIGMA", "CATEGORY_SCALE", "MIN_DESIGNS"]

#: Candidates drawn uniformly each proposal (and as many local steps from the study's best designs).
CANDIDATES = 1000
#: The local steps' spread over the unit fractions.
LOCAL_SIGMA = 0.1
#: How far apart two silicones (or two tips) sit in the model's coordinates, against physical coordinates scaled to
#: their span: near enough that a pair's few designs borrow the others' trends, far enough that a pair's own designs
#: decide its model (1.0 did worse on the fingertip bench set's first three seeds when the model was in the
#: fractions: hypervolume ratios 0.84, 0.89, 0.95; not measured again in mm).
CATEGORY_SCALE = 0.5
#: The radial-basis fit's smoothing: the cheap models are deterministic, so almost an interpolation; a little keeps
#: the fit well-posed where two designs nearly coincide.
SMOOTHING = 1e-3
#: Constraint values are clipped to this band before the fit: a design that misses by 1e9 (a figure it lacks) or
#: meets with room to spare tells the model which side it is on, not by how much.
CLIP = (-1.0, 3.0)
#: The fewest evaluated designs a model is fitted to; fewer, no proposal.
MIN_DESIGNS = 10
#: Best-scored candidates tried, in order, for one the study has not evaluated.
TRIES = 20
#: The augmented Chebyshev scalarisation's linear term (ParEGO's rho).
RHO = 0.05
#: The most designs one model is fitted to (:func:`_kept`).
MAX_FIT = 400


def _numeric_axes(space: Space) -> dict[str, tuple[str, list[float] | None]]:
    """Each numeric variable's param: its fraction (None) or, given as listed values, its own name and the values."""
    out: dict[str, tuple[str, list[float] | None]] = {}
    for name in NUMERIC:
        c = getattr(space.variables, name)
        out[name] = (name, sorted(float(x) for x in c)) if isinstance(c, list) else (FRACTION_OF[name], None)
    return out


def _columns(space: Space, axes, rows: Sequence[Mapping[str, Any]]) -> tuple[np.ndarray, np.ndarray]:
    """Trials' params as (unit coordinates: the magnet's fraction, then each numeric variable's fraction or listed
    value scaled over its list; each one's pair index into :meth:`Space.pairs`)."""
    pairs = space.pairs()
    u = np.empty((len(rows), 1 + len(axes)))
    for i, p in enumerate(rows):
        u[i, 0] = float(p[MAGNET_FRACTION])
        for j, (param, values) in enumerate(axes.values(), start=1):
            u[i, j] = float(p[param]) if values is None else _scaled(values, float(p[param]))
    return u, np.array([pairs.index((p["material"], p["tip"])) for p in rows], dtype=int)


def _scaled(values: list[float], v: float) -> float:
    return (v - values[0]) / (values[-1] - values[0]) if values[-1] > values[0] else 0.5


def _nearest(values: list[float], x: float) -> float:
    """The listed value whose scaled coordinate is nearest ``x`` (ties: the smaller)."""
    return values[int(_nearest_index(values, np.array([x]))[0])]


def _nearest_index(values: list[float], x: np.ndarray) -> np.ndarray:
    """:func:`_nearest` for many, as indices into ``values`` (sorted, so the first of a tie is the smaller)."""
    grid = np.array([_scaled(values, v) for v in values])
    return np.argmin(np.abs(x[:, None] - grid[None, :]), axis=1)


def _physical(space: Space, pair: np.ndarray, f_magnet: np.ndarray, numeric: dict[str, np.ndarray]) -> np.ndarray:
    """The model's coordinates of designs given by their pair index (into :meth:`Space.pairs`), magnet fraction and
    numeric params (:meth:`Space.numeric_params`, one array each; module doc): each design's mm point
    (:meth:`Space.mm`, the mapping :meth:`Space.point` makes, for all at once) as its magnet's log moment, disc
    diameter and height, and its numeric variables, each scaled over what the space spans (:func:`_spans`); then
    indicators of every silicone and tip but the first (a linear term in the fit makes the first redundant), each
    :data:`CATEGORY_SCALE`."""
    lo, width = _spans(space)
    magnets, tips = space.choices["magnet"], space.choices["tip"]
    n_tips = len(tips)
    material, tip = pair // n_tips, pair % n_tips
    magnet = space.magnets_at(tip, f_magnet)
    discs = [stock_disc(m.split(":")[0]) for m in magnets]
    per_magnet = np.array([[math.log(magnet_moment(m)), d, h] for m, (d, h, _) in zip(magnets, discs)])
    mm = space.mm([(m, t) for m in magnets for t in tips], magnet * n_tips + tip, numeric)
    x = np.hstack([per_magnet[magnet], mm])
    ind_m = (material[:, None] == np.arange(1, len(space.choices["material"]))[None, :])
    ind_t = (tip[:, None] == np.arange(1, n_tips)[None, :])
    return np.hstack([(x - lo) / width, CATEGORY_SCALE * ind_m, CATEGORY_SCALE * ind_t])


def _physical_of(space: Space, rows: Sequence[Mapping[str, Any]]) -> np.ndarray:
    """:func:`_physical` of designs given by their params. Each design's row is kept in ``space.memo`` by its params:
    a study fits every proposal to the designs it has evaluated, and all but the latest were mapped before (a row
    depends on its design alone, so a memo's row is the row :func:`_physical` gives in any company)."""
    memo = space.memo.setdefault("physical", {})
    keys = [tuple(sorted(p.items())) for p in rows]
    todo = list(dict.fromkeys(k for k in keys if k not in memo))
    if todo:
        pairs = space.pairs()
        fresh = [dict(k) for k in todo]
        x = _physical(space, np.array([pairs.index((p["material"], p["tip"])) for p in fresh], dtype=int),
                      np.array([float(p[MAGNET_FRACTION]) for p in fresh]),
                      {k: np.array([float(p[k]) for p in fresh]) for k in space.numeric_params()})
        memo.update(zip(todo, x))
    return np.array([memo[k] for k in keys])


def _independent(x: np.ndarray) -> list[int]:
    """The columns of ``x`` that the fit's linear term can tell apart: each kept when it raises the rank of a constant
    and the columns kept before it (a disc size the same for every magnet, or a choice that fixes another, would
    leave the fit singular)."""
    whole = np.column_stack([np.ones(len(x)), x])
    if np.linalg.matrix_rank(whole) == whole.shape[1]:  # all: a set of columns has no smaller least singular value
        return list(range(x.shape[1]))  # than the whole, nor a larger tolerance (one SVD, not one per column)
    kept: list[int] = []
    for j in range(x.shape[1]):
        trial = np.column_stack([np.ones(len(x)), x[:, [*kept, j]]])
        if np.linalg.matrix_rank(trial) == trial.shape[1]:
            kept.append(j)
    return kept


def _spans(space: Space) -> tuple[np.ndarray, np.ndarray]:
    """The low end and width of each physical coordinate over the space: the buildable magnets' log moments and disc
    sizes, and each numeric variable's range (or listed values); a width of 1 where there is one value."""
    magnets = space.choices["magnet"]
    discs = [stock_disc(m.split(":")[0])[:2] for m in magnets]
    columns = [[math.log(magnet_moment(m)) for m in magnets], [d for d, _ in discs], [h for _, h in discs],
               *([float(x) for x in getattr(space.variables, name)] for name in NUMERIC)]
    lo, hi = np.array([min(c) for c in columns]), np.array([max(c) for c in columns])
    return lo, np.where(hi > lo, hi - lo, 1.0)


def _snap(axes, u: np.ndarray) -> np.ndarray:
    """Unit coordinates with each listed-values column moved to the nearest listed value's."""
    u = u.copy()
    for j, (_, values) in enumerate(axes.values(), start=1):
        if values is not None:
            grid = np.array([_scaled(values, v) for v in values])
            u[:, j] = grid[np.argmin(np.abs(u[:, j, None] - grid[None, :]), axis=1)]
    return u


def _params(space: Space, axes, u: np.ndarray, pair: int) -> dict[str, Any]:
    """A candidate's params from its unit coordinates and pair index."""
    material, tip = space.pairs()[pair]
    p: dict[str, Any] = {"material": material, "tip": tip, MAGNET_FRACTION: float(u[0])}
    for j, (param, values) in enumerate(axes.values(), start=1):
        p[param] = float(u[j]) if values is None else _nearest(values, float(u[j]))
    return p


def propose(space: Space, directions: Sequence[str], params: Sequence[Mapping[str, Any]],
            values: Sequence[Sequence[float]], constraints: Sequence[Sequence[float]],
            parents: Sequence[Mapping[str, Any]], is_new: Callable[[dict[str, Any]], bool],
            seed: Sequence[int], pair: int | None = None, optimism: float = 0.0) -> dict[str, Any] | None:
    """The params of the next design to evaluate (module doc), or None: fewer than :data:`MIN_DESIGNS` designs, a
    design without the magnet's fraction (a study stored before it), a fit that fails, or no new design among the
    best-scored.

    ``params``, ``values`` (objective values, in ``directions``), ``constraints`` (<= 0 feasible): the evaluated
    designs; ``parents``: the params local steps start from (the study's best designs); ``is_new``: whether a
    candidate's design is not yet evaluated (or in flight); ``seed``: the random draws' seed; ``pair``: every
    candidate held to this (material, tip) pair (an index into :meth:`Space.pairs`), the local steps' included;
    ``optimism``: the local steps' allowance on each constraint per unit of distance from the designs (module doc)."""
    from scipy.interpolate import RBFInterpolator  # lazy: scipy is slow to import and only a running study needs it
    from scipy.spatial import cKDTree

    if len(params) < MIN_DESIGNS or any(MAGNET_FRACTION not in p for p in (*params, *parents)):
        return None
    keep = _kept(len(params))
    axes = _numeric_axes(space)
    sign = np.array([1.0 if d == "minimize" else -1.0 for d in directions])
    v = np.asarray(values, dtype=float).reshape(len(params), len(directions))[keep]
    logged = np.where(np.all(v > 0, axis=0), np.log(np.where(v > 0, v, 1.0)), v) * sign  # ratios: a log scale
    lo, hi = logged.min(axis=0), logged.max(axis=0)
    objectives = (logged - lo) / np.where(hi > lo, hi - lo, 1.0)
    c = np.clip(np.asarray(constraints, dtype=float).reshape(len(params), -1)[keep], *CLIP)
    kept = [params[i] for i in keep]
    x = _physical_of(space, kept)
    columns = _independent(x)
    designs = x[:, columns]
    try:
        model = RBFInterpolator(designs, np.hstack([objectives, c]), kernel="thin_plate_spline",
                                smoothing=SMOOTHING, degree=1)
    except (np.linalg.LinAlgError, ValueError):
        return None
    rng = np.random.default_rng(list(seed))
    n_pairs = len(space.pairs())
    cu, cp = rng.random((CANDIDATES, 1 + len(axes))), rng.integers(n_pairs, size=CANDIDATES)
    if parents:
        pu, pp = _columns(space, axes, parents)
        pick = rng.integers(len(parents), size=CANDIDATES)
        steps = np.clip(pu[pick] + LOCAL_SIGMA * rng.standard_normal((CANDIDATES, pu.shape[1])), 0.0, 1.0)
        cu, cp = np.vstack([cu, steps]), np.concatenate([cp, pp[pick]])
    if pair is not None:
        cp = np.full(len(cu), pair, dtype=int)
    cu = _snap(axes, cu)
    numeric = {param: cu[:, j] if values is None else np.asarray(values)[_nearest_index(values, cu[:, j])]
               for j, (param, values) in enumerate(axes.values(), start=1)}
    xs = _physical(space, cp, cu[:, 0], numeric)[:, columns]
    predicted = model(xs)
    allowance = np.zeros(len(cu))
    if optimism > 0.0 and parents:  # the local steps: each constraint met within optimism x distance to the nearest
        allowance[CANDIDATES:] = optimism * cKDTree(designs).query(xs[CANDIDATES:])[0]
    o = predicted[:, :len(directions)]
    miss = np.maximum(predicted[:, len(directions):] - allowance[:, None], 0.0).sum(axis=1)
    weight = rng.dirichlet(np.ones(len(directions)))
    feasible = miss <= 0.0
    if feasible.any():
        score = np.max(weight * o, axis=1) + RHO * (o @ weight)
        order = [int(i) for i in np.argsort(score, kind="stable") if feasible[i]]
    else:
        order = [int(i) for i in np.argsort(miss, kind="stable")]
    for i in order[:TRIES]:
        candidate = _params(space, axes, cu[i], int(cp[i]))
        if is_new(candidate):
            return candidate
    return None


def _kept(n: int) -> list[int]:
    """The designs a model is fitted to: the first phase's and the latest, :data:`MAX_FIT` in all (the fit's cost
    grows as their cube; a study's proposals then follow its latest designs)."""
    if n <= MAX_FIT:
        return list(range(n))
    head = MAX_FIT // 4
    return [*range(head), *range(n - (MAX_FIT - head), n)]
