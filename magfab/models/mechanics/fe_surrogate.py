"""A surrogate of the elastomer FE over dimensionless geometry, for the design search.

The FE (:func:`~.fe.fe` with a :class:`~.shear_surface.ShearProbe`, as the build runs it) takes seconds per design;
the search evaluates thousands. Neo-Hookean results scale exactly: with every length multiplied by R and the modulus
by mu, forces scale with mu R^2, displacements with R, stiffnesses with mu R, tilts per newton with 1 / (mu R^2) and
displacements per newton with 1 / (mu R), stretches not at all. So one table of FE runs on bodies of radius
R = 6 mm covers every size: each body is four ratios to its radius,

    a = magnet radius / R,  h = magnet height / R,  z = magnet's lower face above the base / R,
    c = silicone above the magnet on the axis / R     (hemispherical tip; the body's height is z + h + c),

and each run gives, on a fixed grid of indentation over R (:data:`GRID`), the force, magnet travel, peak stretch,
stiffness and peak stress, and at every other grid point the shear response (preload, magnet drop, lateral
displacement and tilt per newton, indenter stiffness, patch radius). The table's runs are a Latin hypercube over
:data:`BOX`; a radial-basis interpolator (scipy's ``RBFInterpolator``, thin-plate spline with a linear term) per grid
point maps the four ratios to every output there, fitted on the runs that reached it; a last one gives the depth
each run reached (the FE stops where an element inverts or a stretch passes its limit), where the surrogate's curve
ends too. Its error is measured on held-out runs of another hypercube (``held_out`` in the data file) and by
``bench/design.py`` on whole designs against the full chain.

A flat tip is a second family with its own table (``fe_surrogate_flat.json``, :data:`FLAT_BOX`): the same four
ratios (``c`` the silicone above the magnet to the flat top; the body's height is z + h + c), the same grid, fit and
scaling, from 203 FE runs (the hemispherical tip's: 478; the held-out errors of both are in their files and
bench/fe_surrogate.py's doc). Its box is the example targets' and the bench target sets' flat-tip designs with a
margin, and its held-out runs are the ratios of designs drawn over the example targets' box and a hypercube over
what the bench sets added.

The Yeoh law (``predict.material_law = "yeoh"``) is scale-free too (its ratios k2 = C20/C10 and k3 = C30/C10 are
dimensionless), but each silicone has its own k2. Every recipe's fit has k3 = 0 and k2 from 0.013 to 0.057, and the
FE's response is close to linear in k2 over that span (MagOne's force at 3 mm: 3.001, 3.163, 3.480 at k2 = 0, 0.02,
0.057; linear from the ends gives 3.169 at 0.02). So each tip has a second table (``fe_surrogate_yeoh.json``,
``fe_surrogate_flat_yeoh.json``): the same bodies run at k2 = :data:`YEOH_K2`, and a silicone's outputs are the two
tables' blended linearly in its k2. The blend's error is measured on the held-out bodies run at
:data:`YEOH_HELD_OUT_K2` (in the file; as small as the neo-Hookean table's own). A Yeoh law past YEOH_K2 or with
k3 > 0 is the FE's.

Used only inside its family's box (:data:`BOXES`) and for bodies :class:`~.body.Body` accepts: anything else is
:class:`OutsideRegion`, and the search evaluates it with the FE.

Not scale-free, so approximated: the magnet's edge radius (the recipe's 0.2 mm at R = 6 mm) and the rest patch of
the shear probe (the scan step) keep their ratio to R = 6 mm; the held-out error includes what that costs.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import cache
from importlib import resources

import numpy as np

from ...spec import Tip
from .body import Body, Curve, MechanicsError
from .fe import fe
from .options import OnFailure
from .shear_surface import ShearProbe, ShearResponse

# Imported lazily, inside the functions that use it, for speed: scipy takes a
# noticeable time to import, and importing this module should not.

__all__ = ["OutsideRegion", "load", "BOX", "FLAT_BOX", "BOXES", "GRID", "in_region", "curve", "normal_and_shear",
           "held_out_error", "description", "ratios", "body_of", "run", "fit_data", "fit_yeoh_data", "YEOH_K2"]

#: The box of ratios the table covers (a, h, z, c), and so the surrogate's validated region: the example targets'
#: whole box and the bench target sets' (bench/targets/; 1,500-point hypercubes of each set's search coordinates:
#: hemispherical designs reach a 0.883, h 1.057, c 0.992, z down to 0.176), with a margin.
BOX = {"a": (0.10, 0.92), "h": (0.08, 1.10), "z": (0.15, 2.20), "c": (0.05, 1.05)}
#: The flat tip's box: the ratios of the example targets' whole box of flat-tip designs (every stock disc, elastomer
#: 8-14 mm, cover 0.5-3 mm, d_max 3-10 mm; 813 of 2000 hypercube points: a 0.227-0.914, h 0.143-0.792, z 0.219-2.008,
#: c 0.077-0.706) and the bench target sets' (as above: a 0.913, h 1.053, c 0.928, z down to 0.195), with a margin. A
#: flat tip's body needs no height of R, so the magnet may fill nearly the radius.
FLAT_BOX = {"a": (0.20, 0.95), "h": (0.12, 1.10), "z": (0.15, 2.15), "c": (0.07, 1.05)}
#: Each tip's box.
BOXES = {Tip.HEMISPHERE: BOX, Tip.FLAT: FLAT_BOX}
#: Least silicone between the magnet's top corner and the cap, over R, the surrogate answers for (the hypercube has
#: few bodies nearer the cap: they are rejected when the magnet pierces it).
CAP_CLEARANCE = 0.05
#: Indentation over R at the table's columns: graded finer near zero (a rounded tip's force rises as delta^1.5).
GRID = 0.75 * np.linspace(0.0, 1.0, 25) ** 1.5
#: The shear response's columns: every other grid point.
PROBED = np.arange(0, GRID.size, 2)
#: The deepest preload (over R) the surrogate gives the shear response at. Deeper, the lateral compliance of many
#: bodies diverges (the loaded cap loses lateral stability: the FE's displacement per newton grows by 10x and changes
#: sign within a few grid points), which no smooth fit follows: the held-out error of the displacement per newton
#: was 3.8 % (median) at 0.5 R and 29 % at 0.65 R, against under 2.8 % up to 0.41 R.
SHEAR_DEPTH_MAX = float(GRID[PROBED[8]])
#: The table's bodies: radius, mesh, magnet edge radius and rest patch depth, mm (MagOne's build values).
R_TABLE, MESH_TABLE, EDGE_TABLE, REST_TABLE = 6.0, 0.75, 0.2, 0.05
MU_TABLE = 1.0  # kPa: the table is per unit modulus
DATA = "fe_surrogate.json"
#: Each tip's data file.
DATAS = {Tip.HEMISPHERE: DATA, Tip.FLAT: "fe_surrogate_flat.json"}
#: The Yeoh law's tables: the same bodies run with C20/C10 = YEOH_K2 (and C30 = 0, as every recipe's fit), one file
#: per tip; a silicone's k2 between 0 and YEOH_K2 is a linear blend of the two tables (:func:`_predict`), whose
#: error is measured on held-out bodies run at YEOH_HELD_OUT_K2. YEOH_K2 is just above the stiffest-stiffening fit
#: (Dragon Skin 10, 0.057).
YEOH_K2, YEOH_HELD_OUT_K2 = 0.06, 0.03
YEOH_DATAS = {Tip.HEMISPHERE: "fe_surrogate_yeoh.json", Tip.FLAT: "fe_surrogate_flat_yeoh.json"}
CURVE_KEYS = ("force", "travel", "stretch", "stiffness", "stress")
SHEAR_KEYS = ("preload", "drop", "disp", "tilt", "kind", "patch")
#: Outputs fitted in log space (positive, spanning decades): the rest as they are.
LOG_KEYS = ("force", "stiffness", "stress", "preload", "disp", "kind")
#: Outputs fixed at rest (no load: no force, travel, stress, drop; stretch 1): not fitted at the first grid point.
AT_REST = {"force": 0.0, "travel": 0.0, "stretch": 1.0, "stress": 0.0, "preload": 0.0, "drop": 0.0}


class OutsideRegion(MechanicsError):
    """A body the surrogate was not validated for: the search evaluates it with the FE instead."""


def ratios(body: Body) -> dict[str, float]:
    """The four ratios of a body (module doc)."""
    R = body.radius_mm
    return {"a": body.magnet_radius_mm / R, "h": body.magnet_height_mm / R, "z": body.magnet_z_mm / R,
            "c": (body.height_mm - body.magnet_top_mm) / R}


def body_of(x: dict[str, float], R: float = R_TABLE, tip: Tip = Tip.HEMISPHERE) -> Body:
    """The body of ratios ``x`` at radius ``R`` with tip ``tip`` (:class:`MechanicsError` if it cannot exist)."""
    H = (x["z"] + x["h"] + x["c"]) * R
    rm, hm = x["a"] * R, x["h"] * R
    return Body(radius_mm=R, height_mm=H, base_height_mm=H - R if tip == Tip.HEMISPHERE else H, tip=tip,
                magnet_radius_mm=rm,
                magnet_height_mm=hm, magnet_z_mm=x["z"] * R,
                magnet_edge_radius_mm=min(EDGE_TABLE * R / R_TABLE, 0.25 * min(2.0 * rm, hm)))


def in_region(body: Body, k2: float = 0.0, k3: float = 0.0) -> bool:
    """Whether the surrogate answers for ``body`` under the law with Yeoh ratios (k2, k3) (0, 0: neo-Hookean)."""
    return _refusal(body, k2, k3) == ""


def _refusal(body: Body, k2: float = 0.0, k3: float = 0.0) -> str:
    if k3 > 0.0 or k2 > YEOH_K2 + 1e-12:
        return f"the Yeoh tables are for C30 = 0 and C20/C10 up to {YEOH_K2:g}, not ({k2:g}, {k3:g})"
    if body.tip not in BOXES:
        return f"the surrogate covers {' and '.join(t.value for t in BOXES)} tips only"
    if not body.has_magnet:
        return "the surrogate covers bodies with a magnet only"
    R, corner_z = body.radius_mm, body.magnet_top_mm - body.base_height_mm
    if body.tip == Tip.HEMISPHERE and corner_z > 0 and R - math.hypot(body.magnet_radius_mm, corner_z) \
            < CAP_CLEARANCE * R:
        return f"the magnet's corner is within {CAP_CLEARANCE:g} R of the cap, where the table has few runs"
    for k, v in ratios(body).items():
        lo, hi = BOXES[body.tip][k]
        if not lo - 1e-9 <= v <= hi + 1e-9:
            return f"ratio {k} = {v:.3g} is outside the surrogate's validated {lo:g}-{hi:g}"
    return ""


# ---------------------------------------------------------------------------------------------------------------
# The table: FE runs (what bench/fe_surrogate.py makes and ships)


def run(x: dict[str, float], tip: Tip = Tip.HEMISPHERE, k2: float = 0.0) -> dict[str, object]:
    """One FE run of the table: the body of ratios ``x`` at R_TABLE with tip ``tip``, its curve on GRID and its shear
    response on PROBED, per unit modulus, as plain lists (NaN where the FE stopped), with the seconds it took.
    ``k2`` > 0: the Yeoh law with that C20/C10 (and C30 = 0, as every recipe's fit) instead of the neo-Hookean."""
    body = body_of(x, tip=tip)
    d = GRID * R_TABLE
    probe = ShearProbe(depths_mm=d[PROBED], rest_indentation_mm=REST_TABLE)
    t0 = time.perf_counter()
    curve = fe(body, MU_TABLE, d, mesh_mm=MESH_TABLE, on_failure=OnFailure.TRUNCATE, probe=probe,
               material="yeoh" if k2 > 0.0 else "neo-hookean", yeoh_ratios=(k2, 0.0) if k2 > 0.0 else None)
    seconds = time.perf_counter() - t0
    resp = probe.response(MU_TABLE)
    n = len(curve.force_N)

    def col(values, size) -> list[float]:
        v = np.full(size, math.nan)
        v[:len(values)] = values
        return [float(f"{t:.9g}") for t in v]

    out: dict[str, object] = {"x": x, "reach": float(d[n - 1] / R_TABLE) if n else 0.0, "seconds": seconds}
    for key, arr in zip(CURVE_KEYS, (curve.force_N, curve.magnet_displacement_mm, curve.max_stretch,
                                     curve.stiffness_N_per_mm, curve.max_stress_kPa)):
        out[key] = col(arr, GRID.size)
    for key, arr in zip(SHEAR_KEYS, (resp.normal_force_N, resp.magnet_drop_mm, resp.displacement_mm_per_N,
                                     resp.tilt_rad_per_N, resp.stiffness_N_per_mm, resp.patch_radius_mm)):
        out[key] = col(arr, PROBED.size)
    return out


def fit_data(runs: Sequence[dict], held_out: Sequence[dict], tip: Tip = Tip.HEMISPHERE) -> dict[str, object]:
    """The shipped data of tip ``tip``: the table's runs, the held-out runs and their errors against the surrogate
    fitted on the table (:func:`_errors`). No timings: the same FE runs give the same bytes (bench/fe_surrogate.py
    prints the speed)."""
    return {**_header(tip), "runs": list(runs), "held_out": list(held_out),
            "held_out_error": _errors(_Model(list(runs), BOXES[tip]), held_out)}


def _header(tip: Tip) -> dict[str, object]:
    """What a data file says of its table: the box, the grids, the table's radius and mesh."""
    return {"box": BOXES[tip], "grid": [float(g) for g in GRID], "probed": [int(i) for i in PROBED],
            "r_table_mm": R_TABLE, "mesh_table_mm": MESH_TABLE}


# ---------------------------------------------------------------------------------------------------------------
# The model


def _scaled(x: np.ndarray, box: dict[str, tuple[float, float]]) -> np.ndarray:
    lo = np.array([box[k][0] for k in "ahzc"])
    hi = np.array([box[k][1] for k in "ahzc"])
    return (np.atleast_2d(x) - lo) / (hi - lo)


@dataclass
class _Column:
    """The interpolator at one grid point: every output there, for the runs that reached it."""

    keys: tuple[str, ...]
    # scipy's RBFInterpolator, or None where fewer runs reached it than it needs
    rbf: Callable[[np.ndarray], np.ndarray] | None


class _Model:
    def __init__(self, runs: list[dict], box: dict[str, tuple[float, float]]):
        from scipy.interpolate import RBFInterpolator

        self.box = box
        X = _scaled(np.array([[r["x"][k] for k in "ahzc"] for r in runs]), box)
        self.reach = RBFInterpolator(X, np.array([r["reach"] for r in runs]), kernel="thin_plate_spline", degree=1)
        self.columns: list[_Column] = []
        for k in range(GRID.size):
            keys = tuple(key for key in CURVE_KEYS + (SHEAR_KEYS if k in PROBED else ()) if k or key not in AT_REST)
            j = int(np.searchsorted(PROBED, k))
            Y = np.array([[_forward(key, r[key][k] if key in CURVE_KEYS else r[key][j]) for key in keys] for r in runs])
            ok = np.all(np.isfinite(Y), axis=1)
            rbf = (RBFInterpolator(X[ok], Y[ok], kernel="thin_plate_spline", degree=1) if ok.sum() >= 12 else None)
            self.columns.append(_Column(keys, rbf))

    def predict(self, x: np.ndarray) -> tuple[float, dict[str, np.ndarray]]:
        """(reach, outputs on GRID / PROBED) at one point of ratios (a, h, z, c), per unit modulus, at R_TABLE."""
        xs = _scaled(x, self.box)
        reach = float(self.reach(xs)[0])
        out = {k: np.full(GRID.size, math.nan) for k in CURVE_KEYS}
        out.update({k: np.full(PROBED.size, math.nan) for k in SHEAR_KEYS})
        for k, col in enumerate(self.columns):
            if col.rbf is None:
                break
            y = col.rbf(xs)[0]
            j = int(np.searchsorted(PROBED, k))
            for key, v in zip(col.keys, y):
                if key in CURVE_KEYS:
                    out[key][k] = _inverse(key, v)
                else:
                    out[key][j] = _inverse(key, v)
        for key, v in AT_REST.items():
            out[key][0] = v
        return reach, out


def _forward(key: str, v: float) -> float:
    if key in LOG_KEYS:
        return math.log(v) if v > 0 else math.nan  # NaN (not reached) stays NaN
    return v


def _inverse(key: str, v: float) -> float:
    return math.exp(v) if key in LOG_KEYS else v


def _shipped(tip: Tip = Tip.HEMISPHERE, yeoh: bool = False) -> tuple[_Model, dict]:
    """Tip ``tip``'s shipped table (the Yeoh one with ``yeoh``) and its model, built once per process."""
    return _loaded(Tip(tip), bool(yeoh))


def load(tip: Tip) -> None:
    """Build tip ``tip``'s models (both laws' tables) now, as its first design would otherwise (about 0.2 s each): a
    study's workers do this while the study plans its first phase (:func:`magfab.inverse.evaluate.warm_up`)."""
    for yeoh in (False, True):
        _shipped(tip, yeoh)


@cache  # one entry per (tip, law): four in all
def _loaded(tip: Tip, yeoh: bool) -> tuple[_Model, dict]:
    # One key per table, however a caller spells its arguments: a bounded cache keyed on the spelling held the
    # tables of a two-tip Yeoh search in six entries and rebuilt one on most designs (0.2 s each, 10x the design).
    name = (YEOH_DATAS if yeoh else DATAS)[tip]
    data = json.loads(resources.files("magfab.models.mechanics").joinpath(name).read_text(encoding="utf-8"))
    return _Model(data["runs"], BOXES[tip]), data


class _Blend:
    """The neo-Hookean table's model and the Yeoh one's, blended linearly in k2 (module doc; :data:`YEOH_K2`)."""

    def __init__(self, neo: _Model, yeoh: _Model, k2: float):
        self.neo, self.yeoh, self.w = neo, yeoh, k2 / YEOH_K2

    def predict(self, x: np.ndarray) -> tuple[float, dict[str, np.ndarray]]:
        (r0, t0), (r1, t1) = self.neo.predict(x), self.yeoh.predict(x)
        return r0 + self.w * (r1 - r0), {key: t0[key] + self.w * (t1[key] - t0[key]) for key in t0}


def _model(tip: Tip, k2: float) -> _Model | _Blend:
    """The model for a silicone with Yeoh ratio ``k2`` (0: neo-Hookean, the first table alone)."""
    neo = _shipped(tip)[0]
    return _Blend(neo, _shipped(tip, True)[0], k2) if k2 > 0.0 else neo


def held_out_error(tip: Tip = Tip.HEMISPHERE, yeoh: bool = False) -> dict[str, float]:
    """The shipped table's held-out errors for tip ``tip`` (relative: median, RMS, 90th percentile and max per
    output, at the table's grid points); ``yeoh``: the blend's, at :data:`YEOH_HELD_OUT_K2`."""
    return dict(_shipped(Tip(tip), yeoh)[1]["held_out_error"])


def fit_yeoh_data(runs: Sequence[dict], held_out: Sequence[dict], tip: Tip = Tip.HEMISPHERE) -> dict[str, object]:
    """The shipped Yeoh data of tip ``tip``: the table's bodies run at :data:`YEOH_K2`, held-out bodies run at
    :data:`YEOH_HELD_OUT_K2`, and the errors of the blend (the shipped neo-Hookean table and this one) on them."""
    blend = _Blend(_shipped(tip)[0], _Model(list(runs), BOXES[tip]), YEOH_HELD_OUT_K2)
    return {**_header(tip), "k2": YEOH_K2, "held_out_k2": YEOH_HELD_OUT_K2, "runs": list(runs),
            "held_out": list(held_out), "held_out_error": _errors(blend, held_out)}


def _errors(model: _Model | _Blend, held_out: Sequence[dict]) -> dict[str, float]:
    """Relative errors of the surrogate on held-out runs, over the grid points both reached (force from the second
    grid point on: the first is zero)."""
    errs: dict[str, list[float]] = {"force": [], "travel": [], "stretch": [], "disp": [], "reach": []}
    for r in held_out:
        reach, out = model.predict(np.array([r["x"][k] for k in "ahzc"]))
        errs["reach"].append(abs(reach - r["reach"]) / max(r["reach"], 1e-9))
        for key in ("force", "travel", "stretch", "disp"):
            truth, guess = np.array(r[key], dtype=float), out[key]
            both = np.isfinite(truth) & np.isfinite(guess) & (np.abs(truth) > 0)
            if key == "disp":  # the shear response is given up to SHEAR_DEPTH_MAX only
                both &= GRID[PROBED] <= SHEAR_DEPTH_MAX + 1e-12
            if key == "stretch":
                both &= truth > 1.0
                errs[key] += list(np.abs(guess[both] - truth[both]) / (truth[both] - 1.0 + 1e-12))
            else:
                errs[key] += list(np.abs(guess[both] - truth[both]) / np.abs(truth[both]))
    summary: dict[str, float] = {}
    for key, values in errs.items():
        e = np.array(values, dtype=float)
        summary[f"{key}_max"] = float(e.max()) if e.size else math.nan
        summary[f"{key}_median"] = float(np.median(e)) if e.size else math.nan
        summary[f"{key}_rms"] = float(np.sqrt(np.mean(e**2))) if e.size else math.nan
        summary[f"{key}_p90"] = float(np.percentile(e, 90)) if e.size else math.nan
    return summary


def description(tip: Tip = Tip.HEMISPHERE, yeoh: bool = False) -> str:
    """One line for the report and the ModelUse: what the surrogate of tip ``tip`` is and its held-out error
    (``yeoh``: the blend of the neo-Hookean and the Yeoh tables)."""
    tip = Tip(tip)
    e = held_out_error(tip, yeoh)
    law = (f"Yeoh law: the neo-Hookean and the k2 = {YEOH_K2:g} tables blended linearly in k2, held out at "
           f"k2 = {YEOH_HELD_OUT_K2:g}" if yeoh else "neo-Hookean")
    return (f"Surrogate of the elastomer FE over dimensionless geometry, {tip.value} tip, {law} (RBF over 4 ratios, "
            f"{len(_shipped(tip, yeoh)[1]['runs'])} FE runs); held-out error: force RMS {100 * e['force_rms']:.1f} % "
            f"(90th percentile {100 * e['force_p90']:.1f} %), magnet travel RMS {100 * e['travel_rms']:.1f} %")


def _interpolate(x: np.ndarray, y: np.ndarray, at: np.ndarray, log: bool) -> np.ndarray:
    """Monotone cubic (PCHIP) interpolation; ``log``: in log-log for a quantity that is zero at zero and grows as a
    power near it (force ~ delta^1.5 on a rounded tip: linear PCHIP on the table's grid is 12 % off at MagOne's first
    indentation, log-log 7 %, measured)."""
    from scipy.interpolate import PchipInterpolator

    if not log:
        return PchipInterpolator(x, y)(at)
    pos = (x > 0) & (y > 0)
    out = np.zeros_like(np.asarray(at, dtype=float))
    nz = at > 0
    out[nz] = np.exp(PchipInterpolator(np.log(x[pos]), np.log(y[pos]), extrapolate=True)(np.log(at[nz])))
    return out


def _interpolate_linear(x: np.ndarray, ys: list[np.ndarray], at: np.ndarray) -> list[np.ndarray]:
    """:func:`_interpolate` (not in log-log) of several quantities on the same ``x`` at once: one PCHIP over their
    columns, the same numbers as one each (PCHIP's slopes are per column), at a fraction of the set-up cost (a design of
    the search built eleven interpolants, a quarter of its time)."""
    from scipy.interpolate import PchipInterpolator

    return list(PchipInterpolator(x, np.column_stack(ys), axis=0)(at).T.copy())


def curve(body: Body, mu_kPa: float, indentation_mm: np.ndarray) -> Curve:
    """The normal curve alone, over ``indentation_mm`` (what the speed-accuracy chart compares with the FE)."""
    d = np.asarray(indentation_mm, dtype=float)
    return normal_and_shear(body, mu_kPa, d, float(d[-1]), d[:1], REST_TABLE)[0]


def normal_and_shear(body: Body, mu_kPa: float, indentation_mm: np.ndarray, depth_mm: float,
                     probe_depths_mm: np.ndarray, rest_indentation_mm: float,
                     k2: float = 0.0, k3: float = 0.0) -> tuple[Curve, ShearResponse]:
    """What ``predict`` takes from the FE (the nominal curve to ``depth_mm`` and the shear response at
    ``probe_depths_mm``), from the surrogate: the table scaled to this body's radius and modulus, interpolated in
    indentation (PCHIP) onto the indentations asked for; ``k2`` > 0, the Yeoh law's blend (:data:`YEOH_K2`).
    :class:`OutsideRegion` outside the validated region or laws."""
    why = _refusal(body, k2, k3)
    if why:
        raise OutsideRegion(why)
    model = _model(body.tip, k2)
    R, mu = body.radius_mm, float(mu_kPa)
    reach, t = model.predict(np.array([ratios(body)[k] for k in "ahzc"]))
    grid = GRID * R
    k = R / R_TABLE  # the table is at R_TABLE and per unit modulus (MU_TABLE = 1 kPa)
    fin = np.isfinite(t["force"]) & (grid <= max(reach, 0.0) * R + 1e-9)
    if fin.sum() < 3:
        raise OutsideRegion(f"the surrogate's curve ends at once for this body (reach {reach * R:.3g} mm)")
    if any((t[key][fin & (grid > 0)] <= 0).any() for key in ("force", "travel")):
        raise OutsideRegion("the surrogate's force or travel is not positive at a small indentation of this body "
                            "(interpolated in log-log, it cannot be extrapolated)")
    end = min(max(reach, 0.0) * R, float(grid[fin][-1]))
    d = np.asarray(indentation_mm, dtype=float)
    ends_at = "model" if end < depth_mm else "scan depth"
    last = min(end, depth_mm)
    inside = int(np.count_nonzero(d <= last + 1e-9))
    kept = d[:inside] if inside == d.size or d[inside - 1] >= last - 1e-9 else np.append(d[:inside], last)

    def along(key: str, scale: float) -> np.ndarray:
        return _interpolate(grid[fin], t[key][fin] * scale, kept, log=True)

    stiffness, stretch, stress = _interpolate_linear(grid[fin], [t["stiffness"][fin] * (mu * k), t["stretch"][fin],
                                                                 t["stress"][fin] * mu], kept)
    curve = Curve("surrogate", mu, kept, force_N=along("force", mu * k * k), magnet_displacement_mm=along("travel", k),
                  stiffness_N_per_mm=stiffness, max_stretch=stretch, max_stress_kPa=stress, mesh_mm=None)
    if inside < d.size:
        info = {"failure": (f"the surrogate's curve is solved to {last:g} mm of indentation ("
                            + ("the depth the design is used over, calibration.scan_z_mm)" if ends_at == "scan depth"
                               else "where the FE runs it was fitted on stop)")),
                "failed_at_mm": float(d[inside]), "ends_at": ends_at}
        curve = replace(curve, info=info)
    probe = np.asarray(probe_depths_mm, dtype=float)
    probe = probe[probe <= min(last, SHEAR_DEPTH_MAX * R) + 1e-9]
    pg = grid[PROBED]
    pfin = np.isfinite(t["disp"]) & (pg <= end + 1e-9)
    probed_at = pfin & (pg > 0)
    if np.count_nonzero(probed_at) < 2 or any((t[key][probed_at] <= 0).any() for key in ("preload", "drop")):
        raise OutsideRegion(f"the surrogate's shear probes end at once for this body (its curve ends at {end:.3g} mm) "
                            "or are not positive")

    def probed(key: str, scale: float) -> np.ndarray:
        return _interpolate(pg[pfin], t[key][pfin] * scale, probe, log=True)

    disp, tilt, kind, patch = _interpolate_linear(pg[pfin], [t["disp"][pfin] * (1.0 / (mu * k)),
                                                             t["tilt"][pfin] * (1.0 / (mu * k * k)),
                                                             t["kind"][pfin] * (mu * k), t["patch"][pfin] * k], probe)
    response = ShearResponse("surface", mu, probe, probed("preload", mu * k * k), probed("drop", k), disp, tilt, kind,
                             patch, MESH_TABLE * R / R_TABLE, {"model": "surrogate"})
    return curve, response
