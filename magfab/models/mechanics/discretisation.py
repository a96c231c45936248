"""Taylor-Hood P2/P1 discretisation of the axisymmetric body on a :mod:`.mesh` triangulation (scikit-fem bases),
and the fast sparse assembly both FE models (indentation and mode-1 shear) use. Cached per mesh.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .mesh import _Mesh

# Imported lazily, inside the functions that use them, for speed: scikit-fem and scipy take a
# noticeable time to import, and importing this module should not.


@dataclass(eq=False)
class _Axisym:
    """Taylor-Hood P2/P1 axisymmetric discretisation of a mesh (all arrays precomputed, mm units).

    Unknowns: u_r at the N P2 nodes, then u_z, then p at the M vertices. Per quadrature point the deformation
    gradient is g = (F_rr, F_rz, F_zr, F_zz, F_thth) = g0 + B u_e; weights include 2 pi r.
    """

    mesh: _Mesh
    N: int
    M: int
    B: np.ndarray  # (nel, nq, 5, 12)
    Bt: np.ndarray  # (nel, 12, nq * 5), B transposed for the element integrals
    psi: np.ndarray  # (nel, nq, 3)
    psi_t: np.ndarray  # (nel, 3, nq)
    w: np.ndarray  # (nel, nq)
    edofs: np.ndarray  # (nel, 15)
    doflocs: np.ndarray  # (2, N)
    dof_tags: np.ndarray  # (N,)
    corner_r: np.ndarray  # (nel, 3) scalar P2 dofs of the corners (= vertex indices)
    node_grad: np.ndarray  # (nel, 6 nodes, 2, 6 basis) in-plane gradients of the P2 basis at the element's nodes
    node_inv_r: np.ndarray  # (nel, 6) 1 / r at the element's nodes (0 on the axis, where the hoop stretch is F_rr)
    pattern: tuple  # (unique keys' rows, cols, inverse) for fast sparse assembly


def _values(field) -> np.ndarray:
    """A scikit-fem DiscreteField's values (an ndarray subclass since 11; a named tuple with .value before)."""
    return np.asarray(field if isinstance(field, np.ndarray) else field.value)


def _scalar_p2(mesh: _Mesh):
    from skfem import Basis, ElementTriP1, ElementTriP2, MeshTri

    m = MeshTri(mesh.p, np.ascontiguousarray(mesh.t), sort_t=False)  # keep the counter-clockwise corner order
    sb = Basis(m, ElementTriP2(), intorder=4)
    pb = Basis(m, ElementTriP1(), quadrature=sb.quadrature)
    phi = np.stack([_values(sb.basis[i][0]) for i in range(6)], axis=-1)  # (nel, nq, 6)
    grad = np.stack([sb.basis[i][0].grad for i in range(6)], axis=-1)  # (2, nel, nq, 6)
    psi = np.stack([_values(pb.basis[i][0]) for i in range(3)], axis=-1)
    rq = _values(sb.global_coordinates())[0]  # (nel, nq)
    # P2 dof tags: vertices keep theirs, a boundary edge's midpoint gets the tags both ends share.
    nv = m.p.shape[1]
    tags = np.zeros(sb.N, dtype=np.int64)
    tags[:nv] = mesh.tags
    bf = m.boundary_facets()
    fv = m.facets[:, bf]
    tags[nv + bf] = mesh.tags[fv[0]] & mesh.tags[fv[1]]
    return m, sb, pb, phi, grad, psi, rq, tags


def _pattern(edofs: np.ndarray):
    n = edofs.shape[1]
    rows = np.repeat(edofs, n, axis=1).ravel()
    cols = np.tile(edofs, (1, n)).ravel()
    nd = int(edofs.max()) + 1
    keys, inverse = np.unique(rows.astype(np.int64) * nd + cols, return_inverse=True)
    r = keys // nd
    return r, keys % nd, inverse.ravel(), nd, np.searchsorted(r, np.arange(nd + 1))


def _sparse(pattern, ke: np.ndarray):
    """The global matrix of element matrices ``ke`` in CSR with the pattern's fixed structure (sorted unique keys are
    already in CSR order, so no conversion): every matrix of one pattern has the same ``indices``, ``indptr``."""
    from scipy.sparse import csr_matrix

    r, c, inv, nd, indptr = pattern
    data = np.bincount(inv, weights=ke.ravel(), minlength=r.size)
    return csr_matrix((data, c, indptr), shape=(nd, nd))


@lru_cache(maxsize=8)
def _axisym(mesh: _Mesh) -> _Axisym:
    m, sb, pb, phi, grad, psi, rq, tags = _scalar_p2(mesh)
    nel, nq = rq.shape
    B = np.zeros((nel, nq, 5, 12))
    B[:, :, 0, :6] = grad[0]
    B[:, :, 1, :6] = grad[1]
    B[:, :, 4, :6] = phi / rq[..., None]
    B[:, :, 2, 6:] = grad[0]
    B[:, :, 3, 6:] = grad[1]
    N, M = sb.N, pb.N
    ed = sb.element_dofs.T
    edofs = np.hstack([ed, N + ed, 2 * N + pb.element_dofs.T])
    w = sb.dx * 2.0 * math.pi * rq
    Bt = np.ascontiguousarray(B.reshape(nel, nq * 5, 12).transpose(0, 2, 1))
    psi_t = np.ascontiguousarray(psi.transpose(0, 2, 1))
    node_grad, node_inv_r = _node_gradients(m, sb)
    return _Axisym(mesh, N, M, B, Bt, psi, psi_t, w, edofs, sb.doflocs, tags, m.t.T.copy(), node_grad, node_inv_r,
                   _pattern(edofs))


def _node_gradients(m, sb):
    """Gradients of the P2 basis at each element's six nodes (the deformed element is curved: its Jacobian varies,
    and the nodes are where an inverted corner or edge shows first) and 1 / r there (0 on the axis)."""
    from skfem import Basis, ElementTriP2

    X = np.array([[0.0, 1.0, 0.0, 0.5, 0.5, 0.0], [0.0, 0.0, 1.0, 0.0, 0.5, 0.5]])  # ElementTriP2's node order
    nb = Basis(m, ElementTriP2(), quadrature=(X, np.ones(6)))
    grad = np.stack([nb.basis[i][0].grad for i in range(6)], axis=-1)  # (2, nel, 6 nodes, 6 basis)
    r = _values(nb.global_coordinates())[0]  # (nel, 6)
    scale = float(np.max(r)) if r.size else 1.0
    inv_r = np.where(r > 1e-12 * scale, 1.0 / np.where(r > 1e-12 * scale, r, 1.0), 0.0)
    return np.ascontiguousarray(grad.transpose(1, 2, 0, 3)), inv_r
