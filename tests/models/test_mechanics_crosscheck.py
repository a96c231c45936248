"""An independent cross-check of the indentation FE: the same axisymmetric problem solved with FElupe's elements.

What is shared and what is not. Shared: the geometry and its triangulation (magfab's graded mesh, its P2 node
numbering and boundary tags), and a small Newton / active-set loop written here (rigid magnet: one common axial
displacement; flat frictionless indenter: prescribed axial displacement on the surface nodes it touches). Not
shared -- everything that makes the discretisation: FElupe's quadratic triangles, quadrature, axisymmetric
kinematics, its isochoric neo-Hookean law, and its (u, p, J) three-field nearly-incompressible formulation with
element-constant pressure and volume ratio, statically condensed (magfab: Taylor-Hood P2/P1, continuous pressure,
exact incompressibility). Agreement within 2 % at 0.5, 1, 2 and 3 mm says both discretise the same physics; the
FElupe bulk modulus of 5000 mu changes the force by far less than that.

The fast test runs the build's coarsest mesh; the exhaustive variant (``-m slow``) a finer one and a flat-tipped body.
"""

from __future__ import annotations

import numpy as np
import pytest

fem = pytest.importorskip("felupe")

# Not yet working: FElupe's SolidBodyNearlyIncompressible on this P2 axisymmetric mesh returns NaN residuals for
# a small random displacement (before any contact), so Newton cannot start. Kept, skipped, for the next step of
# issue 13 item 4 (see the report); remove this mark once _felupe_forces converges.
pytestmark = pytest.mark.skip(reason="issue 13 item 4 in progress: FElupe residual is NaN on this mesh")

from magfab import load_spec  # noqa: E402
from magfab.design import derive  # noqa: E402
from magfab.models import mechanics as mech  # noqa: E402
from magfab.models.mechanics.discretisation import _axisym  # noqa: E402
from magfab.models.mechanics.mesh import _AXIS, _BASE, _MAGNET, _OUTER, _body_mesh  # noqa: E402

DEPTHS_MM = np.array([0.5, 1.0, 2.0, 3.0])
BULK_PER_MU = 5000.0
TOLERANCE = 0.02
DEBUG = False


def _felupe_forces(body: mech.Body, mesh_mm: float, depths_mm: np.ndarray, step_mm: float = 0.1) -> np.ndarray:
    """Indenter force (units of mu * mm^2) at ``depths_mm`` from FElupe's elements on magfab's mesh."""
    from scipy.sparse import csr_matrix
    from scipy.sparse.linalg import splu

    disc = _axisym(_body_mesh(body, mesh_mm))
    points, cells, tags = disc.doflocs.T.copy(), disc.edofs[:, :6].copy(), disc.dof_tags
    region = fem.RegionQuadraticTriangle(fem.Mesh(points, cells, "triangle6"))
    field = fem.FieldContainer([fem.FieldAxisymmetric(region, dim=2)])
    solid = fem.SolidBodyNearlyIncompressible(fem.NeoHooke(mu=1.0), field, bulk=BULK_PER_MU)
    n = points.shape[0]
    magnet = ((tags & _MAGNET) != 0) & ((tags & _BASE) == 0)
    fixed_r = ((tags & (_AXIS | _BASE)) != 0) | magnet
    fixed_z = ((tags & _BASE) != 0) | magnet
    cand = np.nonzero(((tags & _OUTER) != 0) & ((tags & (_BASE | _MAGNET)) == 0))[0]
    Z, H = points[:, 1], body.height_mm
    active = np.zeros(cand.size, dtype=bool)

    def state() -> np.ndarray:
        return field[0].values.ravel().copy()

    def set_state(x: np.ndarray) -> None:
        field[0].values[:] = x.reshape(n, 2)

    def operators(delta: float):
        free_z = ~fixed_z
        free_z[cand[active]] = False
        free = np.concatenate([2 * np.nonzero(~fixed_r)[0], 2 * np.nonzero(free_z)[0] + 1])
        rows = [free, 2 * np.nonzero(magnet)[0] + 1]
        cols = [np.arange(free.size), np.full(int(magnet.sum()), free.size)]
        vals = [np.ones(free.size), -np.ones(int(magnet.sum()))]  # magnet: u_z = -w
        T = csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(2 * n, free.size + 1))
        g = np.zeros(2 * n)
        g[2 * cand[active] + 1] = (H - delta) - Z[cand[active]]
        return T, g

    def newton(delta: float, x: np.ndarray) -> np.ndarray:
        """Newton with the prescribed values entering as a consistent tangent step (not a jump), halving a step
        until no element inverts."""
        T, g = operators(delta)
        free = np.asarray(abs(T).sum(axis=1)).ravel() > 0
        for _ in range(40):
            set_state(x)
            R = np.asarray(solid.assemble.vector(field).todense()).ravel()
            rem = np.where(free, 0.0, g - x)
            r = T.T @ R
            if DEBUG:
                print(delta, np.max(np.abs(r)), np.max(np.abs(rem)))
            if np.max(np.abs(r)) < 1e-9 * H * H and np.max(np.abs(rem)) < 1e-12 * H:
                return x
            K = solid.assemble.matrix(field)
            dx = T @ splu((T.T @ K @ T).tocsc()).solve(-(r + T.T @ (K @ rem))) + rem
            for alpha in 0.5 ** np.arange(12):  # halve the step until no element inverts (a finite residual)
                set_state(x + alpha * dx)
                if np.all(np.isfinite(solid.assemble.vector(field).data)):
                    break
            x = x + alpha * dx
        raise AssertionError(f"FElupe Newton did not converge at {delta} mm")

    forces, x, current = [], state(), 0.0
    for target in depths_mm:
        while current < target - 1e-12:
            delta = min(current + step_mm, target)
            for _ in range(50):  # active set: add penetrating nodes, drop pulling ones, until it settles
                x = newton(delta, x)
                uz = x[2 * cand + 1]
                R = np.asarray(solid.assemble.vector(field).todense()).ravel()
                add = ~active & (Z[cand] + uz > H - delta + 1e-9)
                drop = active & (R[2 * cand + 1] > 1e-9)
                if not (add.any() or drop.any()):
                    break
                active[:] = (active & ~drop) | add
            current = delta
        R = np.asarray(solid.assemble.vector(field).todense()).ravel()
        forces.append(-float(R[2 * cand[active] + 1].sum()))
    return np.array(forces)


def _compare(body: mech.Body, mesh_mm: float, mu_kPa: float = 23.0) -> tuple[np.ndarray, np.ndarray]:
    ours = mech.fe(body, mu_kPa, np.concatenate([[0.0], DEPTHS_MM]), mesh_mm=mesh_mm).force_N[1:]
    theirs = _felupe_forces(body, mesh_mm, DEPTHS_MM) * mu_kPa * 1e-3  # mu * mm^2 -> N (kPa mm^2 = 1e-3 N)
    return ours, theirs


@pytest.fixture(scope="module")
def magone() -> mech.Body:
    return mech.Body.from_design(derive(load_spec(None)))


def test_felupe_agrees_on_magone_to_full_indentation(magone):
    """MagOne (rounded magnet edges, bonded base), 1 mm mesh graded at the edges: within 2 % at 0.5 to 3 mm."""
    ours, theirs = _compare(magone, 1.0)
    np.testing.assert_array_less(np.abs(ours / theirs - 1.0), TOLERANCE)


@pytest.mark.slow
@pytest.mark.parametrize("flat", [False, True])
def test_felupe_agrees_on_a_finer_mesh_and_a_flat_tip(magone, flat):
    body = magone
    if flat:
        body = mech.Body(radius_mm=6.0, height_mm=6.3, base_height_mm=6.3, tip="flat", magnet_radius_mm=2.5,
                         magnet_height_mm=2.0, magnet_z_mm=3.0, magnet_edge_radius_mm=0.2)
    ours, theirs = _compare(body, 0.5)
    np.testing.assert_array_less(np.abs(ours / theirs - 1.0), TOLERANCE)
