"""How a design variable's range or listed values meet the bounds the other choices leave
(:class:`magfab.inverse.space.Space`): the part of a range within them, the lowest allowed value at least a floor, the
listed values allowed, and the fraction of a value. Each takes numbers or arrays (element by element)."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["pick", "max_of", "span_of", "lowest_at_least", "has_value", "listed_mask", "nearest_allowed",
           "range_within", "fraction_within"]


def pick(hemi: Any, a: Any, b: Any) -> Any:
    """``a`` where ``hemi`` (a bool, or an array of them element by element), else ``b``."""
    if isinstance(hemi, (bool, np.bool_)):
        return a if hemi else b
    return np.where(hemi, a, b)


def max_of(a: Any, b: Any) -> Any:
    """Python's ``max`` of two numbers, element by element for arrays (NaN in ``b`` leaves ``a``, as ``max`` does)."""
    if np.ndim(a) == 0 and np.ndim(b) == 0:
        return max(a, b)
    return np.fmax(a, b)


def span_of(c: Any) -> tuple[float, float]:
    return float(min(c)), float(max(c))


def lowest_at_least(c: Any, floor: Any) -> Any:
    """The lowest value of a choice at or above ``floor`` (a range's: the larger of its low end and the floor); inf
    when none is. ``floor`` may be an array (element by element)."""
    f = np.asarray(floor, dtype=float)
    if isinstance(c, list):
        values = np.sort(np.asarray(c, dtype=float))
        i = np.searchsorted(values, f - 1e-9, side="left")
        out = np.where(i < len(values), values[np.minimum(i, len(values) - 1)], math.inf)
    else:
        out = np.where(f <= c[1] + 1e-12, np.maximum(c[0], f), math.inf)
    return out if out.ndim else float(out)


def has_value(c: Any, lo: float, hi: float) -> bool:
    if isinstance(c, list):
        return any(lo - 1e-9 <= x <= hi + 1e-9 for x in c)
    return max(c[0], lo) <= min(c[1], hi) + 1e-12


def listed_mask(c: list[float], lo: Any, hi: Any) -> np.ndarray:
    """Which listed values are allowed within [lo, hi] (the last axis; ``lo`` and ``hi`` may be arrays): those inside,
    or where none is, the one nearest the interval."""
    values = np.asarray(c, dtype=float)
    lo, hi = np.asarray(lo, dtype=float)[..., None], np.asarray(hi, dtype=float)[..., None]
    inside = (values >= lo - 1e-9) & (values <= hi + 1e-9)
    nearest = np.argmin(np.fmax(lo - values, values - hi), axis=-1)
    return np.where(inside.any(axis=-1, keepdims=True), inside, np.arange(len(values)) == nearest[..., None])


def nearest_allowed(c: list[float], lo: Any, hi: Any, x: np.ndarray) -> np.ndarray:
    """Listed values: the allowed one (:func:`listed_mask`) nearest each ``x`` (ties: the smaller)."""
    values = np.asarray(c, dtype=float)
    d = np.where(listed_mask(c, lo, hi), np.abs(values - x[:, None]), math.inf)
    return np.where(d == d.min(axis=-1, keepdims=True), values, math.inf).min(axis=-1)


def range_within(c: Any, lo: Any, hi: Any) -> tuple[Any, Any]:
    """A range's part within [lo, hi] (arrays allowed); where none of it is buildable, the end nearest (the design
    then fails with its reason). A bound that is not a number (no height limit less an infinite cover) leaves the
    range's end: fmax and fmin, as Python's max and min with the bound second."""
    a, b = np.fmax(c[0], lo), np.fmin(c[1], hi)
    nearest = np.fmin(np.fmax(c[0], np.fmin(lo, hi)), c[1])
    return np.where(a > b, nearest, a), np.where(a > b, nearest, b)


def fraction_within(c: Any, lo: float, hi: float, x: float) -> float:
    if isinstance(c, list):
        values = [y for y, ok in zip(c, listed_mask(c, lo, hi)) if ok]
        i = min(range(len(values)), key=lambda j: abs(values[j] - x))
        return (i + 0.5) / len(values)
    a, b = (float(y) for y in range_within(c, lo, hi))
    return 0.5 if b <= a else min(max((x - a) / (b - a), 0.0), 1.0)
