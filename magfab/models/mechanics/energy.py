"""The body's strain energy on one discretisation: its fields, residual and tangent, whether a state is
admissible (no element inverted), and the extreme stretches and stresses. Dimensionless (mu = 1, mm); no
boundary conditions (the problem that uses it imposes them).
"""

from __future__ import annotations

import numpy as np

from .discretisation import _Axisym, _sparse
from .material import _G0, _Material, _stretches

#: Radius of the neighbourhood the FE averages principal stretches over, as a fraction of the elastomer radius
#: (0.2 mm on MagOne, the magnet's edge radius there). A stretch at a point of a corner grows without bound under
#: refinement wherever the geometry keeps a re-entrant corner (the bonded base's outer edge, a sharp magnet); its
#: mean over a stated volume converges, so the range criterion built on it does too (tests/models).
STRETCH_AVERAGING_FRACTION = 1.0 / 30.0


class _Energy:
    """Total potential of the body on ``disc`` with ``material``: x holds u_r, u_z at the P2 nodes, then p.

    ``averaging_mm`` is the radius of the neighbourhood over which :meth:`extremes` averages the principal stretches
    (see :func:`_averaging`)."""

    def __init__(self, disc: _Axisym, material: _Material, averaging_mm: float = 0.0):
        self.disc, self.mat = disc, material
        self.ndof = 2 * disc.N + disc.M
        self.averaging = _averaging(disc, float(averaging_mm))

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
        """(largest and smallest principal stretch averaged over the neighbourhood of radius ``averaging_mm``, the
        largest |principal Cauchy stress| / mu and the largest principal stretch at any quadrature point)."""
        g, p = self.fields(x)
        lam = _stretches(g)
        sig = self.mat.cauchy(g, p)
        w = self.disc.w
        wsum = w.sum(axis=1)
        hi = self.averaging @ ((lam.max(axis=-1) * w).sum(axis=1) / wsum)
        lo = self.averaging @ ((lam.min(axis=-1) * w).sum(axis=1) / wsum)
        return float(hi.max()), float(lo.min()), float(np.abs(sig).max()), float(lam.max())


def _averaging(disc: _Axisym, radius_mm: float):
    """Sparse (nel x nel) operator: element values -> their volume-weighted mean over the elements whose centroids
    lie within ``radius_mm`` of each element's centroid (in the r-z plane; volumes include 2 pi r). With radius 0,
    element means. The mean over a fixed neighbourhood converges under refinement where the pointwise value at a
    corner need not (module :mod:`.fe`, range criterion)."""
    from scipy.sparse import csr_matrix, identity
    from scipy.spatial import cKDTree

    nel = disc.w.shape[0]
    if radius_mm <= 0.0:
        return identity(nel, format="csr")
    p, t = disc.mesh.p, disc.mesh.t
    c = p[:, t].mean(axis=1).T  # (nel, 2)
    pairs = cKDTree(c).query_pairs(radius_mm, output_type="ndarray")
    rows = np.concatenate([np.arange(nel), pairs[:, 0], pairs[:, 1]])
    cols = np.concatenate([np.arange(nel), pairs[:, 1], pairs[:, 0]])
    vol = disc.w.sum(axis=1)
    A = csr_matrix((vol[cols], (rows, cols)), shape=(nel, nel))
    norm = np.asarray(A.sum(axis=1)).ravel()
    return csr_matrix(A.multiply(1.0 / norm[:, None]))
