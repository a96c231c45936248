"""The body's strain energy on one discretisation: its fields, residual and tangent, whether a state is
admissible (no element inverted), and the extreme stretches and stresses. Dimensionless (mu = 1, mm); no
boundary conditions (the problem that uses it imposes them).
"""

from __future__ import annotations

import numpy as np

from .discretisation import _Axisym, _sparse
from .material import _G0, _Material, _stretches


class _Energy:
    """Total potential of the body on ``disc`` with ``material``: x holds u_r, u_z at the P2 nodes, then p."""

    def __init__(self, disc: _Axisym, material: _Material):
        self.disc, self.mat = disc, material
        self.ndof = 2 * disc.N + disc.M

    def fields(self, x: np.ndarray):
        """g (nel, nq, 5) and p (nel, nq) at the quadrature points."""
        d = self.disc
        g = _G0 + np.matmul(d.B, x[d.edofs[:, None, :12, None]])[..., 0]
        p = np.matmul(d.psi, x[d.edofs[:, 12:, None]])[..., 0]
        return g, p

    def admissible(self, x: np.ndarray) -> bool:
        """No inversion: det of the in-plane block, the hoop stretch and every deformed corner triangle > 0."""
        g, _ = self.fields(x)
        det2 = g[..., 0] * g[..., 3] - g[..., 1] * g[..., 2]
        if not (np.all(det2 > 0) and np.all(g[..., 4] > 0) and np.all(np.isfinite(g))):
            return False
        d = self.disc
        corners = d.corner_r
        pr = d.mesh.p[0][corners] + x[corners]
        pz = d.mesh.p[1][corners] + x[d.N + corners]
        area = (pr[:, 1] - pr[:, 0]) * (pz[:, 2] - pz[:, 0]) - (pz[:, 1] - pz[:, 0]) * (pr[:, 2] - pr[:, 0])
        return bool(np.all(area > 0))

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
        R = np.bincount(d.edofs.ravel(), weights=np.hstack([Ru, Rp]).ravel(), minlength=self.ndof)
        DB = np.matmul(D * w[..., None, None], d.B).reshape(nel, nq * 5, 12)
        ke = np.zeros((nel, 15, 15))
        ke[:, :12, :12] = np.matmul(Bt, DB)
        jpsi = (j * w[..., None])[..., :, None] * d.psi[:, :, None, :]  # (nel, nq, 5, 3)
        Kup = np.matmul(Bt, jpsi.reshape(nel, nq * 5, 3))
        ke[:, :12, 12:] = Kup
        ke[:, 12:, :12] = np.transpose(Kup, (0, 2, 1))
        return R, _sparse(d.pattern, ke)

    def extremes(self, x: np.ndarray) -> tuple[float, float, float]:
        """(largest principal stretch, smallest principal stretch, largest |principal Cauchy stress| / mu)."""
        g, p = self.fields(x)
        lam = _stretches(g)
        sig = self.mat.cauchy(g, p)
        return float(lam.max()), float(lam.min()), float(np.abs(sig).max())
