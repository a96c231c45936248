"""The indentation problem on one discretisation (dimensionless: mu = 1, mm): a rigid flat frictionless indenter
on the top, the base bonded (or sliding), the magnet a rigid inclusion; Newton with an active contact set.

Boundary conditions (:meth:`_Indentation.constraints`) are imposed by a map from the unknowns to every dof; the
body's energy is :class:`~.energy._Energy`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .body import Body
from .discretisation import _Axisym
from .energy import STRETCH_AVERAGING_FRACTION, _Energy
from .material import _Material
from .mesh import _AXIS, _BASE, _MAGNET, _OUTER


class _StepFailure(Exception):
    """One load step failed; the march cuts the step before giving up with a MechanicsError."""


@dataclass(frozen=True, eq=False)
class _State:
    """A converged load step: the solution, its contact set, residual and tangent at x, and a factorisation of the
    reduced tangent for that contact set (from the last Newton iterate; None if there was none)."""

    x: np.ndarray
    active: np.ndarray
    iterations: int
    R: np.ndarray
    K: object
    lu: object


class _LDL:
    """A factorisation of the reduced tangent: QDLDL's sparse LDL^T (AMD ordering) of the saddle-point matrix with its
    zero pressure block shifted by -1e-10 of the largest diagonal entry (quasi-definite, so no pivoting is needed),
    and two rounds of iterative refinement against the unshifted matrix in :meth:`solve`. Five to ten times faster
    than SuperLU's threshold-pivoting LU here; if QDLDL meets a zero pivot, SuperLU with COLAMD takes over."""

    def __init__(self, K):
        self.K = K.tocsc()
        diag = self.K.diagonal()
        shift = np.where(diag == 0.0, -1e-10 * float(np.max(np.abs(diag), initial=1.0)), 0.0)
        try:
            import qdldl
            from scipy.sparse import diags

            self._lu = qdldl.Solver((self.K + diags(shift)).tocsc())
        except (ValueError, RuntimeError, ImportError):
            from scipy.sparse.linalg import splu

            self._lu = splu(self.K, permc_spec="COLAMD", diag_pivot_thresh=0.01)

    def solve(self, b: np.ndarray) -> np.ndarray:
        y = self._lu.solve(b)
        for _ in range(2):
            y = y + self._lu.solve(b - self.K @ y)
        return y


def _factor(K) -> _LDL:
    return _LDL(K)


class _Indentation:
    """Newton solver for the indentation problem on one discretisation (dimensionless: mu = 1, mm).

    Dofs as in :class:`~.discretisation._Axisym`; ``candidates`` are the surface P2 nodes that may touch the
    indenter, ``active`` (a mask over them) those that do."""

    MAX_ITER = 30

    def __init__(self, body: Body, disc: _Axisym, material: _Material, base_bonded: bool = True):
        self.body, self.disc = body, disc
        self.energy = _Energy(disc, material, STRETCH_AVERAGING_FRACTION * body.radius_mm)
        N, M = disc.N, disc.M
        self.ndof = self.energy.ndof
        t = disc.dof_tags
        self.plate = body.magnet_is_top_plate
        on_magnet = ((t & _MAGNET) != 0) & ((t & _BASE) == 0)
        fixed_r = ((t & (_AXIS | (_BASE if base_bonded else 0))) != 0) | on_magnet
        fixed_z = ((t & _BASE) != 0) | on_magnet
        self.magnet_z = np.nonzero(on_magnet)[0] + N
        self.candidates = np.nonzero(((t & _OUTER) != 0) & ((t & (_BASE | _MAGNET)) == 0))[0]
        self.Z = disc.doflocs[1]
        self.base_free = np.concatenate([np.nonzero(~fixed_r)[0], N + np.nonzero(~fixed_z)[0],
                                         2 * N + np.arange(M)])
        scale = max(body.radius_mm, body.height_mm)
        # Residuals are nodal forces in mu * mm^2; the indenter force is ~0.1-10 scale^2, so 1e-9 scale^2 is a
        # relative accuracy of ~1e-10 on it (Newton converges quadratically: one iteration more would give 1e-20).
        self.tol = 1e-9 * scale * scale
        self.set_tol = 1e-4 * scale * scale  # revise the contact set once the residual is this small
        self.gap_tol = 1e-9 * scale

    # -- constraints --

    def constraints(self, active: np.ndarray, delta: float):
        """(T, g, prescribed, load) for the active contact nodes at ``delta``.

        Admissible states are x = T y + g: T (ndof x nfree) maps the unknowns (free dofs, and the magnet's common
        axial displacement) to all dofs; g holds the prescribed values on the ``prescribed`` dofs (the bonded base,
        the axis, the magnet's radial displacement, the nodes touching the indenter); ``load`` is d g / d delta.
        """
        from scipy.sparse import csr_matrix

        N = self.disc.N
        act = self.candidates[active]
        free = np.setdiff1d(self.base_free, N + act, assume_unique=True)
        rows, cols = [free], [np.arange(free.size)]
        n = free.size
        g = np.zeros(self.ndof)
        prescribed = np.ones(self.ndof, dtype=bool)
        prescribed[free] = False
        g[N + act] = (self.body.height_mm - delta) - self.Z[act]
        load = np.zeros(self.ndof)
        load[N + act] = -1.0
        if self.body.has_magnet:
            if self.plate:
                g[self.magnet_z] = -delta
                load[self.magnet_z] = -1.0
            else:
                rows.append(self.magnet_z)
                cols.append(np.full(self.magnet_z.size, n))
                prescribed[self.magnet_z] = False
                n += 1
        rows, cols = np.concatenate(rows), np.concatenate(cols)
        T = csr_matrix((np.ones(rows.size), (rows, cols)), shape=(self.ndof, n))
        return T, g, prescribed, load

    # -- one load step --
    def solve(self, x: np.ndarray, active: np.ndarray, delta: float) -> _State:
        """Newton with an active set at indentation ``delta`` from the admissible guess x.

        Each iteration solves the tangent problem for the residual and the still-unmet prescribed values together
        (so a new contact node or a new indentation enters as a consistent tangent step, not a jump), then halves
        the step until no element inverts. Once the residual is small, nodes that penetrate the indenter join the
        contact set and nodes that pull on it leave (a semi-smooth Newton); the step is done when the residual
        vanishes and the set no longer changes. Raises _StepFailure.
        """
        N, c, top = self.disc.N, self.candidates, self.body.height_mm - delta
        active = active | self._penetrating(x, top)
        T, g, prescribed, _ = self.constraints(active, delta)
        lu = None
        for it in range(1, self.MAX_ITER + 1):
            R, K = self.energy.assemble(x)
            rem = np.where(prescribed, g - x, 0.0)
            r = T.T @ R
            if not np.all(np.isfinite(r)):
                raise _StepFailure("non-finite residual (element inversion)")
            res, pending = np.max(np.abs(r), initial=0.0), np.max(np.abs(rem))
            if res <= self.set_tol and pending <= self.gap_tol:
                add = ~active & self._penetrating(x, top)
                drop = active & (-R[N + c] < -self.tol)
                if add.any() or drop.any():
                    active = (active & ~drop) | add
                    T, g, prescribed, _ = self.constraints(active, delta)
                    rem = np.where(prescribed, g - x, 0.0)
                    r = T.T @ R
                    lu = None
                elif res <= self.tol:
                    return _State(x, active, it, R, K, lu)
            lu = _factor(T.T @ K @ T)
            x = self._line_search(x, T @ lu.solve(-(r + T.T @ (K @ rem))) + rem)
        raise _StepFailure(f"Newton did not converge in {self.MAX_ITER} iterations")

    def _penetrating(self, x: np.ndarray, top: float) -> np.ndarray:
        """Mask over the candidates: nodes above the indenter's face at height ``top`` (mm)."""
        c = self.candidates
        return self.Z[c] + x[self.disc.N + c] > top + self.gap_tol

    def _line_search(self, x: np.ndarray, dx: np.ndarray) -> np.ndarray:
        """x + alpha dx for the largest alpha in 1, 1/2, ... 1/2^11 that inverts no element."""
        alpha = 1.0
        for _ in range(12):
            trial = x + alpha * dx
            if self.energy.admissible(trial):
                return trial
            alpha *= 0.5
        raise _StepFailure("element inversion (det F <= 0) that no Newton line search avoids")

    def rest(self) -> _State:
        """The unloaded state (x = 0, nothing in contact)."""
        x = np.zeros(self.ndof)
        R, K = self.energy.assemble(x)
        return _State(x, np.zeros(self.candidates.size, dtype=bool), 0, R, K, None)

    def force(self, state: _State, delta: float) -> tuple[float, float]:
        """(force, d force / d delta) on the indenter, in mu * mm^2 and mu * mm: the reaction and its consistent
        tangent with the converged contact set (at delta = 0 the nodes touching the indenter count as in contact)."""
        active, lu = state.active, state.lu
        if delta == 0.0:
            touching = self.Z[self.candidates] + state.x[self.disc.N + self.candidates] >= \
                self.body.height_mm - self.gap_tol
            if np.any(touching & ~active):
                active, lu = active | touching, None
        T, _, _, load = self.constraints(active, delta)
        F = float(load @ state.R)
        if not np.any(load):
            return F, 0.0
        K = state.K
        Kr = T.T @ K @ T
        b = -(T.T @ (K @ load))
        if lu is None:
            y = _factor(Kr).solve(b)
        else:  # the factorisation is one Newton step old: two rounds of iterative refinement make it exact
            y = lu.solve(b)
            for _ in range(2):
                y += lu.solve(b - Kr @ y)  # (lu refines against its own matrix; these rounds against Kr)
        dx = T @ y + load
        return F, float(load @ (K @ dx))

    def magnet_displacement(self, x: np.ndarray) -> float:
        return float(-x[self.magnet_z[0]]) if self.body.has_magnet else math.nan
