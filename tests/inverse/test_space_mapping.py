"""The search's mapping of many designs at once (:meth:`Space.mm`, what the model step maps its ~2,000 candidates a
proposal with) against a reference written here one design at a time, as the mapping was before it was vectorised:
plain Python floats, the rules of :class:`Space`'s docstring, the bounds from the space's own methods called with
floats. Drawn over the bench target sets, with listed values and with no height limit, fractions at their ends and
listed values off their list and halfway between two, many combinations of magnet and tip in one batch."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab.inverse.propose import _numeric_axes, _params, _physical, _physical_of, _snap
from magfab.inverse.space import FRACTION_OF, MAGNET_FRACTION, NUMERIC, Space
from magfab.inverse.targets import load_targets

BENCH = Path(__file__).resolve().parents[2] / "bench" / "targets"


def _spaces() -> dict[str, Space]:
    out = {}
    for name in ("fingertip", "taxel", "stiff_pad"):
        targets, base = load_targets(BENCH / f"{name}.toml")
        v, r = targets.variables, targets.require
        out[name] = Space(targets, base)
        listed = v.model_copy(update={"d_max_mm": sorted({v.d_max_mm[0], sum(v.d_max_mm) / 2, v.d_max_mm[1]}),
                                      "cover_mm": [v.cover_mm[0], 1.0, v.cover_mm[1]]})
        out[f"{name}, listed"] = Space(targets.model_copy(update={"variables": listed}), base)
        out[f"{name}, no height limit"] = Space(targets.model_copy(
            update={"require": r.model_copy(update={"max_height_mm": None})}), base)
    return out


SPACES = _spaces()


def _value(c, lo: float, hi: float, x: float) -> float:
    """One variable's mm value, the rules of Space.point with Python's own max and min: a range's part within
    [lo, hi] (its nearest end where none is) at fraction x; a listed value moved to the nearest allowed (those
    within [lo, hi], or the one nearest it)."""
    if isinstance(c, list):
        allowed = [y for y in c if lo - 1e-9 <= y <= hi + 1e-9] or [min(c, key=lambda y: max(lo - y, y - hi))]
        return min(allowed, key=lambda y: (abs(y - x), y))
    a, b = max(c[0], lo), min(c[1], hi)
    if a > b:
        a = b = min(max(c[0], min(lo, hi)), c[1])
    return a + min(max(x, 0.0), 1.0) * (b - a)


def _reference(space: Space, params: dict) -> list[float]:
    tip = params["tip"]
    order = space.magnet_order[tip]
    magnet = order[min(int(min(max(params[MAGNET_FRACTION], 0.0), 1.0) * len(order)), len(order) - 1)]
    v = space.variables

    def value(name, lo, hi):
        c = getattr(v, name)
        return _value(c, float(lo), float(hi), params[name if isinstance(c, list) else FRACTION_OF[name]])

    d_e = value("elastomer_diameter_mm", *(space.diameter_range(magnet, tip) or (min(v.elastomer_diameter_mm),
                                                                                   max(v.elastomer_diameter_mm))))
    d_max = value("d_max_mm", *space.d_max_bounds(magnet, tip, d_e))
    cover = value("cover_mm", *space.cover_bounds(magnet, tip, d_e, d_max))
    d_min = value("d_min_mm", *space.d_min_bounds(magnet, d_max))
    return [d_max, d_min, d_e, cover]


fraction = st.one_of(st.sampled_from([0.0, 1.0]), st.floats(0.0, 1.0))


@st.composite
def _batch(draw):
    name = draw(st.sampled_from(sorted(SPACES)))
    space = SPACES[name]
    rows = []
    for _ in range(draw(st.integers(1, 40))):
        material, tip = draw(st.sampled_from(space.pairs()))
        p = {"material": material, "tip": tip, MAGNET_FRACTION: draw(fraction)}
        for var in NUMERIC:
            c = getattr(space.variables, var)
            midpoints = [(a + b) / 2 for a, b in itertools.pairwise(c)] or c  # a tie between two values
            p.update({var: draw(st.one_of(st.sampled_from(c), st.sampled_from(midpoints),
                                          st.floats(min(c) - 1.0, max(c) + 1.0)))}
                     if isinstance(c, list) else {FRACTION_OF[var]: draw(fraction)})
        rows.append(p)
    return name, rows


@settings(max_examples=300, deadline=None)
@given(_batch())
def test_the_batch_mapping_is_the_one_design_mapping(drawn):
    name, rows = drawn
    space = SPACES[name]
    mm = _physical_of(space, rows)  # through Space.mm, every row in one batch
    lo, width = _spans_of(space)
    got = mm[:, 3:3 + len(NUMERIC)] * width[3:] + lo[3:]
    want = np.array([_reference(space, p) for p in rows])
    # Python's float ** 2 and numpy's square differ in the last place at a few points (a hemisphere's cover floor)
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)
    for p, one in zip(rows, want):  # and the one-design mapping is the batch's
        point = space.point(p)
        np.testing.assert_allclose([point[k] for k in NUMERIC], one, rtol=1e-12, atol=1e-12)


def _spans_of(space: Space):
    from magfab.inverse.propose import _spans

    return _spans(space)


@settings(max_examples=100, deadline=None)
@given(st.sampled_from(sorted(SPACES)), st.integers(0, 2**32 - 1))
def test_candidates_from_arrays_are_their_params(name, seed):
    """The model step scores candidates from their unit coordinates (no params built); the candidate it returns is
    built from the same coordinates as params: both give one design."""
    space = SPACES[name]
    axes = _numeric_axes(space)
    rng = np.random.default_rng(seed)
    cu = _snap(axes, rng.random((50, 1 + len(axes))))
    cp = rng.integers(len(space.pairs()), size=50)
    numeric = {param: cu[:, j] if values is None else np.asarray(values)[np.argmin(
        np.abs(cu[:, j, None] - (np.asarray(values) - values[0]) / max(values[-1] - values[0], 1e-300)), axis=1)]
        for j, (param, values) in enumerate(axes.values(), start=1)}
    from_arrays = _physical(space, cp, cu[:, 0], numeric)
    from_params = _physical_of(space, [_params(space, axes, cu[i], int(cp[i])) for i in range(len(cu))])
    np.testing.assert_array_equal(from_arrays, from_params)
