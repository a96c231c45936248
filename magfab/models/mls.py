"""Moving least squares (docs/models.md, M13), the kernel of the calibration's host-only accurate option
(:mod:`magfab.models.calibration`): at each query a polynomial in the local scaled coordinates, fitted with Gaussian
weights, its constant term the value; and the monomials both that and the global polynomial are made of."""

from __future__ import annotations

import functools

import numpy as np

__all__ = ["monomials", "mls"]


def monomials(order: int) -> list[tuple[int, int]]:
    """Exponents (i, j) of u^i v^j, docs/bundle.md order: for k = 0..n, for i = k down to 0: (i, k - i)."""
    return [(i, k - i) for k in range(order + 1) for i in range(k, -1, -1)]



#: Queries x scan points per block of :func:`mls` (its arrays then stay in the processor's cache).
_MLS_BLOCK_CELLS = 1 << 15
#: The exponent below which :func:`mls` takes a weight as exactly 0: exp of it is the smallest normal double,
#: 2.2e-308. Below it exp returns subnormals (and exactly 0 below -745.1), on which the processor is tens of
#: times slower, in exp and in every product after it; such a weight is ~300 decades below the ridge (1e-12 of
#: the nearest point's weight, 1), so it changes nothing but rounding.
_MLS_EXP_FLOOR = float(np.log(np.finfo(float).tiny))


@functools.cache
def _mls_layout(order: int) -> tuple[tuple[tuple[int, int, int], ...], tuple[int, ...], np.ndarray]:
    """:func:`mls`'s bookkeeping for ``order``, rows numbered as :func:`monomials`: the products that build each
    monomial of degree >= 2 from a lower one, (row, lower row, row of du or dv); the rows of the degree-``order``
    monomials t whose weighted values give the moments above degree ``order`` as sum w p_i t (pure powers
    first: order 2 needs only du^2 and dv^2); and the (m, m) table of where each normal-matrix entry
    sum w p_i p_j is found in the flattened (m, 1 + len(tops)) block [sum w p_i, sum w p_i t, ...]."""
    mono = monomials(order)
    row = {e: i for i, e in enumerate(mono)}
    steps = tuple((row[(a, b)], row[(a - 1, b)] if a else row[(a, b - 1)], row[(1, 0)] if a else row[(0, 1)])
                  for a, b in mono if a + b >= 2)
    highest = sorted((e for e in mono if sum(e) == order), key=min)
    tops: list[tuple[int, int]] = []
    where = {e: (i, 0) for i, e in enumerate(mono)}
    for d in range(order + 1, 2 * order + 1):
        for a in range(d, -1, -1):
            b = d - a
            t = next(t for t in tops + highest if t[0] <= a and t[1] <= b)
            if t not in tops:
                tops.append(t)
            where[(a, b)] = (row[(a - t[0], b - t[1])], 1 + tops.index(t))
    flat = {e: i * (1 + len(tops)) + c for e, (i, c) in where.items()}
    index = np.array([[flat[(a + c, b + d)] for c, d in mono] for a, b in mono])
    return steps, tuple(row[t] for t in tops), index


def mls(u: np.ndarray, v: np.ndarray, y: np.ndarray, uq: np.ndarray, vq: np.ndarray, order: int,
         h: float) -> np.ndarray:
    """Moving least squares at (uq, vq) (Q,) from data (u, v) (N,), y (N, k): (Q, k).

    At each query a polynomial of ``order`` in the local coordinates ((u - uq)/h, (v - vq)/h) is fitted
    with weights exp(-d^2 / 2h^2); its constant term is the value. Weights are taken relative to the
    nearest point's, so a query far outside the data still gets a (flagged) answer rather than 0/0; those
    below 2.2e-308 of it are 0 (:data:`_MLS_EXP_FLOOR`). The normal equations get a ridge of 1e-12 times their
    trace and are solved.

    How: the normal matrix's entries sum w p_i p_j over the scan points are the weighted moments
    sum w du^a dv^b, a + b <= 2 order (15 distinct for order 2, not 36), and the right-hand side is
    sum w p_i y. For a block of queries the local monomials p (q, m, N) are built once, unweighted, and one
    batched product of p with [w, w t..., w y...] (:func:`_mls_layout`'s degree-``order`` monomials t) gives
    every moment and the right-hand side; the (Q, m, m) systems are assembled from the moments at the end.
    """
    steps, tops, index = _mls_layout(order)
    m, n, k, nq = len(monomials(order)), len(u), y.shape[1], len(uq)
    if nq == 0:
        return np.empty((0, k))
    us, vs = np.asarray(u, dtype=float) / h, np.asarray(v, dtype=float) / h
    uqs, vqs = np.asarray(uq, dtype=float) / h, np.asarray(vq, dtype=float) / h
    yt = np.asarray(y, dtype=float).T
    width = 1 + len(tops)  # columns [w, w t...] of the moments; then [w y...] of the right-hand side
    sums = np.empty((nq, m, width + k))
    block = max(1, min(nq, _MLS_BLOCK_CELLS // max(1, n)))
    p_all = np.empty((block, max(m, 3), n))  # order 0 still needs rows 1 and 2: du, dv
    p_all[:, 0] = 1.0
    wp_all = np.empty((block, width + k, n))
    x_all = np.empty((block, n))
    keep_all = np.empty((block, n), dtype=bool)
    for s in range(0, nq, block):
        e = min(nq, s + block)
        p, wp, x, keep = p_all[:e - s], wp_all[:e - s], x_all[:e - s], keep_all[:e - s]
        du, dv, w = p[:, 1], p[:, 2], wp[:, 0]
        np.subtract(us, uqs[s:e, None], out=du)
        np.subtract(vs, vqs[s:e, None], out=dv)
        for i, lower, axis in steps:
            np.multiply(p[:, lower], p[:, axis], out=p[:, i])
        if order >= 2:  # d^2 = du^2 + dv^2, already rows 3 and 5
            np.add(p[:, 3], p[:, 5], out=x)
        else:
            np.multiply(du, du, out=x)
            x += dv * dv
        nearest = x.min(axis=1)
        x -= nearest[:, None]
        x *= -0.5
        np.greater_equal(x, _MLS_EXP_FLOOR, out=keep)
        w.fill(0.0)
        np.exp(x, out=w, where=keep)
        w[np.isnan(nearest)] = np.nan  # a NaN coordinate gives NaN, as exp would, not a singular system
        for c, t in enumerate(tops, 1):
            np.multiply(w, p[:, t], out=wp[:, c])
        np.multiply(w[:, None, :], yt, out=wp[:, width:])
        np.matmul(p[:, :m], wp.transpose(0, 2, 1), out=sums[s:e])
    normal = sums[:, :, :width].reshape(nq, m * width)[:, index]
    normal += (1e-12 * np.trace(normal, axis1=1, axis2=2))[:, None, None] * np.eye(m)
    return np.linalg.solve(normal, sums[:, :, width:])[:, 0, :]
