"""An independent cross-check of the indentation FE: the same axisymmetric problem solved with FElupe's elements.

What is shared and what is not. Shared: the geometry and its straight-sided triangulation (magfab's graded mesh
vertices and triangles, its boundary tags), and a small Newton / active-set loop written here (rigid magnet: one
common axial displacement; flat frictionless indenter: prescribed axial displacement on the surface nodes it
touches). Not shared: the quadratic nodes (FElupe's ``add_midpoints_edges``), FElupe's quadratic triangles,
quadrature, axisymmetric kinematics, its neo-Hookean law and its (u, p, J) three-field nearly-incompressible
formulation (continuous P1 pressure and volume ratio, bulk modulus 5000 mu; magfab: two-field Taylor-Hood P2/P1,
exact incompressibility).

FElupe's conventions (read from its source, ``felupe/field/_axi.py``): the first coordinate is the axial one, the
second the radius (the hoop stretch is 1 + u_2 / X_2), so magfab's (r, z) points are swapped and each triangle's
corner order reversed to stay counter-clockwise. The NaN residual of the first attempt came from the (r, z) order
(FElupe took z as the radius) and from FElupe's mean-dilatation state, which moves incrementally with every
evaluation and is poisoned by one evaluation at an inverted trial state; the three-field form below keeps p and J
as ordinary unknowns, so an evaluation is a pure function of them.

Status (issue 13 item 4, still open, so the tests with a magnet are skipped): FElupe converges on MagOne but is
softer than magfab -- F(0.5 mm) = 10.36, 10.63, 10.67 mu mm^2 on 1.0, 0.5, 0.25 mm meshes against magfab's 10.93, 10.93,
10.99 (-5.5 %, -2.8 %, -3.0 %), and 26 % softer at 1 mm on the 1 mm mesh, where its Newton stalls (0.8-1.3 mm).
Without a magnet the two agree within 0.2-1.7 % (flat and hemispherical tips, 0.1-1 mm). FElupe's solution shows
J oscillating between 0.6 and 1.4 across the quadrature points of the elements between the magnet's top and the
apex (the volume constraint holds only on P1 averages there), and the result depends on the law's volumetric part
(isochoric NeoHooke: 8 % softer at 0.5 mm) -- see the report for the next steps.
"""

from __future__ import annotations

import numpy as np
import pytest

fem = pytest.importorskip("felupe")

OPEN = pytest.mark.skip(reason="issue 13 item 4 open: FElupe runs but is 3-6 % softer than magfab on MagOne at 0.5 mm "
                               "and stalls near 1 mm (module doc)")

from scipy.sparse import csr_matrix  # noqa: E402
from scipy.sparse.linalg import splu  # noqa: E402

from magfab import load_spec  # noqa: E402
from magfab.design import derive  # noqa: E402
from magfab.models import mechanics as mech  # noqa: E402
from magfab.models.mechanics.mesh import _AXIS, _BASE, _MAGNET, _OUTER, _body_mesh  # noqa: E402

DEPTHS_MM = np.array([0.5, 1.0, 2.0, 3.0])
BULK_PER_MU = 5000.0
TOLERANCE = 0.02


def _quadratic_mesh(body: mech.Body, mesh_mm: float):
    """FElupe's triangle6 mesh on magfab's vertices: (points (n, 2) as (z, r), cells (nel, 6), tags (n,)). A boundary
    edge's midpoint gets the tags both its ends share; an interior edge's midpoint none."""
    m = _body_mesh(body, mesh_mm)
    points, cells, kind = fem.mesh.add_midpoints_edges(m.p.T[:, ::-1].copy(), m.t.T[:, [0, 2, 1]].copy(), "triangle")
    tags = np.zeros(len(points), dtype=np.int64)
    tags[: m.p.shape[1]] = m.tags
    ends = ((0, 1), (1, 2), (2, 0))  # FElupe's triangle6: nodes 3, 4, 5 are the midpoints of these edges
    for k, (a, b) in zip((3, 4, 5), ends):
        tags[cells[:, k]] = tags[cells[:, a]] & tags[cells[:, b]]
    edges = np.sort(np.concatenate([cells[:, [a, b]] for a, b in ends]), axis=1)
    mids = np.concatenate([cells[:, k] for k in (3, 4, 5)])
    _, inverse, counts = np.unique(edges, axis=0, return_inverse=True, return_counts=True)
    tags[mids[counts[inverse.ravel()] > 1]] = 0
    return points, cells, kind, tags


class FElupeIndentation:
    """The indentation on FElupe's mixed (u, p, J) axisymmetric solid, dimensionless (mu = 1, mm). Unknowns x: the
    displacement (n, 2) flattened (axial, radial per node), then p and J - 1 at the m vertices."""

    def __init__(self, body: mech.Body, mesh_mm: float, bulk_per_mu: float = BULK_PER_MU, order: int = 5):
        self.body = body
        points, cells, kind, tags = _quadratic_mesh(body, mesh_mm)
        region = fem.RegionQuadraticTriangle(fem.Mesh(points, cells, kind),
                                             quadrature=fem.TriangleQuadrature(order=order))
        self.field = fem.FieldsMixed(region, n=3, axisymmetric=True)
        law = fem.NearlyIncompressible(fem.NeoHookeCompressible(mu=1.0, lmbda=0.0), bulk=bulk_per_mu)
        self.solid = fem.SolidBody(law, self.field)
        self.n, self.m = len(points), self.field[1].values.shape[0]
        self.nd = 2 * self.n + 2 * self.m
        self.Z = points[:, 0]
        magnet = ((tags & _MAGNET) != 0) & ((tags & _BASE) == 0)
        self.magnet = np.nonzero(magnet)[0]
        self.fixed_r = ((tags & (_AXIS | _BASE)) != 0) | magnet
        self.fixed_z = ((tags & _BASE) != 0) | magnet
        self.cand = np.nonzero(((tags & _OUTER) != 0) & ((tags & (_BASE | _MAGNET)) == 0))[0]
        scale = max(body.radius_mm, body.height_mm)
        self.tol, self.gap = 1e-8 * scale * scale, 1e-9 * scale

    def residual(self, x: np.ndarray) -> np.ndarray | None:
        """FElupe's assembled residual at x, or None where an element is inverted (non-finite)."""
        n2 = 2 * self.n
        self.field[0].values[:] = x[:n2].reshape(self.n, 2)
        self.field[1].values[:, 0] = x[n2:n2 + self.m]
        self.field[2].values[:, 0] = 1.0 + x[n2 + self.m:]
        R = np.asarray(self.solid.assemble.vector(self.field).todense()).ravel()
        return R if np.all(np.isfinite(R)) else None

    def operators(self, active: np.ndarray, delta: float):
        """(T, g, prescribed): x = T y + g on the prescribed dofs; y = (free dofs, the magnet's axial displacement)."""
        free_z = ~self.fixed_z
        free_z[self.cand[active]] = False
        free = np.concatenate([2 * np.nonzero(~self.fixed_r)[0] + 1, 2 * np.nonzero(free_z)[0],
                               np.arange(2 * self.n, self.nd)])
        rows = np.concatenate([free, 2 * self.magnet])
        cols = np.concatenate([np.arange(free.size), np.full(self.magnet.size, free.size)])
        T = csr_matrix((np.ones(rows.size), (rows, cols)), shape=(self.nd, free.size + (self.magnet.size > 0)))
        g = np.zeros(self.nd)
        act = self.cand[active]
        g[2 * act] = (self.body.height_mm - delta) - self.Z[act]
        prescribed = np.ones(self.nd, dtype=bool)
        prescribed[rows] = False
        return T, g, prescribed

    def newton(self, delta: float, x: np.ndarray, R: np.ndarray, active: np.ndarray):
        """Newton with the prescribed values entering as a consistent tangent step, halving a step until no element
        inverts. Raises RuntimeError."""
        T, g, prescribed = self.operators(active, delta)
        for _ in range(25):
            rem = np.where(prescribed, g - x, 0.0)
            r = T.T @ R
            if np.max(np.abs(r)) < self.tol and np.max(np.abs(rem)) < self.gap:
                return x, R
            K = self.solid.assemble.matrix().tocsr()
            dx = T @ splu((T.T @ K @ T).tocsc()).solve(-(r + T.T @ (K @ rem))) + rem
            for alpha in 0.5 ** np.arange(12):
                Rn = self.residual(x + alpha * dx)
                if Rn is not None:
                    break
            else:
                raise RuntimeError(f"element inversion at {delta:g} mm")
            x, R = x + alpha * dx, Rn
        raise RuntimeError(f"Newton did not converge at {delta:g} mm")

    def step(self, delta: float, x: np.ndarray, R: np.ndarray, active: np.ndarray):
        """One load step with the active set: add penetrating nodes, drop pulling ones, until it settles."""
        top = self.body.height_mm - delta
        for _ in range(30):
            x, R = self.newton(delta, x, R, active)
            add = ~active & (self.Z[self.cand] + x[2 * self.cand] > top + self.gap)
            drop = active & (R[2 * self.cand] > self.tol)
            if not (add.any() or drop.any()):
                return x, R, active
            active = (active & ~drop) | add
        raise RuntimeError(f"contact set did not settle at {delta:g} mm")

    def run(self, depths_mm: np.ndarray, step_mm: float = 0.1) -> np.ndarray:
        """(k, 2): indenter force (mu mm^2) and magnet displacement (mm, + down) at each depth; a failing step is
        halved down to 1/64 of ``step_mm``."""
        x = np.zeros(self.nd)
        R = self.residual(x)
        active = np.zeros(self.cand.size, dtype=bool)
        out, current = [], 0.0
        for target in depths_mm:
            step = step_mm
            while current < target - 1e-12:
                delta = min(current + step, target)
                try:
                    x, R, active = self.step(delta, x, R, active.copy())
                except RuntimeError:
                    step *= 0.5
                    if step < step_mm / 64:
                        raise
                    continue
                current, step = delta, min(2 * step, step_mm)
            travel = -float(x[2 * self.magnet[0]]) if self.magnet.size else float("nan")
            out.append((-float(R[2 * self.cand[active]].sum()), travel))
        return np.array(out)


def _compare(body: mech.Body, mesh_mm: float, mu_kPa: float = 23.0) -> tuple[np.ndarray, np.ndarray]:
    ours = mech.fe(body, mu_kPa, np.concatenate([[0.0], DEPTHS_MM]), mesh_mm=mesh_mm).force_N[1:]
    theirs = FElupeIndentation(body, mesh_mm).run(DEPTHS_MM)[:, 0] * mu_kPa * 1e-3  # mu mm^2 -> N
    return ours, theirs


@pytest.fixture(scope="module")
def magone() -> mech.Body:
    return mech.Body.from_design(derive(load_spec(None)))


@OPEN
def test_felupe_agrees_on_magone_to_full_indentation(magone):
    """MagOne (rounded magnet edges, bonded base), 1 mm mesh graded at the edges: within 2 % at 0.5 to 3 mm."""
    ours, theirs = _compare(magone, 1.0)
    np.testing.assert_array_less(np.abs(ours / theirs - 1.0), TOLERANCE)


def test_felupe_agrees_without_a_magnet():
    """No magnet, flat tip: the two codes agree within 2 % to 1 mm on the 1 mm mesh (measured 0.2-1.3 %)."""
    body = mech.Body(radius_mm=6.0, height_mm=6.3, base_height_mm=6.3, tip="flat")
    d = np.array([0.1, 0.5, 1.0])
    ours = mech.fe(body, 1.0, np.concatenate([[0.0], d]), mesh_mm=1.0).force_N[1:] * 1e3
    theirs = FElupeIndentation(body, 1.0).run(d)[:, 0]
    np.testing.assert_array_less(np.abs(ours / theirs - 1.0), TOLERANCE)


@OPEN
@pytest.mark.slow
@pytest.mark.parametrize("flat", [False, True])
def test_felupe_agrees_on_a_finer_mesh_and_a_flat_tip(magone, flat):
    body = magone
    if flat:
        body = mech.Body(radius_mm=6.0, height_mm=6.3, base_height_mm=6.3, tip="flat", magnet_radius_mm=2.5,
                         magnet_height_mm=2.0, magnet_z_mm=3.0, magnet_edge_radius_mm=0.2)
    ours, theirs = _compare(body, 0.5)
    np.testing.assert_array_less(np.abs(ours / theirs - 1.0), TOLERANCE)
