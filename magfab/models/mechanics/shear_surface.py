"""Shear as the bench applies it: a lateral load through the contact patch under a normal preload.

The bench (the calibration scan, docs/models.md, M22) indents the tip by delta and moves the indenter sideways with the
silicone stuck to it. :func:`shear_response` follows the axisymmetric large-strain indentation (the FE of
:mod:`.fe`, the same load path) to each preload delta and solves there the incremental problem for a lateral
load, linearised about that state: a Fourier-mode-1 displacement (U_r cos t, -U_t sin t, U_z cos t) and pressure
P cos t on the axisymmetric mesh, exact in 3-D for the axisymmetric body and state.

Incremental energy (reference configuration, units of mu): 1/2 Grad du : D : Grad du, D = d2W/dF2 of the
incompressible neo-Hookean (or Yeoh) law at the state's F and p -- 2 W_1 I (+ 4 W_11 F (x) F) + q d2J + j (x) j /
J^2, q = p - 1/J as :class:`~.material._Material` has it -- with the linearised constraint cof F : Grad du = 0
(multiplier P). In cylindrical components Grad du of mode 1 has five cos t entries, (rr, rz, zr, zz, tt) as the
axisymmetric g, and four sin t entries (rt, tr, tz, zt); their cross terms integrate to zero over t, the cos block
of D is the axisymmetric material's, the sin block is 2 W_1 I + q d2J_sin (:func:`_sin_block`). At delta = 0
(F = I, p = 0) this is the small-strain mode-1 energy of :func:`~.shear._mode1_matrix` (a test).

Boundary conditions of the increment: base bonded (zero); on the axis U_t = U_r, U_z = 0 (regularity); the magnet
rigid and free (lateral shift s of its lower-face centre and tilt phi about it: U_r = U_t = s + phi (Z - z_m),
U_z = -phi R); the patch the indenter holds (the axisymmetric contact set: sticking contact, the bench's) moves
with the indenter: U_r = U_t = a, U_z = 0. A hemispherical tip touches in one point at delta = 0; there the patch
is the surface within :data:`REST_PATCH_INDENTATION_MM`'s Hertz radius (a flat tip: its whole top face).
Load ``"surface"``: the indenter moves by a; ``"magnet"``: a force on the magnet, the indenter holding the patch
(nothing holds the surface at delta = 0: today's :func:`~.shear.shear_stiffness` FE).

Cost: one mode-1 assembly and one sparse LDL factorisation per preload (QDLDL, its symbolic factorisation shared
along the path: every tangent has one structure), plus the indentation load path itself.
Lengths in mm, forces in N, mu in kPa, angles in rad.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from enum import Enum
from functools import lru_cache

import numpy as np

from .body import FLAT, Body, MechanicsError, _check_indentation, _check_mu, _newton_per_mu_mm2, check_option
from .discretisation import _Axisym, _axisym, _pattern, _sparse
from .fe import STRETCH_LIMIT, _LoadPath
from .indentation import _Indentation, _Reduction, _State
from .material import _Material, _material
from .mesh import _AXIS, _BASE, _MAGNET, _body_mesh, mesh_size
from .options import MaterialLaw, OnFailure

# Imported lazily, inside the functions that use it, for speed: scipy takes a
# noticeable time to import, and importing this module should not.

__all__ = ["ShearLoad", "ShearResponse", "ShearProbe", "shear_response", "REST_PATCH_INDENTATION_MM"]

#: The patch the indenter holds at delta = 0 on a rounded tip is the surface within the Hertz contact radius
#: sqrt(R delta) of this indentation: the bench's scan step, 50 um (docs/models.md, M22; 0.55 mm on MagOne). The
#: magnet's shift and tilt per newton hardly depend on it (a load at the apex is far from the magnet); the
#: indenter's own stiffness does (a point load has none), so at rest it is a figure for this patch only.
REST_PATCH_INDENTATION_MM = 0.05


class ShearLoad(str, Enum):
    """Where the lateral load goes in: through the indenter's contact patch (the bench), or on the magnet."""

    SURFACE = "surface"
    MAGNET = "magnet"


@dataclass(frozen=True, eq=False)
class ShearResponse:
    """The lateral response per newton of lateral force along +x, at each normal preload. Arrays (n,), one entry per
    indentation.

    ``normal_force_N``: the preload; ``magnet_drop_mm``: the magnet's axial displacement towards the chip (the gap is
    the rest gap minus it); ``displacement_mm_per_N``: lateral displacement of the magnet's lower-face centre, along
    the force; ``tilt_rad_per_N``: the magnet's rotation about the y axis through that centre, positive when its
    top leans along the force (the frame of :mod:`magfab.models.field.tilt`); ``stiffness_N_per_mm``: lateral
    force per lateral displacement of the indenter (NaN for the magnet load); ``patch_radius_mm``: the outermost
    surface node the indenter holds (reference radius; 0 where nothing does).
    """

    load: str
    mu_kPa: float
    indentation_mm: np.ndarray
    normal_force_N: np.ndarray
    magnet_drop_mm: np.ndarray
    displacement_mm_per_N: np.ndarray
    tilt_rad_per_N: np.ndarray
    stiffness_N_per_mm: np.ndarray
    patch_radius_mm: np.ndarray
    mesh_mm: float
    info: Mapping[str, object] = field(default_factory=dict)

    @property
    def magnet_stiffness_N_per_mm(self) -> np.ndarray:
        """Lateral force per lateral displacement of the magnet's lower-face centre, N/mm (what
        :func:`~.shear.shear_stiffness` gives for the magnet load at rest)."""
        return 1.0 / self.displacement_mm_per_N

    def scaled(self, mu_kPa: float) -> ShearResponse:
        """The same response for another shear modulus: forces and stiffnesses scale with mu, displacements and
        tilts per newton with 1/mu, the magnet's drop not at all."""
        k = _check_mu(mu_kPa) / self.mu_kPa
        return replace(self, mu_kPa=float(mu_kPa), normal_force_N=self.normal_force_N * k,
                       displacement_mm_per_N=self.displacement_mm_per_N / k, tilt_rad_per_N=self.tilt_rad_per_N / k,
                       stiffness_N_per_mm=self.stiffness_N_per_mm * k)


def shear_response(body: Body, mu_kPa: float, indentation_mm: Sequence[float] | np.ndarray = (0.0,),
                   mesh_mm: float | None = None, load: ShearLoad | str = ShearLoad.SURFACE,
                   material: MaterialLaw | str = MaterialLaw.NEO_HOOKEAN,
                   yeoh_ratios: tuple[float, float] | None = None, stretch_limit: float = STRETCH_LIMIT,
                   on_failure: OnFailure | str = OnFailure.RAISE,
                   rest_indentation_mm: float = REST_PATCH_INDENTATION_MM) -> ShearResponse:
    """Shear under normal preload (module doc): the lateral response per newton at each indentation (mm,
    non-decreasing, from 0 up), on the FE mesh of size ``mesh_mm`` (default as :func:`~.fe.fe`). Linear in 1/mu at
    each preload (:meth:`ShearResponse.scaled`: one solve serves a material band). If the indentation FE fails part
    way it raises :class:`MechanicsError`, or with ``on_failure="truncate"`` returns the preloads reached (the
    failure in ``info["failure"]``). ``rest_indentation_mm``: see :class:`ShearProbe`."""
    mu = _check_mu(mu_kPa)
    d = _check_indentation(indentation_mm)
    kind = check_option(ShearLoad, load, "load")
    policy = check_option(OnFailure, on_failure, "on_failure")
    if not body.has_magnet:
        raise MechanicsError("shear: the response is the magnet's; the body has none")
    if body.magnet_is_top_plate:
        raise MechanicsError("shear: the magnet is the top plate the indenter pushes; it cannot tilt under the "
                             "indenter, use shear_stiffness(..., ends='guided')")
    mesh = _body_mesh(body, mesh_size(body, mesh_mm))
    prob = _Indentation(body, _axisym(mesh), _material(material, yeoh_ratios))
    path = _LoadPath(prob, stretch_limit)
    probe = ShearProbe(kind, rest_indentation_mm=rest_indentation_mm)
    failure: dict[str, object] = {}
    try:
        for delta in d:
            if delta > 0.0:
                path.reach(float(delta))
            path.record(float(delta))  # the next step's predictor
            probe(float(delta), prob, path.state)
    except MechanicsError as exc:
        if policy == OnFailure.RAISE:
            raise
        failure = {"failure": str(exc), "failed_at_mm": float(d[len(probe.rows)])}
    return probe.response(mu, **failure)


class ShearProbe:
    """The shear response at converged states of an indentation load path, one mode-1 solve each: call it with
    (indentation in mm, the :class:`~.indentation._Indentation` problem, its converged ``_State``) at each preload
    wanted -- :func:`shear_response` does so along its own load path; a caller that already steps the indentation
    FE can call it from there and skip a second path -- then :meth:`response` for a shear modulus. ``depths_mm``:
    the indentations to probe (others are skipped; None: every call). ``rest_indentation_mm``: at delta = 0 a
    rounded tip's patch is the surface within the Hertz radius sqrt(R rest_indentation_mm) of the axis (default
    :data:`REST_PATCH_INDENTATION_MM`; a build may pass its scan step)."""

    def __init__(self, load: ShearLoad | str = ShearLoad.SURFACE, depths_mm: Sequence[float] | np.ndarray | None = None,
                 rest_indentation_mm: float = REST_PATCH_INDENTATION_MM):
        self.load = check_option(ShearLoad, load, "load")
        self.rest = float(rest_indentation_mm)
        if not (math.isfinite(self.rest) and self.rest > 0.0):
            raise MechanicsError(f"Input rest_indentation_mm must be a finite indentation > 0; instead received "
                                 f"{rest_indentation_mm!r}")
        self.depths = None if depths_mm is None else np.asarray(depths_mm, dtype=float)
        self.rows: list[tuple[float, ...]] = []
        self.mesh_mm, self.dofs = math.nan, 0

    def __call__(self, delta: float, prob: _Indentation, state: _State) -> None:
        if self.depths is not None and not np.any(np.abs(self.depths - delta) <= 1e-9 * (1.0 + abs(delta))):
            return
        body, disc = prob.body, prob.disc
        if not body.has_magnet or body.magnet_is_top_plate:
            raise MechanicsError("shear: the response is the magnet's; this body has none, or its magnet is the top "
                                 "plate the indenter holds (use shear_stiffness(..., ends='guided'))")
        if prob.slide.size:
            raise MechanicsError("shear: the increment keeps the magnet bonded to the silicone; this load path lets "
                                 "it slide")
        op = _operator(body, disc)
        patch = _patch(body, prob, state.x, state.active, delta, self.rest)
        held = patch if (self.load == ShearLoad.SURFACE or delta > 0.0) else patch[:0]
        g, p = prob.energy.fields(state.x)
        a, s, phi = op.respond(op.matrix(g, p, prob.energy.mat), held, self.load)
        force = -float(state.R[disc.N + prob.candidates[state.active]].sum())  # the indenter's reaction
        radius = float(disc.doflocs[0, held].max()) if held.size else 0.0
        drop = prob.magnet_displacement(state.x)
        self.rows.append((delta, force + 0.0, drop + 0.0, s, phi, a, radius))  # + 0.0: no -0.0 at rest
        self.mesh_mm, self.dofs = disc.mesh.h, op.ndof

    def response(self, mu_kPa: float, **info: object) -> ShearResponse:
        """The probed preloads for shear modulus ``mu_kPa`` (``info`` goes into the result's)."""
        mu = _check_mu(mu_kPa)
        out = np.array(self.rows, dtype=float).reshape(-1, 7)
        unit = _newton_per_mu_mm2(mu)  # N per (mu mm^2): displacements per N divide by it
        stiffness = unit / out[:, 5] if self.load == ShearLoad.SURFACE else np.full(out.shape[0], math.nan)
        return ShearResponse(self.load.value, mu, out[:, 0], out[:, 1] * unit, out[:, 2], out[:, 3] / unit,
                             out[:, 4] / unit, stiffness, out[:, 6], self.mesh_mm,
                             {"dofs": self.dofs, "load": self.load.value, **info})


def _patch(body: Body, prob: _Indentation, x: np.ndarray, active: np.ndarray, delta: float,
           rest_mm: float = REST_PATCH_INDENTATION_MM) -> np.ndarray:
    """P2 dofs the indenter holds: the axisymmetric contact set; at delta = 0 the surface touching the indenter and,
    on a rounded tip, within the Hertz radius sqrt(R rest_mm) of the axis."""
    c = prob.candidates
    held = active.copy()
    if delta == 0.0:
        top = body.height_mm - prob.gap_tol
        held |= prob.Z[c] + x[prob.disc.N + c] >= top
        if body.tip != FLAT:
            held |= prob.disc.doflocs[0, c] <= math.sqrt(body.radius_mm * rest_mm)
    return c[held]


def _sin_block(g: np.ndarray, q: np.ndarray, f1: np.ndarray) -> np.ndarray:
    """d2W/dH2 for the sin t entries (rt, tr, tz, zt) of Grad du, (..., 4, 4): 2 W_1 I + q d2J, where the second
    derivatives of J = det F in those entries are -F_zz (rt, tr), F_zr (rt, tz), F_rz (tr, zt), -F_rr (tz, zt)
    (the axisymmetric F has no sin entries, so neither W_11 F (x) F nor j (x) j reaches this block)."""
    a, b, c, d = (g[..., i] for i in range(4))
    D = np.zeros((*g.shape[:-1], 4, 4))
    for i in range(4):
        D[..., i, i] = 2.0 * f1
    for (i, k), v in (((0, 1), -d), ((0, 2), c), ((1, 3), b), ((2, 3), -a)):
        D[..., i, k] = D[..., k, i] = q * v
    return D


class _Operator:
    """The mode-1 increment on one discretisation of one body: shape functions of the nine entries of Grad du,
    the map T from the unknowns (free dofs, then the magnet's shift s and tilt phi) to the dofs
    (U_r, U_t, U_z at the P2 nodes, then P at the vertices), and the reduction T^T K T."""

    def __init__(self, body: Body, disc: _Axisym):
        N, M = disc.N, disc.M
        self.N, self.M, self.ndof = N, M, 3 * N + M
        gr, gz, pr = disc.B[:, :, 0, :6], disc.B[:, :, 1, :6], disc.B[:, :, 4, :6]  # d/dR, d/dZ, phi/R
        nel, nq = gr.shape[:2]
        ur, ut, uz = slice(0, 6), slice(6, 12), slice(12, 18)
        B = np.zeros((nel, nq, 9, 18))  # cos t: rr, rz, zr, zz, tt (the order of g); sin t: rt, tr, tz, zt
        B[:, :, 0, ur], B[:, :, 1, ur], B[:, :, 2, uz], B[:, :, 3, uz] = gr, gz, gr, gz
        B[:, :, 4, ur], B[:, :, 4, ut] = pr, -pr
        B[:, :, 5, ur], B[:, :, 5, ut] = -pr, pr
        B[:, :, 6, ut], B[:, :, 7, ut], B[:, :, 8, uz] = -gr, -gz, -pr
        self.B = B
        self.Bt = np.ascontiguousarray(B.reshape(nel, nq * 9, 18).transpose(0, 2, 1))
        self.w = 0.5 * disc.w  # pi R dx: the integral of cos^2 t (or sin^2 t) over t is pi, not 2 pi
        self.psi = disc.psi
        ed = disc.edofs[:, :6]
        self.edofs = np.hstack([ed, N + ed, 2 * N + ed, N + disc.edofs[:, 12:]])  # pressure 2N + k -> 3N + k
        self.pattern = _pattern(self.edofs)
        self._unknowns(body, disc)
        self.reduction = _Reduction(self.pattern, self.T)  # weighted rows: the magnet's

    def _unknowns(self, body: Body, disc: _Axisym) -> None:
        from scipy.sparse import csr_matrix

        N, M = self.N, self.M
        tags, (r, z) = disc.dof_tags, disc.doflocs
        axis, base = (tags & _AXIS) != 0, (tags & _BASE) != 0
        mag = ((tags & _MAGNET) != 0) & ~base
        free_r = ~base & ~mag
        free_tz = free_r & ~axis
        idx = np.arange(N)
        col = np.full(self.ndof, -1)
        free = np.concatenate([idx[free_r], N + idx[free_tz], 2 * N + idx[free_tz], 3 * N + np.arange(M)])
        col[free] = np.arange(free.size)
        tie = idx[axis & free_r]
        col[N + tie] = col[tie]  # U_t on the axis is U_r's unknown
        self.col = col
        n = free.size
        self.s_col, self.phi_col, self.n = n, n + 1, n + 2
        m = idx[mag]
        lever = z[m] - body.magnet_z_mm
        rows = np.concatenate([free, N + tie, m, N + m, m, N + m, 2 * N + m])
        cols = np.concatenate([col[free], col[tie], np.full(2 * m.size, n), np.full(3 * m.size, n + 1)])
        vals = np.concatenate([np.ones(free.size + tie.size + 2 * m.size), lever, lever, -r[m]])
        keep = vals != 0.0
        self.T = csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(self.ndof, self.n))

    def matrix(self, g: np.ndarray, p: np.ndarray, mat: _Material):
        """The mode-1 tangent (CSR, the pattern's structure) at the axisymmetric state's g (nel, nq, 5), p (nel, nq)."""
        _, D, j, J, _ = mat.response(g, p)
        s = np.einsum("...i,...i->...", g, g) - 3.0
        f1 = 0.5 * (1.0 + 2.0 * mat.k2 * s + 3.0 * mat.k3 * s * s)  # dW/dI1, as _Material.response
        w = self.w
        nel, nq = w.shape
        Dw = np.zeros((nel, nq, 9, 9))  # cos and sin entries do not couple (module doc)
        Dw[..., :5, :5] = D
        Dw[..., 5:, 5:] = _sin_block(g, p - 1.0 / J, f1)
        Dw *= w[..., None, None]
        ke = np.empty((nel, 21, 21))
        np.matmul(self.Bt, np.matmul(Dw, self.B).reshape(nel, nq * 9, 18), out=ke[:, :18, :18])
        jB = np.matmul((j * w[..., None])[..., None, :], self.B[:, :, :5])[:, :, 0]  # (nel, nq, 18)
        np.matmul(jB.transpose(0, 2, 1), self.psi, out=ke[:, :18, 18:])
        ke[:, 18:, :18] = ke[:, :18, 18:].transpose(0, 2, 1)
        ke[:, 18:, 18:] = 0.0
        return _sparse(self.pattern, ke)

    def respond(self, K, patch: np.ndarray, load: ShearLoad) -> tuple[float, float, float]:
        """(indenter shift a, magnet shift s, tilt phi) per unit lateral force (mm and rad per mu mm^2) with the
        P2 dofs ``patch`` held by the indenter: moved by a (surface load), or held still (magnet load)."""
        N = self.N
        fixed = np.zeros(self.n, dtype=bool)
        held = np.concatenate([self.col[patch], self.col[N + patch], self.col[2 * N + patch]])
        fixed[held[held >= 0]] = True
        lu = self.reduction.factor(K, fixed)
        if load == ShearLoad.MAGNET:
            b = np.zeros(self.n)
            b[self.s_col] = 1.0
            y = lu.solve(b)
            return math.nan, float(y[self.s_col]), float(y[self.phi_col])
        if patch.size == 0:
            raise MechanicsError("shear: nothing touches the indenter, so it cannot load the surface")
        a_vec = np.zeros(self.ndof)  # the indenter moved by a = 1
        a_vec[patch] = a_vec[N + patch] = 1.0
        b = -(self.T.T @ (K @ a_vec))
        b[fixed] = 0.0
        y = lu.solve(b)
        force = float(a_vec @ (K @ (self.T @ y + a_vec)))
        return 1.0 / force, float(y[self.s_col]) / force, float(y[self.phi_col]) / force


@lru_cache(maxsize=4)  # ~20 MB each on a 0.5 mm MagOne mesh
def _operator(body: Body, disc: _Axisym) -> _Operator:
    return _Operator(body, disc)
