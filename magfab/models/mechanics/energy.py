"""The body's strain energy on one discretisation: its fields, residual and tangent, whether a state is
admissible (no element inverted), and the extreme stretches and stresses. Dimensionless (mu = 1, mm); no
boundary conditions (the problem that uses it imposes them).
"""

from __future__ import annotations

import numpy as np

from .discretisation import _Axisym, _sparse
from .material import _G0, _Material, _stretches

# Imported lazily, inside the functions that use them, for speed: scikit-fem and scipy take a
# noticeable time to import, and importing this module should not.

#: Radius ``a`` of the kernel the FE averages principal stretches with, as a fraction of the elastomer radius (0.2 mm
#: on MagOne, the magnet's edge radius there: the scale of the stress concentration the range criterion looks at).
#: A stretch at a point of a corner grows without bound under refinement wherever the geometry keeps a re-entrant
#: corner (the bonded base's outer edge, a sharp magnet), and the largest stretch at any quadrature point depends
#: on where the mesh puts its points; a smooth kernel mean over a stated radius converges (tests/models/
#: test_range_convergence.py: the range it ends is within 0.5 % over meshes 1 to 0.25 mm on MagOne, where the mean
#: over a ball of elements moved 5.7 % as elements entered and left it).
STRETCH_AVERAGING_FRACTION = 1.0 / 30.0


class _Energy:
    """Total potential of the body on ``disc`` with ``material``: x holds u_r, u_z at the P2 nodes, then p.

    ``averaging_mm`` is the radius of the kernel with which :meth:`extremes` averages the principal stretches (see
    :func:`_averaging`)."""

    def __init__(self, disc: _Axisym, material: _Material, averaging_mm: float = 0.0):
        self.disc, self.mat = disc, material
        self.ndof = 2 * disc.N + disc.M
        self.averaging, self.centroids = _averaging(disc, float(averaging_mm))

    def fields(self, x: np.ndarray):
        """g (nel, nq, 5) and p (nel, nq) at the quadrature points."""
        d = self.disc
        g = _G0 + np.matmul(d.B, x[d.edofs[:, None, :12, None]])[..., 0]
        p = np.matmul(d.psi, x[d.edofs[:, 12:, None]])[..., 0]
        return g, p

    def admissible(self, x: np.ndarray) -> bool:
        """No inversion: det F > 0 at every quadrature point and at every node of every (curved, deformed) P2
        element -- the in-plane determinant and the hoop stretch 1 + u_r / r (on the axis the hoop stretch is F_rr,
        which the in-plane check covers)."""
        g, _ = self.fields(x)
        det2 = g[..., 0] * g[..., 3] - g[..., 1] * g[..., 2]
        if not (np.all(det2 > 0) and np.all(g[..., 4] > 0) and np.all(np.isfinite(g))):
            return False
        d = self.disc
        e = d.edofs[:, :6]
        ur, uz = x[e], x[d.N + e]  # (nel, 6)
        Gr = np.einsum("enkb,eb->enk", d.node_grad, ur)  # (nel, nodes, 2): du_r/dr, du_r/dz
        Gz = np.einsum("enkb,eb->enk", d.node_grad, uz)
        det_nodes = (1.0 + Gr[..., 0]) * (1.0 + Gz[..., 1]) - Gr[..., 1] * Gz[..., 0]
        hoop = 1.0 + ur * d.node_inv_r
        return bool(np.all(det_nodes > 0) and np.all(hoop > 0))

    def assemble(self, x: np.ndarray):
        """Residual (ndof,) and tangent (sparse) at x: R = dPi/dx, K = d2Pi/dx2."""
        d = self.disc
        g, p = self.fields(x)
        S, D, j, J, _ = self.mat.response(g, p)
        w = d.w
        nel, nq = w.shape
        Bt = d.Bt  # (nel, 12, nq * 5)
        Ru = np.matmul(Bt, (S * w[..., None]).reshape(nel, nq * 5, 1))[..., 0]
        Rp = np.matmul(d.psi_t, ((J - 1.0) * w)[..., None])[..., 0]
        R = np.bincount(d.edofs.ravel(), weights=np.concatenate([Ru, Rp], axis=1).ravel(), minlength=self.ndof)
        Dj = np.empty((nel, nq, 6, 5))  # rows: D w, then (dJ/dg) w -- one product with B gives D B w and B^T j w
        np.multiply(D, w[..., None, None], out=Dj[:, :, :5])
        np.multiply(j, w[..., None], out=Dj[:, :, 5])
        DjB = np.matmul(Dj, d.B)  # (nel, nq, 6, 12)
        ke = np.empty((nel, 15, 15))
        np.matmul(Bt, DjB[:, :, :5].reshape(nel, nq * 5, 12), out=ke[:, :12, :12])
        np.matmul(DjB[:, :, 5].transpose(0, 2, 1), d.psi, out=ke[:, :12, 12:])  # (nel, 12, 3)
        ke[:, 12:, :12] = ke[:, :12, 12:].transpose(0, 2, 1)
        ke[:, 12:, 12:] = 0.0
        return R, _sparse(d.pattern, ke)

    def extremes(self, x: np.ndarray) -> tuple[float, float, float, float]:
        """(largest and smallest kernel-averaged principal stretch (:func:`_averaging`) over the element centroids,
        the largest |principal Cauchy stress| / mu and the largest principal stretch at any quadrature point)."""
        g, p = self.fields(x)
        lam = _stretches(g)
        sig = self.mat.cauchy(g, p)
        mean = self.averaging @ np.stack([lam.max(axis=-1).ravel(), lam.min(axis=-1).ravel()], axis=1)
        return float(mean[:, 0].max()), float(mean[:, 1].min()), float(np.abs(sig).max()), float(lam.max())

    def stretch_peak(self, x: np.ndarray) -> tuple[float, float, float]:
        """(largest kernel-averaged principal stretch, and the r, z in mm of the element centroid where it is)."""
        g, _ = self.fields(x)
        hi = self.averaging @ _stretches(g).max(axis=-1).ravel()
        k = int(np.argmax(hi))
        return float(hi[k]), float(self.centroids[k, 0]), float(self.centroids[k, 1])


def _kernel(s: np.ndarray) -> np.ndarray:
    """The averaging kernel k(s) = (1 - s^2)^3 on s = distance / radius in [0, 1], 0 beyond: smooth (its value and
    first two derivatives vanish at s = 1), so a quadrature point entering the support as the mesh changes adds a
    weight that starts at zero, where a ball's indicator would add it whole."""
    t = np.clip(1.0 - s * s, 0.0, None)
    return t * t * t


def _quadrature_points(disc: _Axisym) -> np.ndarray:
    """(nel, nq, 2) r, z in mm of the quadrature points of ``disc`` (scikit-fem's order-4 rule on the straight
    triangles, the rule :mod:`.discretisation` integrates with)."""
    from skfem.quadrature import get_quadrature
    from skfem.refdom import RefTri

    X, _ = get_quadrature(RefTri, 4)
    p, t = disc.mesh.p, disc.mesh.t
    p0 = p[:, t[0]].T[:, None, :]
    e1, e2 = (p[:, t[1]] - p[:, t[0]]).T[:, None, :], (p[:, t[2]] - p[:, t[0]]).T[:, None, :]
    return p0 + X[0][None, :, None] * e1 + X[1][None, :, None] * e2


#: Side of the cells the quadrature points are gathered into before the kernel mean, as a fraction of its radius:
#: each cell enters as one point (its weighted centroid) carrying its weight and weighted mean, which bounds the
#: operator's cost on finely refined meshes (a cell within the kernel, not every quadrature point, per sample: at
#: most ~800) and changes the mean by O((1/16)^2) of its local variation.
GATHER_FRACTION = 1.0 / 16.0


class _KernelMean:
    """Values at the quadrature points (flattened element by element) -> their kernel means at the samples:
    ``self @ v`` = K @ (G @ v), G the cells' weighted means of the points they gather, K the normalised kernel
    weights of the cells at each sample (both sparse)."""

    def __init__(self, K, G):
        self.K, self.G = K, G

    def __matmul__(self, v: np.ndarray) -> np.ndarray:
        return self.K @ (self.G @ v)


def _averaging(disc: _Axisym, radius_mm: float):
    """(A, centroids): A (:class:`_KernelMean`) takes values at the quadrature points to their kernel-weighted
    means at the element centroids (nel, 2 in r, z mm):

        mean(c) = sum_q w_q k(|x_q - c| / a) v_q / sum_q w_q k(|x_q - c| / a),   a = ``radius_mm``,

    with w_q the quadrature weights (volumes, including 2 pi r) and k :func:`_kernel`; the points are first gathered
    into square cells of side :data:`GATHER_FRACTION` a (each cell at its weighted centroid, with its total weight
    and weighted mean). The mean is a smooth function of c, and its integrals converge under refinement; the mesh
    sets only where it is sampled, and the elements are small (a third of a or less) where the stretch peaks, at
    the magnet's resolved edges. A centroid whose kernel holds no cell (an element wider than 2 a) takes its own
    element's mean, as does every centroid with radius 0."""
    from scipy.sparse import csr_matrix
    from scipy.spatial import cKDTree

    w = disc.w
    nel, nq = w.shape
    wq = w.ravel()
    q = _quadrature_points(disc).reshape(-1, 2)
    c = disc.mesh.p[:, disc.mesh.t].mean(axis=1).T  # (nel, 2)
    own = csr_matrix((wq / np.repeat(w.sum(axis=1), nq), (np.repeat(np.arange(nel), nq), np.arange(nel * nq))),
                     shape=(nel, nel * nq))  # each element's weighted mean
    if radius_mm <= 0.0:
        return _KernelMean(csr_matrix((np.ones(nel), (np.arange(nel), np.arange(nel))), shape=(nel, nel)), own), c
    _, cell = np.unique(np.floor(q / (GATHER_FRACTION * radius_mm)).astype(np.int64), axis=0, return_inverse=True)
    cell = cell.ravel()
    ncell = int(cell.max()) + 1
    cw = np.bincount(cell, weights=wq, minlength=ncell)
    cx = np.column_stack([np.bincount(cell, weights=wq * q[:, i], minlength=ncell) for i in (0, 1)]) / cw[:, None]
    gather = csr_matrix((wq / cw[cell], (cell, np.arange(nel * nq))), shape=(ncell, nel * nq))
    near = cKDTree(c).sparse_distance_matrix(cKDTree(cx), radius_mm, output_type="ndarray")
    rows, cols = near["i"].astype(np.int64), near["j"].astype(np.int64)
    vals = _kernel(near["v"] / radius_mm) * cw[cols]
    keep = vals > 0.0
    rows, cols, vals = rows[keep], cols[keep], vals[keep]
    norm = np.bincount(rows, weights=vals, minlength=nel)
    K = csr_matrix((vals / norm[rows], (rows, cols)), shape=(nel, ncell))
    empty = norm == 0.0  # no cell inside its kernel: the element's own mean
    if np.any(empty):
        sel = csr_matrix((np.ones(int(empty.sum())), (np.nonzero(empty)[0], np.arange(int(empty.sum())))),
                         shape=(nel, int(empty.sum())))
        from scipy.sparse import hstack, vstack

        return _KernelMean(hstack([K, sel], format="csr"), vstack([gather, own[empty]], format="csr")), c
    return _KernelMean(K, gather), c
