"""The indentation problem on one discretisation (dimensionless: mu = 1, mm): a rigid flat frictionless indenter
on the top, the base bonded (or sliding), the magnet a rigid inclusion; Newton with an active contact set.

Boundary conditions (:meth:`_Indentation.constraints`) are imposed by a map from the unknowns to every dof; the
body's energy is :class:`~.energy._Energy`'s.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np

from .body import Body, MechanicsError
from .discretisation import _Axisym
from .energy import STRETCH_AVERAGING_FRACTION, _Energy
from .material import _Material
from .mesh import _AXIS, _BASE, _MAGNET, _OUTER, _magnet_normals

# Imported lazily, inside the functions that use them, for speed: scipy's sparse module takes a noticeable time to
# import, and importing this module should not; qdldl is optional (scipy's splu without it).


class MagnetInterface(str, Enum):
    """How the silicone holds the rigid magnet: bonded (glued: every surface node moves with it), or sliding
    (bilateral frictionless: a surface node keeps to the magnet's surface, normal to it, and slides freely along
    it; no separation, so a sealed pocket that neither glues nor opens)."""

    BONDED = "bonded"
    SLIDING = "sliding"


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
    lu: _LDL | None


class _LDL:
    """A factorisation of a reduced tangent ``K`` (CSR): QDLDL's sparse LDL^T of the saddle-point matrix with its
    zero pressure block shifted by -1e-10 of the largest diagonal entry (quasi-definite, so no pivoting is needed),
    and two rounds of iterative refinement against the unshifted ``K`` in :meth:`solve`. ``solver`` may be a QDLDL
    solver whose symbolic factorisation (AMD ordering, elimination tree) is reused from an earlier matrix of the same
    structure; ``version`` says which of its numeric factorisations this is (:attr:`valid`). If QDLDL meets a zero
    pivot, SuperLU with COLAMD takes over."""

    def __init__(self, K, upper=None, owner: _Reduction | None = None):
        self.K, self.owner = K, owner
        self._lu: Any = None  # qdldl's Solver, or scipy's SuperLU where qdldl cannot factor
        if upper is None:
            from scipy.sparse import triu

            upper = triu(K, format="csc")
            diag = upper.diagonal()
            upper = upper + _diag_shift(diag)
        try:
            import qdldl

            if owner is not None and owner.solver is not None:
                owner.solver.update(upper, upper=True)
                self._lu = owner.solver
            else:
                self._lu = qdldl.Solver(upper, upper=True)
                if owner is not None:
                    owner.solver = self._lu
        except (ValueError, RuntimeError, ImportError):
            from scipy.sparse.linalg import splu

            self._lu = splu(K.tocsc(), permc_spec="COLAMD", diag_pivot_thresh=0.01)
            if owner is not None:
                owner.solver = None
        if owner is not None:
            owner.version += 1
            self.version = owner.version

    @property
    def valid(self) -> bool:
        """False once the shared solver has been refactored for another matrix."""
        return self.owner is None or self.owner.version == self.version

    def solve(self, b: np.ndarray) -> np.ndarray:
        y = self._lu.solve(b)
        for _ in range(2):
            y = y + self._lu.solve(b - self.K @ y)
        return y


def _diag_shift(diag: np.ndarray):
    from scipy.sparse import diags

    return diags(np.where(diag == 0.0, -1e-10 * float(np.max(np.abs(diag), initial=1.0)), 0.0), format="csc")


def _factor(K) -> _LDL:
    return _LDL(K.tocsr())


class _Reduction:
    """T^T K T for tangents K of the discretisation's fixed sparsity pattern, T the map from the unknowns with nothing
    in contact (:meth:`_Indentation.constraints`): the reduced matrix is a sum of K's entries (each unknown maps at
    most one dof, the magnet's axial unknown several), so its values are one ``bincount`` of K's data into a structure
    computed once. A contact set fixes some unknowns (``fixed``): their rows and columns are zeroed and their diagonal
    set to 1, which keeps the structure, so QDLDL's symbolic factorisation of the upper triangle (CSC, the pressure
    diagonal shifted) is computed once per load path and only the numeric factorisation is repeated."""

    def __init__(self, pattern, T):
        r, c, _, nd, _ = pattern
        Tc = T.tocsr()
        n = T.shape[1]
        has = np.diff(Tc.indptr) > 0
        col = np.full(nd, -1, dtype=np.int64)
        col[has] = Tc.indices[Tc.indptr[:-1][has]]
        self.unknown = col  # dof -> its (first) unknown (-1: prescribed whatever the contact set)
        if np.all(np.diff(Tc.indptr) <= 1) and np.all(Tc.data == 1.0):
            keep = (col[r] >= 0) & (col[c] >= 0)
            self.keep, self.weight = np.nonzero(keep)[0], None
            ka, kb = col[r[self.keep]], col[c[self.keep]]
        else:  # a sliding magnet: a dof is a weighted sum of unknowns (:meth:`_Indentation.constraints`)
            self.keep, ka, kb, self.weight = _expand(r, c, Tc)
        keys, inv = np.unique(ka * n + kb, return_inverse=True)
        rows, cols = keys // n, keys % n
        self.n, self.inv, self.nnz, self.rows, self.cols = n, inv.ravel(), keys.size, rows, cols
        self.indptr = np.searchsorted(rows, np.arange(n + 1))
        self.diag = np.nonzero(rows == cols)[0]
        up = np.nonzero(rows <= cols)[0]
        up = up[np.argsort(cols[up] * n + rows[up], kind="stable")]
        self.upper, self.u_rows = up, rows[up]
        self.u_indptr = np.searchsorted(cols[up], np.arange(n + 1))
        self.u_diag = np.nonzero(rows[up] == cols[up])[0]
        self.solver, self.version = None, 0

    def matrix(self, K, fixed: np.ndarray):
        """T^T K T in CSR, the ``fixed`` unknowns' (a mask) rows and columns replaced by the identity's."""
        from scipy.sparse import csr_matrix

        kd = K.data[self.keep] if self.weight is None else K.data[self.keep] * self.weight
        data = np.bincount(self.inv, weights=kd, minlength=self.nnz)
        if fixed.any():
            data[fixed[self.rows] | fixed[self.cols]] = 0.0
            data[self.diag[fixed[self.rows[self.diag]]]] = 1.0
        return csr_matrix((data, self.cols, self.indptr), shape=(self.n, self.n))

    def factor(self, K, fixed: np.ndarray) -> _LDL:
        """A factorisation of :meth:`matrix` (see :class:`_LDL`)."""
        from scipy.sparse import csc_matrix

        Kr = self.matrix(K, fixed)
        ud = Kr.data[self.upper]
        d = ud[self.u_diag]
        ud[self.u_diag] = np.where(d == 0.0, -1e-10 * float(np.max(np.abs(d), initial=1.0)), d)
        return _LDL(Kr, csc_matrix((ud, self.u_rows, self.u_indptr), shape=(self.n, self.n)), self)


def _expand(r: np.ndarray, c: np.ndarray, Tc) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For T^T K T with a general T (CSR): every (K entry, unknown a of its row's dof, unknown b of its column's dof)
    as (index into K's data, a, b, T[i, a] T[j, b]), so the reduced matrix is again one weighted ``bincount``."""
    cnt = np.diff(Tc.indptr)

    def spread(k: np.ndarray, dof: np.ndarray):
        m = cnt[dof]
        rep = np.repeat(np.arange(k.size), m)
        off = np.arange(rep.size) - np.repeat(np.cumsum(m) - m, m)
        at = Tc.indptr[dof[rep]] + off
        return rep, Tc.indices[at], Tc.data[at]

    rep1, a, wa = spread(np.arange(r.size), r)
    k1 = rep1  # K entry of each (entry, a) pair
    rep2, b, wb = spread(k1, c[k1])
    return k1[rep2], a[rep2], b, wa[rep2] * wb


class _Indentation:
    """Newton solver for the indentation problem on one discretisation (dimensionless: mu = 1, mm).

    Dofs as in :class:`~.discretisation._Axisym`; ``candidates`` are the surface P2 nodes that may touch the
    indenter, ``active`` (a mask over them) those that do."""

    MAX_ITER = 30

    def __init__(self, body: Body, disc: _Axisym, material: _Material, base_bonded: bool = True,
                 interface: MagnetInterface = MagnetInterface.BONDED):
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
        self.magnet_ref = self.magnet_z[0] if self.magnet_z.size else -1  # a z dof that moves exactly as the magnet
        self.slide, self.slide_normal = self._sliding_nodes(on_magnet, interface)
        self.candidates = np.nonzero(((t & _OUTER) != 0) & ((t & (_BASE | _MAGNET)) == 0))[0]
        self.Z = disc.doflocs[1]
        self.base_free = np.concatenate([np.nonzero(~fixed_r)[0], N + np.nonzero(~fixed_z)[0],
                                         2 * N + np.arange(M)])
        scale = max(body.radius_mm, body.height_mm)
        # Residuals are nodal forces in mu * mm^2; the indenter force is ~0.1-10 scale^2, so 1e-6 scale^2 is a
        # relative accuracy of ~1e-7 on it (measured on MagOne: forces within 5e-8 of a 1e-9 tolerance's, one Newton
        # iteration less per step; Newton converges quadratically, so the last iterate is far better than this).
        self.tol = 1e-6 * scale * scale
        # Revise the contact set once the residual is this small: the sign of a node's reaction is settled after one or
        # two iterations, and revising then saves the iterations a tighter threshold spends converging the wrong set.
        self.set_tol = 1e-2 * scale * scale
        self.gap_tol = 1e-9 * scale
        T0 = self.constraints(np.zeros(self.candidates.size, dtype=bool), 0.0)[0]
        self.T = T0  # unknowns -> dofs with nothing in contact; a contact set fixes some unknowns (_fixed)
        self.reduction = _Reduction(disc.pattern, T0)
        self.contact_unknowns = self.reduction.unknown[N + self.candidates]

    def _sliding_nodes(self, on_magnet: np.ndarray, interface: MagnetInterface) -> tuple[np.ndarray, np.ndarray]:
        """The magnet's surface nodes that slide on it, and their outward normals (2, k) in the reference state; none
        for a bonded magnet. Nodes on the axis (the radial displacement fixed there) and the corners of a sharp-edged
        magnet (no single normal) stay bonded."""
        none = (np.zeros(0, dtype=np.int64), np.zeros((2, 0)))
        if interface == MagnetInterface.BONDED or not self.body.has_magnet:
            return none
        if self.plate:
            raise MechanicsError("Input interface 'sliding' needs a magnet inside the silicone; this magnet is the "
                                 "flat tip's top plate, pushed by the indenter itself")
        t, (r, z) = self.disc.dof_tags, self.disc.doflocs
        nodes = np.nonzero(on_magnet & ((t & _AXIS) == 0))[0]
        normal, unique = _magnet_normals(self.body, r[nodes], z[nodes])
        nodes, normal = nodes[unique], normal[:, unique]
        flat = np.nonzero(on_magnet & ((t & _AXIS) != 0))[0]  # the axis node: n = (0, +-1), u_z is the magnet's
        if flat.size:
            self.magnet_ref = flat[0] + self.disc.N
        else:
            self.magnet_ref = nodes[np.argmax(np.abs(normal[1]))] + self.disc.N
        return nodes, normal

    def _fixed(self, active: np.ndarray) -> np.ndarray:
        """Mask over the unknowns of :attr:`T`: those the contact set ``active`` prescribes."""
        fixed = np.zeros(self.T.shape[1], dtype=bool)
        fixed[self.contact_unknowns[active]] = True
        return fixed

    # -- constraints --

    def constraints(self, active: np.ndarray, delta: float):
        """(T, g, prescribed, load) for the active contact nodes at ``delta``.

        Admissible states are x = T y + g: T (ndof x nfree) maps the unknowns (free dofs, the magnet's common
        axial displacement w, and for a sliding magnet each surface node's slide s along the tangent t = (-n_z, n_r)
        of its reference normal n: u = w e_z + s t, so (u - w e_z) . n = 0) to all dofs; g holds the prescribed values
        on the ``prescribed`` dofs (the bonded base, the axis, the magnet's radial displacement, the nodes touching the
        indenter); ``load`` is d g / d delta.
        """
        from scipy.sparse import csr_matrix

        N = self.disc.N
        act = self.candidates[active]
        free = np.setdiff1d(self.base_free, N + act, assume_unique=True)
        rows, cols, vals = [free], [np.arange(free.size)], [np.ones(free.size)]
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
                vals.append(np.ones(self.magnet_z.size))
                prescribed[self.magnet_z] = False
                n += 1
        if self.slide.size:  # the tangential slide of each sliding node: u_r = -n_z s, u_z = w + n_r s
            k = n + np.arange(self.slide.size)
            rows += [self.slide, N + self.slide]
            cols += [k, k]
            vals += [-self.slide_normal[1], self.slide_normal[0]]
            prescribed[self.slide] = False
            n += self.slide.size
        T = csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(self.ndof, n))
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
        T = self.T
        _, g, prescribed, _ = self.constraints(active, delta)
        fixed = self._fixed(active)
        lu = None
        for it in range(1, self.MAX_ITER + 1):
            R, K = self.energy.assemble(x)
            rem = np.where(prescribed, g - x, 0.0)
            r = np.where(fixed, 0.0, T.T @ R)
            if not np.all(np.isfinite(r)):
                raise _StepFailure("non-finite residual (element inversion)")
            res, pending = np.max(np.abs(r), initial=0.0), np.max(np.abs(rem))
            if res <= self.set_tol and pending <= self.gap_tol:
                add = ~active & self._penetrating(x, top)
                drop = active & (-R[N + c] < -self.tol)
                if add.any() or drop.any():
                    active = (active & ~drop) | add
                    _, g, prescribed, _ = self.constraints(active, delta)
                    fixed = self._fixed(active)
                    rem = np.where(prescribed, g - x, 0.0)
                    r = np.where(fixed, 0.0, T.T @ R)
                    lu = None
                elif res <= self.tol:
                    return _State(x, active, it, R, K, lu)
            lu = self.reduction.factor(K, fixed)
            b = np.where(fixed, 0.0, -(r + T.T @ (K @ rem)))
            x = self._line_search(x, T @ lu.solve(b) + rem)
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

    def force(self, state: _State, delta: float) -> tuple[float, float, np.ndarray | None]:
        """(force, d force / d delta, d x / d delta) on the indenter, in mu * mm^2 and mu * mm: the reaction and its
        consistent tangent with the converged contact set (at delta = 0 the nodes touching the indenter count as in
        contact); d x / d delta (None with nothing in contact) is the load path's tangent, the next step's
        predictor."""
        active, lu = state.active, state.lu
        if delta == 0.0:
            touching = self.Z[self.candidates] + state.x[self.disc.N + self.candidates] >= \
                self.body.height_mm - self.gap_tol
            if np.any(touching & ~active):
                active, lu = active | touching, None
        _, _, _, load = self.constraints(active, delta)
        F = float(load @ state.R)
        if not np.any(load):
            return F, 0.0, None
        K, T, fixed = state.K, self.T, self._fixed(active)
        Kr = self.reduction.matrix(K, fixed)
        b = np.where(fixed, 0.0, -(T.T @ (K @ load)))
        if lu is None or not lu.valid:
            y = self.reduction.factor(K, fixed).solve(b)
        else:  # the factorisation is one Newton step old: two rounds of iterative refinement make it exact
            y = lu.solve(b)
            for _ in range(2):
                y += lu.solve(b - Kr @ y)  # (lu refines against its own matrix; these rounds against Kr)
        dx = T @ y + load
        return F, float(load @ (K @ dx)), dx

    def magnet_displacement(self, x: np.ndarray) -> float:
        return float(-x[self.magnet_ref]) if self.body.has_magnet else math.nan

    def magnet_slide(self, x: np.ndarray) -> float:
        """Largest tangential slide (mm) of a silicone node along the magnet's surface (0 if bonded)."""
        if not self.slide.size:
            return 0.0
        N = self.disc.N
        w = x[self.magnet_ref]
        ur, uz = x[self.slide], x[N + self.slide] - w
        return float(np.max(np.abs(-self.slide_normal[1] * ur + self.slide_normal[0] * uz)))
