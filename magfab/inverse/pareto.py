"""Pareto fronts of evaluated designs: non-dominated sorting, and which designs the full chain re-verifies."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

__all__ = ["values_of", "minimised", "front_mask", "ranks", "pick_for_verification", "dominates_or_equals"]


def values_of(records: Sequence, objectives: Sequence[str]) -> np.ndarray:
    """The objective values of records (anything with a ``metrics`` dict), one row each: shape (n, objectives)."""
    return np.array([[r.metrics[o] for o in objectives] for r in records], dtype=float).reshape(-1, len(objectives))


def minimised(values: np.ndarray, directions: Sequence[str]) -> np.ndarray:
    """The objective values with every column turned into one to minimise."""
    sign = np.array([1.0 if d == "minimize" else -1.0 for d in directions])
    return np.asarray(values, dtype=float) * sign


def front_mask(values: np.ndarray, directions: Sequence[str]) -> np.ndarray:
    """True for each row no other row dominates (at least as good on every objective, better on one)."""
    v = minimised(values, directions)
    n = len(v)
    keep = np.ones(n, dtype=bool)
    for i in range(n):
        better_eq = np.all(v <= v[i], axis=1)
        strictly = np.any(v < v[i], axis=1)
        keep[i] = not np.any(better_eq & strictly)
    return keep


def ranks(values: np.ndarray, directions: Sequence[str]) -> np.ndarray:
    """Non-dominated rank of each row: 1 on the front, 2 on the front of the rest, ..."""
    v = np.asarray(values, dtype=float)
    rank = np.zeros(len(v), dtype=int)
    left = np.arange(len(v))
    r = 1
    while left.size:
        mask = front_mask(v[left], directions)
        rank[left[mask]] = r
        left = left[~mask]
        r += 1
    return rank


def _spread(values: np.ndarray, directions: Sequence[str], k: int) -> list[int]:
    """``k`` rows of one front spread along it: the extremes of each objective first, then by crowding distance."""
    v = minimised(values, directions)
    n = len(v)
    if n <= k:
        return list(range(n))
    chosen: list[int] = []
    for j in range(v.shape[1]):
        for i in (int(np.argmin(v[:, j])),):
            if i not in chosen and len(chosen) < k:
                chosen.append(i)
    span = np.ptp(v, axis=0)
    span[span == 0] = 1.0
    z = v / span
    while len(chosen) < k:
        d = np.min(np.linalg.norm(z[:, None, :] - z[None, chosen, :], axis=2), axis=1)
        d[chosen] = -1.0
        chosen.append(int(np.argmax(d)))
    return chosen


def pick_for_verification(values: np.ndarray, directions: Sequence[str], k: int) -> list[int]:
    """Up to ``k`` rows near the front, for the full chain: the front first (spread along it when it holds more
    than ``k``), then the next ranks, whose cheap-model figures may be within the surrogate's error of the front."""
    r = ranks(values, directions)
    out: list[int] = []
    for level in range(1, int(r.max(initial=0)) + 1):
        idx = np.nonzero(r == level)[0]
        room = k - len(out)
        if room <= 0:
            break
        out.extend(int(idx[i]) for i in _spread(values[idx], directions, room))
    return out


def dominates_or_equals(a: Sequence[float], b: Sequence[float], directions: Sequence[str]) -> bool:
    """``a`` is at least as good as ``b`` on every objective."""
    va, vb = minimised(np.array([a]), directions)[0], minimised(np.array([b]), directions)[0]
    return bool(np.all(va <= vb))
