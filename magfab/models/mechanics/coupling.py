"""Mechanical coupling in a continuous skin: how far a load over one taxel moves a neighbour's magnet.

The model a pitch decision needs is small-strain and linear: the coupling is the ratio of two displacements
at small load, so neither the load nor the shear modulus enters, and what matters is the layer's thickness
and that it is bonded to a rigid pad. The skin is taken as a flat layer of the tips' height bonded at its base,
loaded by a point force on its top over taxel i; the magnet of a taxel at distance r sits at the magnet's
depth under the top. The ratio

    c(r) = u_z(r, depth) / u_z(0, depth)

is the fraction of taxel i's own magnet travel that a neighbour's magnet makes. A flat layer holds more silicone
between the taxels than the skin, whose domes dip to the base height between them, so it errs on the side of
more coupling (an upper bound for the pitch decision).

Solved with scikit-fem on the axisymmetric layer about the loaded taxel (a neighbour at distance r sees the ring
at r): quadratic triangles in (r, z), graded from the load outwards, nearly incompressible (Poisson 0.49, as
silicone rubbers are). Checked against
Boussinesq's half-space solution for a layer much thicker than r and depth (tests/models/test_crosstalk.py), and by
mesh refinement.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Imported lazily, inside the functions that use them, for speed: scikit-fem and scipy take a
# noticeable time to import, and importing this module should not.

__all__ = ["Coupling", "coupling", "boussinesq_ratio", "POISSON"]

#: Poisson's ratio of the layer: silicone rubber is nearly incompressible (0.49-0.5); 0.49 keeps quadratic
#: triangles free of volumetric locking.
POISSON = 0.49


@dataclass(frozen=True)
class Coupling:
    """c(r) sampled on ``r_mm`` (0 first: 1 there) for a layer ``thickness_mm`` thick, magnets ``depth_mm`` deep."""

    r_mm: np.ndarray
    ratio: np.ndarray
    thickness_mm: float
    depth_mm: float
    dofs: int

    def at(self, r_mm: float | np.ndarray) -> np.ndarray:
        """c at ``r_mm`` (linear between samples; beyond the last, the last sample scaled as 1/r, the half-space's
        far field, which overstates a bonded layer's)."""
        r = np.asarray(r_mm, dtype=float)
        inside = np.interp(r, self.r_mm, self.ratio)
        far = self.ratio[-1] * self.r_mm[-1] / np.maximum(r, 1e-9)
        return np.where(r <= self.r_mm[-1], inside, far)


def boussinesq_ratio(r_mm: np.ndarray, depth_mm: float, nu: float = POISSON) -> np.ndarray:
    """The same ratio in an elastic half-space under a point force (Boussinesq): u_z is proportional to
    z^2 / R^3 + 2 (1 - nu) / R, R = sqrt(r^2 + z^2)."""
    r = np.asarray(r_mm, dtype=float)
    R = np.hypot(r, depth_mm)
    u = depth_mm**2 / R**3 + 2.0 * (1.0 - nu) / R
    return u / (1.0 / depth_mm + 2.0 * (1.0 - nu) / depth_mm)


def _graded(length: float, first: float, growth: float) -> np.ndarray:
    """Node coordinates from 0 to ``length``: the first cell ``first`` long, each next ``growth`` times longer."""
    xs, step = [0.0], first
    while xs[-1] + step < length:
        xs.append(xs[-1] + step)
        step *= growth
    xs.append(length)
    if xs[-1] - xs[-2] < 0.3 * step / growth:
        xs.pop(-2)
    return np.array(xs)


def coupling(thickness_mm: float, depth_mm: float, reach_mm: float, cell_mm: float = 0.1,
             growth: float = 1.15) -> Coupling:
    """Solve the layer out to ``reach_mm`` (plus a margin of three thicknesses, a free edge) and sample c(r) at the
    magnets' depth. ``cell_mm``: the cells at the load, growing by ``growth`` away from it."""
    import skfem
    from scipy.sparse.linalg import spsolve

    H = thickness_mm
    L = reach_mm + 3.0 * H
    rs = np.unique(np.concatenate([_graded(L, cell_mm, growth), np.linspace(0.0, reach_mm, 8 * int(reach_mm) + 1)]))
    zs = np.unique(np.round(np.concatenate([H - _graded(H, cell_mm, growth)[::-1], [H - depth_mm]]), 12))
    mesh = skfem.MeshTri.init_tensor(rs, zs)
    basis = skfem.Basis(mesh, skfem.ElementVector(skfem.ElementTriP2()))
    lam = POISSON / ((1 + POISSON) * (1 - 2 * POISSON))  # Young's modulus 1: ratios only
    mu = 0.5 / (1 + POISSON)

    @skfem.BilinearForm
    def stiffness(u, v, w):
        r = w.x[0]
        # axisymmetric strains: e_rr, e_zz, e_tt = u_r / r, e_rz; the volume element 2 pi r (2 pi dropped)
        urr, uzz, utt = u.grad[0][0], u.grad[1][1], u[0] / r
        vrr, vzz, vtt = v.grad[0][0], v.grad[1][1], v[0] / r
        urz, vrz = 0.5 * (u.grad[0][1] + u.grad[1][0]), 0.5 * (v.grad[0][1] + v.grad[1][0])
        return (lam * (urr + uzz + utt) * (vrr + vzz + vtt)
                + 2.0 * mu * (urr * vrr + uzz * vzz + utt * vtt + 2.0 * urz * vrz)) * r

    K = stiffness.assemble(basis)
    f = np.zeros(basis.N)
    apex = np.flatnonzero((mesh.p[0] < 1e-9) & (mesh.p[1] > H - 1e-9))
    f[basis.nodal_dofs[1][apex]] = -1.0  # the force on the axis, at the top
    fixed = np.concatenate([basis.get_dofs(lambda x: x[1] < 1e-9).all(),
                            basis.get_dofs(lambda x: x[0] < 1e-9).nodal["u^1"]])
    u = skfem.solve(*skfem.condense(K, f, D=np.unique(fixed)), solver=spsolve)
    uz = u[basis.nodal_dofs[1]]
    line = (np.abs(mesh.p[1] - (H - depth_mm)) < 1e-9) & (mesh.p[0] <= reach_mm + 1e-9)
    order = np.argsort(mesh.p[0, line])
    r, w = mesh.p[0, line][order], uz[line][order]
    return Coupling(r, w / w[0], H, depth_mm, int(basis.N))
