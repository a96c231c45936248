"""The axisymmetric large-strain FE of the indentation: :func:`fe`.

Built on scikit-fem: incompressible neo-Hookean (or Yeoh), mixed displacement-pressure formulation with
Taylor-Hood P2/P1 triangles (inf-sup stable, so no volumetric locking) and an exact incompressibility constraint
(Lagrange multiplier, no penalty); base bonded; magnet a rigid inclusion (every node on the magnet's surface
shares one axial displacement and has zero radial displacement); indenter by an active set on the surface nodes
(frictionless: only the axial displacement of a node in contact is constrained). Newton iterations with load
stepping, automatic step cutting, and failure detection: element inversion, Newton non-convergence and excessive
distortion raise :class:`~.body.MechanicsError` naming the indentation.

The FE solves the dimensionless problem (lengths in mm, stresses in units of mu) and converts to SI in one place,
:func:`~.body._newton_per_mu_mm2`.

Known limit (measured by bench/mechanics.py): with the magnet bonded and its edges sharp, as the paper's model
has it, the silicone at the magnet's lower outer edge is crushed while the magnet is pushed down. The strain there
is singular, so the indentation at which the FE reports excessive distortion (or, without the stretch limit,
element inversion) falls as the mesh is refined (MagOne: 2.4 mm at a 1 mm mesh, 2.0 mm at 0.5 mm, 1.6 mm at
0.25 mm), while the force up to that point converges. The paper's 3 mm range was "limited by stress concentration
at the magnet edge": the same effect. ``fe(..., on_failure="truncate")`` returns the curve up to the failure and
says where and why, for a caller that uses the failure as the range limit.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from .body import Body, Curve, MechanicsError, _check_indentation, _check_mu, _newton_per_mu_mm2, check_option
from .discretisation import _axisym
from .indentation import MagnetInterface, _Indentation, _State, _StepFailure
from .material import _material
from .mesh import Wall, _body_mesh, check_void, mesh_size
from .options import MaterialLaw, MechanicsModel, OnFailure

__all__ = ["fe", "STRETCH_LIMIT"]

#: Largest principal stretch (and smallest, as its inverse) the FE accepts before calling the mesh too distorted
#: to trust: 10 is Ecoflex's elongation at break (~900 %), beyond which no silicone answer is physical.
STRETCH_LIMIT = 10.0


def fe(body: Body, mu_kPa: float, indentation_mm: Sequence[float] | np.ndarray, mesh_mm: float | None = None,
       material: MaterialLaw | str = MaterialLaw.NEO_HOOKEAN, yeoh_ratios: tuple[float, float] | None = None,
       refine: int = 0, refine_near_apex_mm: float = 0.0, stretch_limit: float = STRETCH_LIMIT,
       base_bonded: bool = True, on_failure: OnFailure | str = OnFailure.RAISE,
       interface: MagnetInterface | str = MagnetInterface.BONDED, void: Wall | None = None,
       probe: Callable[[float, _Indentation, _State], None] | None = None) -> Curve:
    """Axisymmetric large-strain FE of the indentation (module doc). Returns a :class:`~.body.Curve`.

    ``mesh_mm``: element size in mm (default ``radius / 12``, 0.5 mm for MagOne); ``refine``: extra refinement
    rounds (uniform, or near the apex within ``refine_near_apex_mm``). ``material``: "neo-hookean", or "yeoh" with
    ``yeoh_ratios = (C20/C10, C30/C10)`` (C10 = mu/2): the recipes' fits (recipes/materials.toml yeoh_k2, yeoh_k3;
    the build passes them for predict.material_law = "yeoh"). ``base_bonded = False`` lets the base slide
    (frictionless), for checks against the homogeneous uniaxial solution.

    The magnet's interface (``interface``): "bonded" (the build's model, :data:`MODEL_DESCRIPTION`) or "sliding"
    (bilateral frictionless contact on the reference normals of its rounded profile; exact on its flat faces, on
    the rounded edges a node sliding by s leaves the arc by ~s^2 / (2 edge radius), reported as
    ``info["max_slide_mm"]``). ``void``: the silicone removed inside a wall from the base to the magnet's lower
    face (:func:`~.mesh.channel_wall` gives the design's open insertion channel and funnel); the void's walls
    are free surfaces, their contact with each other or with the magnet is not modelled.

    ``probe``: called as ``probe(indentation_mm, problem, converged state)`` at each indentation reached (a
    :class:`~.shear_surface.ShearProbe` solves the shear response there, on this load path).

    Steps through the indentations in order, halving a failing step (down to 1/64 of it). On element inversion,
    Newton non-convergence, or a principal stretch beyond ``stretch_limit`` (or below its inverse) it raises
    :class:`MechanicsError` naming the indentation; with ``on_failure = "truncate"`` it instead returns the curve
    up to the last indentation reached, with the failure in ``info["failure"]`` and ``info["failed_at_mm"]``.
    """
    mu = _check_mu(mu_kPa)
    d = _check_indentation(indentation_mm)
    law = check_option(MaterialLaw, material, "material")
    mat = _material(law, yeoh_ratios)
    policy = check_option(OnFailure, on_failure, "on_failure")
    interface = check_option(MagnetInterface, interface, "interface")
    mesh = _body_mesh(body, mesh_size(body, mesh_mm), int(refine), float(refine_near_apex_mm), check_void(body, void))
    prob = _Indentation(body, _axisym(mesh), mat, bool(base_bonded), interface)
    path = _LoadPath(prob, stretch_limit)
    out = np.zeros((d.size, 6))  # force, tangent, magnet displacement, max stretch, max stress, peak stretch
    slide = np.zeros(d.size)  # largest slide along a sliding magnet's surface, mm
    done = 0
    info: dict[str, object] = {"elements": int(mesh.t.shape[1]), "dofs": int(prob.ndof),
                               "min_angle_deg": mesh.min_angle_deg, "material": law.value}
    if interface != MagnetInterface.BONDED or void:
        info.update(interface=interface.value, void=void, max_slide_mm=slide)
    try:
        for i, target in enumerate(d):
            path.reach(target)
            out[i] = path.record(target)
            if probe is not None:  # e.g. a ShearProbe: the shear response at this converged preload
                probe(float(target), prob, path.state)
            slide[i] = prob.magnet_slide(path.state.x)
            done = i + 1
    except MechanicsError as exc:
        if policy == OnFailure.RAISE:
            raise
        info.update(failure=str(exc), failed_at_mm=float(d[done]) if done < d.size else math.nan)
    unit = _newton_per_mu_mm2(mu)
    out, d = out[:done], d[:done]
    if "max_slide_mm" in info:
        info["max_slide_mm"] = slide[:done]
    F, tangent = out[:, 0] * unit, out[:, 1] * unit
    info.update(newton_iterations=path.iterations, step_cuts=path.cuts, tangent_N_per_mm=tangent,
                peak_stretch=out[:, 5].copy())
    return Curve(MechanicsModel.FE.value, mu, d, F, out[:, 2], _smooth_stiffness(d, F, tangent), out[:, 3],
                 out[:, 4] * mu, mesh_mm=mesh.h, info=info)


class _LoadPath:
    """Load stepping along the indentation: the last converged state, the last two for the predictor, and the
    Newton iterations and step cuts it took."""

    def __init__(self, prob: _Indentation, stretch_limit: float):
        self.prob, self.stretch_limit = prob, stretch_limit
        self.state: _State = prob.rest()
        self.current = 0.0
        self.hist: list[tuple[float, np.ndarray]] = [(0.0, self.state.x)]
        self.iterations = self.cuts = 0
        self.rate: np.ndarray | None = None  # d x / d delta at the current state, if :meth:`record` computed it
        self.extremes = prob.energy.extremes(self.state.x)  # of the current state: checked once, recorded after

    def reach(self, target: float) -> None:
        """Step from the current indentation to ``target`` (mm), halving a failing step down to 1/64 of what is
        left; raises :class:`MechanicsError` naming the indentation if that fails or the stretch limit is passed."""
        prob, h = self.prob, self.prob.disc.mesh.h
        step = target - self.current
        while self.current < target:
            trial = min(self.current + step, target)
            if self.rate is not None:  # Euler predictor along the path's tangent: second-order accurate
                guess = self.state.x + self.rate * (trial - self.current)
            else:
                guess = _extrapolate(self.hist, trial)
            if not prob.energy.admissible(guess):
                guess = self.state.x.copy()
            try:
                new = prob.solve(guess, self.state.active.copy(), trial)
            except _StepFailure as exc:
                step *= 0.5
                self.cuts += 1
                if step < (target - self.current) / 64.0:
                    raise MechanicsError(f"fe (mesh {h:g} mm): {exc} at indentation {trial:.4g} mm "
                                         f"(last converged {self.current:.4g} mm)") from None
                continue
            self.iterations += new.iterations
            extremes = prob.energy.extremes(new.x)
            lmax, lmin = extremes[:2]
            if lmax > self.stretch_limit or lmin < 1.0 / self.stretch_limit:
                raise MechanicsError(f"fe (mesh {h:g} mm): excessive distortion at indentation "
                                     f"{trial:.4g} mm: principal stretches {lmin:.3g} to {lmax:.3g} leave "
                                     f"[1/{self.stretch_limit:g}, {self.stretch_limit:g}]")
            self.state, self.current, self.rate, self.extremes = new, trial, None, extremes
            self.hist = [*self.hist, (self.current, self.state.x)][-2:]

    def record(self, delta: float) -> tuple[float, float, float, float, float, float]:
        """(force, tangent, magnet displacement, largest averaged stretch, largest |stress|, largest pointwise
        stretch) at ``delta``, in units of mu."""
        prob, x = self.prob, self.state.x
        F, K, self.rate = prob.force(self.state, delta)
        lmax, _, smax, peak = self.extremes
        return F, K, prob.magnet_displacement(x), lmax, smax, peak


def _smooth_stiffness(d: np.ndarray, F: np.ndarray, tangent: np.ndarray) -> np.ndarray:
    """dF/d(delta) along an FE curve: second-order differences of the force where there are neighbours, else
    the consistent tangent. The tangent is exact for the discrete model but jumps by a few % each time a surface
    node enters contact; differences of the converged forces average over those jumps. At zero indentation the
    tangent is kept (a hemispherical cap's force grows as delta^1.5 there, which differences cannot follow)."""
    k = tangent.copy()
    if d.size >= 3 and np.all(np.diff(d) > 0):
        k[1:] = np.gradient(F, d, edge_order=2)[1:]
    return k


def _extrapolate(hist: list[tuple[float, np.ndarray]], delta: float) -> np.ndarray:
    """Linear predictor along the solution path from the last two converged states."""
    if len(hist) < 2:
        return hist[-1][1].copy()
    (d0, x0), (d1, x1) = hist
    if d1 <= d0:
        return x1.copy()
    return x1 + (x1 - x0) * ((delta - d1) / (d1 - d0))
