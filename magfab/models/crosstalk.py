"""The crosstalk budget of an array: what each taxel misreads when its neighbours move, and the pitch that keeps it
within the spec's tolerance.

Field: every chip reads every magnet (exact superposition of :func:`magfab.models.field.exact`, a flipped magnet's
field negated). Neighbour j moving through its range (pressed to the end of the normal range, or shifted by the shear
range's lateral travel along x or y) changes chip i's field by dB; taxel i's own calibration reads that as a force,
|dBz| over its normal sensitivity or |dBxy| over its shear sensitivity (the worst of the material and magnet bands:
the smallest sensitivity, the largest misreading). The table i x j holds the worst of those; each taxel's budget is
the worst neighbour alone and every neighbour pressed at once (a broad contact: the signed sum, where alternating
polarity matters; alone, a neighbour's misreading has the same size whichever way it is magnetised).

Mechanics: separate tips stand on a rigid pad, so a load on one does not move another. In a continuous skin a load
over taxel i moves magnet j by c(r) of magnet i's own travel (:mod:`magfab.models.mechanics.coupling`, a bonded
layer's axisymmetric FE); taxel j then reads about c(r) times the load on i.

The budget is against ``array.crosstalk_mN`` (default: the taxel's normal resolution). The least pitch is found by
scaling the layout (a grid's pitch, or explicit positions about their centre) over a sweep and bisecting the last
crossing; for both polarities. The magnets also push on each other (side by side, same polarity repels, opposite
attracts): the force between the nearest two at rest, by dipoles and checked by the exact field's energy, and the net
force on every magnet with the lateral shift it gives through the softest shear stiffness (a warning past a tenth of
the shear travel). Saturation: a chip's own magnet at d_min plus its neighbours at rest against the z full scale; the
neighbours' lateral field plus the own magnet slid through its shear travel against the xy full scale.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from ..formats import array_json
from ..units import UT_PER_GAUSS
from . import field as fieldmod
from .mechanics.coupling import coupling
from .taxels import array_field

if TYPE_CHECKING:
    from ..design import ArrayLayout, Design
    from ..spec import Array
    from .predict import Prediction

__all__ = ["Crosstalk", "crosstalk", "layout_errors", "compensated_errors", "pitch_budget", "least_pitch",
           "magnet_forces"]

#: Pitches swept for the least pitch: from the parts' minimum up to this many times the spec's pitch (or 60 mm).
SWEEP_POINTS = 48
MU0 = 4e-7 * math.pi
#: The least pitch with the host's compensation is swept (a third of the points) for arrays up to this many taxels;
#: its cost grows as N^3 (every neighbour's motion, every chip, the compensation's sweeps).
COMPENSATED_SWEEP_MAX = 8
@dataclass(frozen=True)
class _Loads:
    """What each neighbour does and how a taxel reads it."""

    magnet: fieldmod.Magnet
    z_chip: float
    z_centre: float
    normal_travel_mm: float
    shear_travel_mm: float
    normal_G_per_N: float
    shear_G_per_N: float
    range_N: float
    shear_stiffness_N_per_mm: float  # the softest of the material band's lateral stiffness at the magnet

    @classmethod
    def of(cls, design: Design, pred: Prediction) -> _Loads:
        stiff = min(pred.shear.stiffness_N_per_mm.values())
        return cls(fieldmod.Magnet.from_design(design), design.z_sense_mm,
                   design.z_magnet_low_mm + design.magnet_height_mm / 2.0, pred.normal.travel_mm,
                   pred.shear.range_N / stiff, min(pred.normal.sensitivity_G_per_N),
                   min(pred.shear.sensitivity_G_per_N), pred.normal.range_N, stiff)


def layout_errors(loads: _Loads, xy: np.ndarray, signs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(field error i x j in mN, every neighbour pressed at once per taxel in mN, the neighbours' field at rest per
    chip in G) for magnets over chips at ``xy`` (N, 2) mm with polarities ``signs``."""
    n = len(xy)
    chips = np.column_stack([xy, np.full(n, loads.z_chip)])
    centres = np.column_stack([xy, np.full(n, loads.z_centre)])
    moves = [(0.0, 0.0, -loads.normal_travel_mm)] + [(sx * loads.shear_travel_mm, sy * loads.shear_travel_mm, 0.0)
                                                      for sx, sy in ((1, 0), (-1, 0), (0, 1), (0, -1))]
    pair, pressed, rest = np.zeros((n, n)), np.zeros((n, 3)), np.zeros((n, 3))
    others = ~np.eye(n, dtype=bool)
    for j in range(n):
        at_rest = signs[j] * fieldmod.exact(loads.magnet, chips - centres[j])
        rest += np.where(others[:, j, None], at_rest, 0.0)
        for k, move in enumerate(moves):
            dB = signs[j] * fieldmod.exact(loads.magnet, chips - centres[j] - move) - at_rest
            read = np.maximum(np.abs(dB[:, 2]) / loads.normal_G_per_N,
                              np.hypot(dB[:, 0], dB[:, 1]) / loads.shear_G_per_N)
            pair[:, j] = np.maximum(pair[:, j], np.where(others[:, j], read, 0.0))
            if k == 0:
                pressed += np.where(others[:, j, None], dB, 0.0)
    common = np.maximum(np.abs(pressed[:, 2]) / loads.normal_G_per_N, np.hypot(pressed[:, 0], pressed[:, 1])
                        / loads.shear_G_per_N)
    return 1000.0 * pair, 1000.0 * common, rest


def compensated_errors(design: Design, loads: _Loads, xy: np.ndarray,
                       signs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The field error i x j and every neighbour pressed at once (per taxel), in mN, left after the host's compensation
    (:class:`magfab.formats.array_json.Compensator` with its dynamic terms, on the tables
    :func:`magfab.models.taxels.array_field` makes for this layout): the chips read every magnet exactly, neighbour j
    moved as in :func:`layout_errors`, and the compensated field of chip i is compared with its own magnet's."""

    taxels = tuple(replace(t, x_mm=float(x), y_mm=float(y), polarity=int(sg))
                   for t, (x, y), sg in zip(design.taxels, xy, signs))
    field = array_field(replace(design, array=replace(_arrays(design)[0], taxels=taxels)))
    doc = {"format": array_json.FORMAT, "dynamic": True, **field.as_json(),
           "taxels": [{"index": t.index, "polarity": t.polarity, "i2c_address": t.i2c_address, "calibration": "-"}
                      for t in taxels]}
    comp = array_json.validate(doc)
    n = len(xy)
    chips = np.column_stack([xy, np.full(n, loads.z_chip)])
    centres = np.column_stack([xy, np.full(n, loads.z_centre)])
    at_rest = np.stack([signs[m] * fieldmod.exact(loads.magnet, chips - centres[m]) for m in range(n)], axis=1)
    moves = [(0.0, 0.0, -loads.normal_travel_mm)] + [(sx * loads.shear_travel_mm, sy * loads.shear_travel_mm, 0.0)
                                                      for sx, sy in ((1, 0), (-1, 0), (0, 1), (0, -1))]
    out = np.zeros((n, n))
    for j in range(n):
        for move in moves:
            B = at_rest.copy()
            B[:, j] = signs[j] * fieldmod.exact(loads.magnet, chips - centres[j] - move)
            own = np.array(comp.apply((B.sum(axis=1) * UT_PER_GAUSS).tolist())) / UT_PER_GAUSS
            err = own - np.diagonal(B, axis1=0, axis2=1).T
            read = np.maximum(np.abs(err[:, 2]) / loads.normal_G_per_N, np.hypot(err[:, 0], err[:, 1])
                              / loads.shear_G_per_N)
            out[:, j] = np.maximum(out[:, j], np.where(np.arange(n) != j, read, 0.0))
    common = np.zeros(n)
    for i in range(n):  # every neighbour of i pressed at once
        B = at_rest.copy()
        for j in set(range(n)) - {i}:
            B[:, j] = signs[j] * fieldmod.exact(loads.magnet, chips - centres[j] - moves[0])
        own = np.array(comp.apply((B.sum(axis=1) * UT_PER_GAUSS).tolist())) / UT_PER_GAUSS
        err = own[i] - B[i, i]
        common[i] = max(abs(err[2]) / loads.normal_G_per_N, math.hypot(err[0], err[1]) / loads.shear_G_per_N)
    return 1000.0 * out, 1000.0 * common


def _distances(xy: np.ndarray) -> np.ndarray:
    return np.hypot(xy[:, None, 0] - xy[None, :, 0], xy[:, None, 1] - xy[None, :, 1])


@dataclass(frozen=True)
class Crosstalk:
    """An array's crosstalk budget (module doc). Forces mN, fields G, lengths mm; i x j tables row i (the taxel that
    misreads), column j (the neighbour that moves)."""

    polarity: str
    skin: str
    pitch_mm: float
    tolerance_mN: float
    field_mN: np.ndarray  # (N, N)
    residual_mN: np.ndarray  # (N, N) what the host's compensation leaves of field_mN
    common_mN: np.ndarray  # (N,)
    common_residual_mN: np.ndarray  # (N,) what the compensation leaves of common_mN
    coupling: np.ndarray  # (N, N) fraction of j's own travel that a load on j gives magnet i (0: separate tips)
    mechanical_mN: np.ndarray  # (N, N) what taxel i reads when j is loaded to its range
    offset_G: np.ndarray  # (N, 3) the neighbours' field at rest
    saturation_G: float  # the largest |Bz| a chip reads with its magnet at d_min and its neighbours at rest
    full_scale_G: float
    min_pitch_mm: dict[str, float | None]  # per polarity (None: not within the sweep), uncompensated
    min_pitch_compensated_mm: dict[str, float | None]  # the same with the host's compensation (None: not swept)
    sweep_mm: np.ndarray
    sweep_worst_mN: dict[str, np.ndarray]
    force_mN: float  # between the nearest two magnets at rest, dipoles (+ repels)
    force_exact_mN: float  # the same from the exact field's energy
    coupling_curve: tuple[np.ndarray, np.ndarray] | None  # (r mm, c) for a continuous skin
    coupling_depth_mm: float  # the magnets' depth under the skin's top (0: separate tips)
    magnet_forces_mN: np.ndarray  # (N, 2) net lateral force on each magnet at rest from the others (exact)
    predisplacement_mm: np.ndarray  # (N, 2) the lateral shift it gives the magnet through the softest shear stiffness
    shear_travel_mm: float  # the magnet's lateral travel at the shear range (softest), for scale
    saturation_xy_G: float  # the largest |Bx| or |By|: the neighbours at rest and the own magnet slid its shear travel
    full_scale_xy_G: float

    @property
    def worst_mN(self) -> np.ndarray:
        """Per taxel, as the build ships it (the host compensating): the worst neighbour alone (field left by the
        compensation, and mechanics) or every neighbour pressed at once."""
        return np.maximum((self.residual_mN + self.mechanical_mN).max(axis=1), self.common_residual_mN)

    @property
    def dynamic(self) -> bool:
        """Whether the host should remove a moving neighbour's field (the field crosstalk alone is over budget)."""
        return bool(max(self.field_mN.max(), self.common_mN.max()) > self.tolerance_mN)

    HEADER = ("taxel", "neighbours at rest, G (x, y, z)", "worst neighbour, field, mN", "after compensation, mN",
              "all pressed (compensated), mN", "worst neighbour through the skin, mN", "budget, mN")

    def rows(self) -> list[tuple[str, ...]]:
        return [(str(i), ", ".join(f"{v:+.1f}" for v in self.offset_G[i]), f"{self.field_mN[i].max():.2f}",
                 f"{self.residual_mN[i].max():.2f}", f"{self.common_mN[i]:.2f} ({self.common_residual_mN[i]:.2f})",
                 f"{self.mechanical_mN[i].max():.2f}", f"{self.worst_mN[i]:.2f}") for i in range(len(self.common_mN))]

    def as_json(self) -> dict[str, object]:
        r = lambda a, d=4: np.round(np.asarray(a, dtype=float), d).tolist()
        return {"format": "magfab-crosstalk/1", "polarity": self.polarity, "skin": self.skin,
                "pitch_mm": round(self.pitch_mm, 4), "tolerance_mN": round(self.tolerance_mN, 4),
                "field_mN": r(self.field_mN), "residual_mN": r(self.residual_mN), "common_mN": r(self.common_mN),
                "common_residual_mN": r(self.common_residual_mN), "coupling": r(self.coupling, 5),
                "mechanical_mN": r(self.mechanical_mN), "worst_mN": r(self.worst_mN), "offset_G": r(self.offset_G, 3),
                "saturation_G": round(self.saturation_G, 2), "full_scale_G": round(self.full_scale_G, 2),
                "min_pitch_mm": {k: None if v is None else round(v, 3) for k, v in self.min_pitch_mm.items()},
                "min_pitch_compensated_mm": {k: None if v is None else round(v, 3)
                                             for k, v in self.min_pitch_compensated_mm.items()},
                "parts_min_pitch_mm": round(float(self.sweep_mm[0]), 3), "sweep_mm": r(self.sweep_mm, 3),
                "sweep_worst_mN": {k: r(v) for k, v in self.sweep_worst_mN.items()},
                "magnet_force_mN": round(self.force_mN, 3), "magnet_force_exact_mN": round(self.force_exact_mN, 3),
                "magnet_net_force_mN": r(self.magnet_forces_mN, 3), "predisplacement_mm": r(self.predisplacement_mm, 5),
                "shear_travel_mm": round(self.shear_travel_mm, 4), "saturation_xy_G": round(self.saturation_xy_G, 2),
                "full_scale_xy_G": round(self.full_scale_xy_G, 2),
                "dynamic": self.dynamic, "header": list(self.HEADER), "rows": [list(row) for row in self.rows()]}


def _signs(design: Design, alternating: bool) -> np.ndarray:
    """Polarities for the layout: the design's own where it alternates, else a checkerboard (by grid cell, or by
    index for explicit positions) when asked to alternate."""
    arr = _arrays(design)[1]
    if not alternating:
        return np.ones(len(design.taxels))
    if arr.positions_mm is not None:
        return np.array([(-1.0) ** i for i in range(len(design.taxels))])
    return np.array([(-1.0) ** (i // arr.cols + i % arr.cols) for i in range(len(design.taxels))])


def _mechanical(design: Design, loads: _Loads, xy: np.ndarray, curve) -> tuple[np.ndarray, np.ndarray]:
    """(coupling i x j, what i reads in mN when j is loaded to the range) for a continuous skin; zeros otherwise."""
    n = len(xy)
    if curve is None:
        return np.zeros((n, n)), np.zeros((n, n))
    c = np.where(np.eye(n, dtype=bool), 0.0, curve.at(_distances(xy)))
    return c, 1000.0 * np.abs(c) * loads.range_N


def _magnet_force(loads: _Loads, r_mm: float, same: bool) -> tuple[float, float]:
    """Lateral force (mN, + repels) between two of the magnets side by side ``r_mm`` apart: dipoles, and the exact
    field's energy over magnet 2's volume (Gauss-Legendre in r and z, 12 angles), differentiated centrally."""
    m = loads.magnet
    br = m.remanence_T
    volume = math.pi * m.radius_mm**2 * m.height_mm * 1e-9
    dipole = 3.0 * (br * volume) ** 2 / (4.0 * math.pi * MU0 * (r_mm * 1e-3) ** 4)
    gr, wr = np.polynomial.legendre.leggauss(6)
    gz, wz = np.polynomial.legendre.leggauss(4)
    rr, ww = m.radius_mm * (gr + 1) / 2, wr * m.radius_mm / 2
    zz, wzz = m.height_mm * (gz - 0) / 2, wz * m.height_mm / 2
    th = np.arange(12) * 2 * math.pi / 12
    R, T, Z = np.meshgrid(rr, th, zz, indexing="ij")
    W = (ww[:, None, None] * rr[:, None, None]) * (2 * math.pi / 12) * wzz[None, None, :] * np.ones_like(R)

    def energy(d: float) -> float:  # - M . B integrated, J (B in T, M = Br / mu0)
        pts = np.column_stack([(d + R * np.cos(T)).ravel(), (R * np.sin(T)).ravel(), Z.ravel()])
        bz = fieldmod.exact(m, pts)[:, 2] * 1e-4
        return -(br / MU0) * float(np.sum(bz * W.ravel())) * 1e-9

    h = 0.01
    exact = -(energy(r_mm + h) - energy(r_mm - h)) / (2 * h * 1e-3)
    sign = 1.0 if same else -1.0
    return 1000.0 * sign * dipole, 1000.0 * (exact if same else -exact)


def pitch_budget(design: Design, loads: _Loads, signs: np.ndarray, curve, pitch_mm: float,
                 compensate: bool = False) -> float:
    """The worst taxel's misreading (mN) with ``design``'s layout scaled about its centre to ``pitch_mm`` and
    magnetised ``signs``: the worst neighbour alone (field and, through a continuous skin ``curve``, mechanics) or
    every neighbour pressed at once; ``compensate``: what the host's compensation leaves of the field part."""
    xy = np.array([[t.x_mm, t.y_mm] for t in design.taxels])
    centre = xy.mean(axis=0)
    scaled = centre + (xy - centre) * (pitch_mm / _arrays(design)[0].pitch_mm)
    f, cm = compensated_errors(design, loads, scaled, signs) if compensate else layout_errors(loads, scaled, signs)[:2]
    return float(np.maximum((f + _mechanical(design, loads, scaled, curve)[1]).max(axis=1), cm).max())


def least_pitch(design: Design, loads: _Loads, signs: np.ndarray, curve, sweep: np.ndarray, tol: float,
                compensate: bool = False, steps: int = 30) -> tuple[np.ndarray, float | None]:
    """(:func:`pitch_budget` over ``sweep``, the least pitch from which it stays within ``tol``: bisected between the
    sweep's last failing and first passing pitch, so a budget that dips and rises again is not crossed early; the
    sweep's first pitch when it all passes, None when its last fails)."""
    def budget(p: float) -> float:
        return pitch_budget(design, loads, signs, curve, p, compensate)

    worst = np.array([budget(p) for p in sweep])
    failing = np.flatnonzero(worst > tol)
    if len(failing) == 0:
        return worst, float(sweep[0])
    k = failing[-1]
    if k == len(sweep) - 1:
        return worst, None
    lo, hi = float(sweep[k]), float(sweep[k + 1])
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if budget(mid) > tol else (lo, mid)
    return worst, hi


def magnet_forces(loads: _Loads, xy: np.ndarray, signs: np.ndarray) -> np.ndarray:
    """(N, 2) net lateral force on each magnet at rest from all the others, mN (the exact field's energy, pair by
    pair: like poles push a magnet away from its neighbour, unlike pull it towards)."""
    out = np.zeros((len(xy), 2))
    for i in range(len(xy)):
        for j in range(len(xy)):
            if i != j:
                d = xy[i] - xy[j]
                r = float(np.hypot(*d))
                out[i] += _magnet_force(loads, r, signs[i] == signs[j])[1] * d / r
    return out


def _arrays(design: Design) -> tuple[ArrayLayout, Array]:
    """The design's array layout and the spec's [array] section; ValueError for a single taxel's design."""
    if design.array is None or design.spec.array is None:
        raise ValueError(f"{design.spec.name!r} is a single taxel: crosstalk is an array's")
    return design.array, design.spec.array


def crosstalk(design: Design, pred: Prediction) -> Crosstalk:
    """The budget of ``design``'s array (``design.array`` must not be None)."""
    arr, spec_arr = _arrays(design)
    loads = _Loads.of(design, pred)
    xy = np.array([[t.x_mm, t.y_mm] for t in design.taxels])
    signs = np.array([float(t.polarity) for t in design.taxels])
    tol = spec_arr.crosstalk_mN or pred.normal.resolution_mN
    sweep = np.geomspace(arr.min_pitch_mm, max(4.0 * arr.pitch_mm, 60.0), SWEEP_POINTS)
    span = float(_distances(xy).max()) / arr.pitch_mm
    curve, depth = None, 0.0
    if design.continuous:
        depth = design.elastomer_height_mm - design.pocket_roof_z_mm + design.magnet_height_mm / 2.0
        curve = coupling(design.elastomer_height_mm, depth, min(span * sweep[-1], 60.0))
    field, common, rest = layout_errors(loads, xy, signs)
    c, mech = _mechanical(design, loads, xy, curve)
    worst: dict[str, np.ndarray] = {}
    least: dict[str, float | None] = {}
    least_comp: dict[str, float | None] = {}
    for name, alt in (("same", False), ("alternating", True)):
        s = _signs(design, alt)
        worst[name], least[name] = least_pitch(design, loads, s, curve, sweep, tol)
        least_comp[name] = None
        if len(xy) <= COMPENSATED_SWEEP_MAX:
            least_comp[name] = least_pitch(design, loads, s, curve, sweep[::3], tol, compensate=True, steps=12)[1]
    magnet = loads.magnet
    own_dmin = fieldmod.exact(magnet,
                              np.array([[0.0, 0.0, -(design.spec.sensor.d_min_mm + magnet.height_mm / 2)]]))[0, 2]
    dist = _distances(xy) + np.eye(len(xy)) * 1e9
    i, j = np.unravel_index(np.argmin(dist), dist.shape)
    force, exact = _magnet_force(loads, float(dist[i, j]), signs[i] == signs[j])
    net = magnet_forces(loads, xy, signs)
    residual, common_residual = compensated_errors(design, loads, xy, signs)
    own_slid = abs(fieldmod.exact(magnet,
                                  np.array([[-loads.shear_travel_mm, 0.0, loads.z_chip - loads.z_centre]]))[0, 0])
    return Crosstalk(arr.polarity.value, arr.skin.value, arr.pitch_mm, tol, field, residual, common, common_residual,
                     c, mech, rest,
                     float(np.max(np.abs(own_dmin * signs + rest[:, 2]))), pred.chip.full_scale_z_G, least, least_comp,
                     sweep,
                     worst, force, exact, None if curve is None else (curve.r_mm, curve.ratio), depth,
                     net, net / 1000.0 / loads.shear_stiffness_N_per_mm, loads.shear_travel_mm,
                     float(np.abs(rest[:, :2]).max() + own_slid), pred.chip.full_scale_xy_G)
