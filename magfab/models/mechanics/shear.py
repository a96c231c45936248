"""Shear stiffness at the magnet: Timoshenko's closed form for the column below the magnet, or a small-strain
Fourier-mode-1 FE of the same axisymmetric body under a lateral load on the magnet, at rest.

The bench loads through the surface under a normal preload, and the magnet tilts: :mod:`.shear_surface` (the same
mode-1 FE linearised about the preloaded state, loaded through the contact patch; at rest and loaded on the magnet
it is this one, which its tests pin).

Lengths in mm, moduli in kPa, stiffness in N/mm.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from ...units import N_PER_KPA_MM2
from .body import Body, MechanicsError, _check_mu, _newton_per_mu_mm2, check_option
from .discretisation import _pattern, _scalar_p2, _sparse
from .indentation import _factor
from .mesh import _AXIS, _BASE, _MAGNET, _body_mesh, _Mesh, mesh_size
from .options import ShearEnds, ShearModel

# Imported lazily, inside the functions that use it, for speed: scipy takes a
# noticeable time to import, and importing this module should not.

__all__ = ["shear_stiffness", "shear_compliance", "SHEAR_MODELS"]

#: Shear models by name, for shear_stiffness(model=...).
SHEAR_MODELS = tuple(m.value for m in ShearModel)


def _timoshenko_shear(body: Body, mu_kPa: float, ends: ShearEnds) -> float:
    """G A / h / (1 + c h^2 / (9 R^2)) in N/mm for the column of height h = magnet_z below the magnet; c = 4 with
    the magnet free to tilt, 1 with it guided (docs/models.md, M17)."""
    h, R = body.magnet_z_mm, body.radius_mm
    c = 4.0 if ends == ShearEnds.FREE else 1.0
    return mu_kPa * N_PER_KPA_MM2 * body.area_mm2 / h / (1.0 + c * h * h / (9.0 * R * R))


@lru_cache(maxsize=8)
def _mode1_matrix(mesh: _Mesh):
    """Small-strain, incompressible, Fourier mode-1 stiffness (mu = 1, mm) of the axisymmetric body.

    Displacement u_r = U_r cos(t), u_t = -U_t sin(t), u_z = U_z cos(t); pressure P cos(t). Strain amplitudes
    (e_rr, e_tt, e_zz, g_rz, g_rt, g_tz) = (U_r,r, (U_r-U_t)/r, U_z,z, U_r,z + U_z,r, U_t,r + (U_r-U_t)/r,
    U_t,z + U_z/r); energy pi * integral of [e_rr^2 + e_tt^2 + e_zz^2 + (g_rz^2 + g_rt^2 + g_tz^2)/2] r dr dz
    with the constraint that the divergence e_rr + e_tt + e_zz vanishes (P as its multiplier).
    """
    _m, sb, pb, phi, grad, psi, rq, tags = _scalar_p2(mesh)
    nel, nq = rq.shape
    B = np.zeros((nel, nq, 6, 18))
    ur, ut, uz = slice(0, 6), slice(6, 12), slice(12, 18)
    inv_r = phi / rq[..., None]
    B[:, :, 0, ur] = grad[0]
    B[:, :, 1, ur] = inv_r
    B[:, :, 1, ut] = -inv_r
    B[:, :, 2, uz] = grad[1]
    B[:, :, 3, ur] = grad[1]
    B[:, :, 3, uz] = grad[0]
    B[:, :, 4, ut] = grad[0] - inv_r
    B[:, :, 4, ur] = inv_r
    B[:, :, 5, ut] = grad[1]
    B[:, :, 5, uz] = inv_r
    w = sb.dx * math.pi * rq
    C = np.array([2.0, 2.0, 2.0, 1.0, 1.0, 1.0])
    Kuu = np.einsum("eqia,eqib->eab", B, B * (C[None, None, :, None] * w[..., None, None]))
    div = B[:, :, 0] + B[:, :, 1] + B[:, :, 2]  # (nel, nq, 18)
    Kup = np.einsum("eqa,eqk->eak", div * w[..., None], psi)
    N, M = sb.N, pb.N
    ed = sb.element_dofs.T
    edofs = np.hstack([ed, N + ed, 2 * N + ed, 3 * N + pb.element_dofs.T])
    ke = np.zeros((nel, 21, 21))
    ke[:, :18, :18] = Kuu
    ke[:, :18, 18:] = Kup
    ke[:, 18:, :18] = np.transpose(Kup, (0, 2, 1))
    return _sparse(_pattern(edofs), ke), N, M, tags, sb.doflocs


def _fe_shear(body: Body, mesh_mm: float | None, ends: ShearEnds) -> float:
    """Lateral force on the magnet per unit lateral displacement of its lower-face centre, mu * mm (mu = 1)."""
    from scipy.sparse import csr_matrix

    if not body.has_magnet:
        raise MechanicsError("shear: the FE shear load is applied to the magnet; the body has none")
    K, N, M, tags, loc = _mode1_matrix(_body_mesh(body, mesh_size(body, mesh_mm)))
    nd = 3 * N + M
    r, z = loc
    axis = (tags & _AXIS) != 0
    base = (tags & _BASE) != 0
    mag = ((tags & _MAGNET) != 0) & ~base
    # Rigid magnet: U_r = U_t = s + phi (z - z_m), U_z = -phi r. Axis: U_z = 0, U_t tied to U_r. Base: zero.
    free_r = ~base & ~mag
    free_tz = free_r & ~axis
    idx = np.arange(N)
    free = np.concatenate([idx[free_r], N + idx[free_tz], 2 * N + idx[free_tz], 3 * N + np.arange(M)])
    col = np.full(nd, -1)
    col[free] = np.arange(free.size)
    tie = idx[axis & free_r]  # U_t on the axis follows U_r
    rows = [free, N + tie]
    cols = [col[free], col[tie]]
    vals = [np.ones(free.size), np.ones(tie.size)]
    n = free.size
    s_vec = np.zeros(nd)  # prescribed lateral translation s = 1
    s_vec[idx[mag]] = 1.0
    s_vec[N + idx[mag]] = 1.0
    phi_vec = np.zeros(nd)  # tilt about the lower face's centre
    phi_vec[idx[mag]] = z[mag] - body.magnet_z_mm
    phi_vec[N + idx[mag]] = z[mag] - body.magnet_z_mm
    phi_vec[2 * N + idx[mag]] = -r[mag]
    if ends == ShearEnds.FREE:
        nz = np.nonzero(phi_vec)[0]
        rows.append(nz)
        cols.append(np.full(nz.size, n))
        vals.append(phi_vec[nz])
        n += 1
    T = csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(nd, n))
    y = _factor(T.T @ K @ T).solve(-(T.T @ (K @ s_vec)))  # sparse LDL^T (QDLDL), as the indentation FE
    x = T @ y + s_vec
    return float(s_vec @ (K @ x))


def shear_stiffness(body: Body, mu_kPa: float, model: ShearModel | str = ShearModel.TIMOSHENKO,
                    ends: ShearEnds | str = ShearEnds.FREE, mesh_mm: float | None = None) -> float:
    """Lateral stiffness at the magnet, N/mm: lateral force on the magnet per unit lateral displacement of the
    centre of its lower face, for a small displacement.

    ``ends``: "free" (the magnet tilts freely: force through the lower-face centre, no moment) or "guided" (the
    magnet held level). ``model``: "timoshenko", the column of radius R and height magnet_z below the magnet,
    G A / h / (1 + c h^2/(9 R^2)) with c = 4 (free) or 1 (guided); or "fe", the small-strain incompressible FE of
    the axisymmetric body under this non-axisymmetric load (Fourier mode 1, Taylor-Hood, exact in 3-D for the
    axisymmetric geometry). Linear in mu.
    """
    mu = _check_mu(mu_kPa)
    ends = check_option(ShearEnds, ends, "ends")
    if not body.has_magnet:
        raise MechanicsError("shear: the shear stiffness is defined at the magnet; the body has none")
    if check_option(ShearModel, model, "model") == ShearModel.TIMOSHENKO:
        if mesh_mm is not None:
            raise MechanicsError("Input mesh_mm must be omitted for the timoshenko model")
        return _timoshenko_shear(body, mu, ends)
    return _fe_shear(body, mesh_mm, ends) * _newton_per_mu_mm2(mu)


def shear_compliance(body: Body, mu_kPa: float, model: ShearModel | str = ShearModel.TIMOSHENKO,
                     ends: ShearEnds | str = ShearEnds.FREE, mesh_mm: float | None = None) -> float:
    """Magnet lateral displacement per unit shear force on it, mm/N: 1 / :func:`shear_stiffness`."""
    return 1.0 / shear_stiffness(body, mu_kPa, model, ends, mesh_mm)
