"""The acceptance test: what a correctly built sensor reads, as bands a measurement must fall in.

The researcher runs it last, on the finished sensor (``magfab-readout check``): the field at rest, its sign,
the lateral field at rest, and the rise of Bz under a known weight on the tip. :func:`acceptance` computes the
bands from the design, the prediction and the tolerances below; the readout package embeds the result as
``acceptance.json`` (format ``magfab-acceptance/1``) and compares its measurements with it. The two optional
drift steps (``check --rotation``: turned over; ``--warmup``: warmed) take their bands from
:mod:`magfab.models.acceptance_steps`.

Fields are in microtesla (the readout's unit; 1 G = 100 uT), in the chip's axes: +z out of the package top,
towards the magnet. The predictions take the magnet magnetised along +z, i.e. north pole up, away from the
chip: then Bz > 0 at the Hall point. A magnet put in upside down gives the same field with the opposite sign.

**How the bands are combined.** The rest band the check uses is statistical: each tolerance's effect on the
exact field is taken alone (one at a time, at its two ends), the effects are combined root-sum-square on each
side (independent tolerances, the usual tolerance-stack practice), and the Earth's field is added in full. The
every-corner worst case below is also computed and kept (``rest.worst_case_Bz_uT``): it is too wide to catch a
wrong grade, and a real build sits near the nominal in most of its tolerances at once.

The worst case, deterministically: every tolerance is an interval, the field is
evaluated with the exact cylinder model (:func:`magfab.models.field.bz_br`) at every corner of the box of magnet
remanence x diameter x height x stack-up (the stack-up's terms enter the distance linearly, so its extremes
are the sums of their extremes) x magnet seating, and the band is [min, max] over the corners. On the axis
Bz rises monotonically with remanence, diameter and height and falls with distance over these bands (the
on-axis formula's derivatives keep their sign for d > R/sqrt 2), and the rise under a weight is monotonic
in the same variables and in the shear modulus, so the corners hold the extremes (tests/test_acceptance.py
checks this against a denser grid). Then the multiplicative terms (chip sensitivity, magnet temperature)
scale the band's ends outwards, and the Earth's field is added as an offset of either sign.

**The rest distance d** (magnet's lower face to the Hall point) moves with, summed worst case:

* the pad's printed thickness and the mould core's printed length (which sets the pocket roof in the
  silicone): each +/- the printer's dimensional tolerance, taken as max(fit_clearance_mm / 2, layer_height_mm)
  from recipes/printers.toml -- a sliding fit needs the clearance to absorb both mating surfaces' errors, so
  one surface is good to about half of it, and a height cannot be better than one layer (SLA: 0.1 mm,
  FDM: 0.15 mm);
* the glue layer, +/- ``glue_fraction`` of its thickness (assumption: 50 % for a hand-spread Sil-Poxy layer);
* the Hall point's height above the board: the chip recipe's sensing-depth band around the design's depth,
  and the solder joint under the QFN (0 to 75 um: the design puts the package on the copper; a QFN's
  reflowed joint is 50-75 um by the usual guidance);
* the magnet's seating: the design pushes it against the pocket roof; if not fully home it sits lower
  (closer to the chip), by at most the pocket's height clearance (plus what a short magnet leaves);
* the magnet's height tolerance (its top is at the roof, so a taller magnet's lower face is closer).

The package-height band of the chip recipe (0.8-1.0 mm) does not move the Hall point: the die sits on the
lead frame at a fixed height above the seating plane (the recipe derives the sensing depth from exactly that),
and the pad stands on the board, not on the chip; the package-height tolerance is the mould cap's above the
die. Counting it as well would count the same uncertainty twice; it is listed with a zero effect.

**Known weight.** A weight of W grams on the tip pushes with F = W g0 (g0 = 9.80665 m/s^2). The prediction's
normal curves (one per material band: soft, nominal, stiff shear modulus) give the magnet's travel u(F)
(force -> indentation -> magnet displacement); the rise is Bz(d - u) - Bz(d) with the same magnet and
distance corners as at rest, times the sensitivity and temperature terms. The mechanics are the nominal
geometry's: the stack-up tolerances move the whole fingertip, and the +/-0.1 mm of the pocket roof changes the
silicone under the magnet by a few per cent, far inside the material band (soft/stiff differ by 2.6x).
The Earth's field cancels in the difference.

**Lateral field at rest.** |Bxy| is zero on the axis of a perfect build. The bound adds a lateral offset of
the magnet from the Hall point (the chip's placement, the pad on its dowel pins, the fingertip in the pad's
lip, the magnet in its pocket, the core in the mould: summed) and a tilt of the magnetisation (the magnet's
magnetisation-axis tolerance plus its tilt in the pocket), evaluated with magpylib at the strongest corner
with the two effects aligned, plus the Earth's field.

The grade table of recipes/magnets.toml is evaluated at the nominal geometry so the output says which grades
the rest band can and cannot tell apart. For the MagOne N35 the root-sum-square band is about -10/+11 % of
the nominal field: N52 (+20.5 %) falls outside it, N42 (+8.8 %) inside. The worst-case band (-24/+35 %; the
distance band alone, 5.48-6.45 mm, is worth -16 % to +23 %) would hold every grade.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from .. import __version__
from ..errors import ModelLimitError
from ..formats import acceptance_json
from ..recipes import catalogue
from ..units import G0, GAUSS_PER_TESLA, UT_PER_GAUSS
from . import acceptance_steps
from . import field as fieldmod

if TYPE_CHECKING:
    from ..design import Design
    from .predict import Prediction

# Imported lazily, inside the functions that use it, for speed: magpylib takes a
# noticeable time to import, and importing this module should not.

__all__ = ["FORMAT", "G0", "DEFAULT_WEIGHT_G", "Tolerances", "SOURCES", "acceptance", "default_weight_g",
           "tolerance_bands"]

FORMAT = acceptance_json.FORMAT
DEFAULT_WEIGHT_G = 50.0
#: The known weight stays at or below this fraction of the softest material's predicted range, so the
#: magnet stays well inside the range (and the curve) whichever material band the batch turned out in.
WEIGHT_RANGE_FRACTION = 0.5
#: Forces at which the weight table is tabulated (plus the chosen weight's own force).
TABLE_POINTS = 41
#: Temperature at which the grade tables give the remanence.
BR_REFERENCE_C = 20.0


@dataclass(frozen=True)
class Tolerances:
    """The tolerances the bands are built from; ``None`` takes the recipe's or the spec's value.

    Intervals are (minus, plus) deviations where the field says so; every default and its source is in
    :data:`SOURCES`."""

    remanence_T: tuple[float, float] | None = None  # absolute band; None: the grade's min..max (prediction)
    magnet_diameter_mm: float = 0.05  # +/-
    magnet_height_mm: float = 0.05  # +/-
    printer_mm: float | None = None  # +/- per printed surface; None: max(fit_clearance/2, layer height)
    glue_fraction: float = 0.5  # +/- fraction of the glue thickness
    sensing_depth_mm: tuple[float, float] | None = None  # (minus, plus) deviations; None: the chip recipe's
    solder_standoff_mm: tuple[float, float] = (0.0, 0.075)  # the package's lift off the copper, absolute band
    seating_mm: float | None = None  # how far below the roof the magnet may sit; None: the pocket clearance
    sensitivity_pct: tuple[float, float] | None = None  # (minus, plus); None: the chip recipe's drift band
    ambient_C: tuple[float, float] = (15.0, 30.0)
    earth_field_uT: float = 65.0
    magnetisation_angle_deg: float = 5.0
    chip_placement_mm: float = 0.05  # lateral: the chip on its land and the Hall point in the package


SOURCES: dict[str, str] = {
    "remanence_T": "recipes/magnets.toml: the grade's remanence band (min..max), as used by the prediction",
    "magnet_diameter_mm": "sintered NdFeB, ground dimensions +/-0.05 mm (Mainrich International, 'NdFeB magnet "
                          "tolerances: dimensional specs and procurement guide'; the Chinese national standard table "
                          "for sintered NdFeB, as reproduced by rizinia.com, gives +/-0.05 mm for ground faces up to "
                          "10 mm); an as-sintered face is +/-0.1 mm or worse - set it here for unground magnets",
    "magnet_height_mm": "as magnet_diameter_mm: +/-0.05 mm on a ground face (the pressing direction is the hardest to "
                        "hold, Mainrich); the coating (Ni-Cu-Ni 10-20 um per side) is inside it",
    "printer_mm": "recipes/printers.toml: max(fit_clearance_mm / 2, layer_height_mm) - a sliding fit's clearance "
                  "absorbs the errors of two mating surfaces, so one surface is good to about half of it, and a "
                  "printed height is quantised to one layer. For SLA this is 0.1 mm, which is what SLA machine "
                  "manuals quote for parts under 100 mm (3d-printing-china.com, 'Can the printing accuracy of "
                  "photosensitive resin SLA reach 0.05 mm?')",
    "glue_fraction": "assumption: a hand-spread Sil-Poxy layer holds its thickness to +/-50 %; no bulletin gives a "
                     "bond-line tolerance (recipes/adhesives.toml)",
    "sensing_depth_mm": "recipes/chips.toml sensing_depth_mm band (itself an assumption there) around the design's "
                        "depth",
    "chip_height_mm": "recipes/chips.toml height_mm (JEDEC MO-220): not added - the Hall plates are on the die, at "
                      "a fixed height above the seating plane, and the pad stands on the board; the package-height "
                      "tolerance is the mould cap's above the die (the sensing-depth band already holds the die's "
                      "height)",
    "solder_standoff_mm": "the design seats the package on the copper; a reflowed QFN stands 50-75 um (2-3 mil) off "
                          "the board by the usual QFN guidance (as collected in electronics.stackexchange.com "
                          "question 189048); 0 to 75 um",
    "seating_mm": "spec elastomer.pocket_clearance_mm: the magnet is pushed up against the pocket roof; one not "
                  "fully home sits lower, closer to the chip, by at most the pocket's height clearance",
    "sensitivity_pct": "recipes/chips.toml sensitivity_drift_pct: MLX90393 datasheet SENSTHD, +/-3 % over "
                       "temperature (the datasheet's sensitivities are typical values)",
    "ambient_C": "assumption: a lab bench at 15-30 C; remanence falls 0.12 %/C above the grade table's ~20 C "
                 "(recipes/magnets.toml br_temperature_coefficient_pct_per_C)",
    "earth_field_uT": "the geomagnetic field's total intensity is about 22-67 uT at the Earth's surface (NOAA/BGS "
                      "World Magnetic Model); taken as an offset of up to 65 uT, either sign, on every axis",
    "magnetisation_angle_deg": "sintered NdFeB: the magnetisation is within a few degrees of the geometric axis, "
                               "'less than 5 deg' (K&J Magnetics, as quoted by kylemagnet.info); <= 5 deg a common "
                               "production tolerance (quadrant.cn, 'Controlling angular deviation in permanent "
                               "magnets', 2025)",
    "chip_placement_mm": "assumption: a reflowed QFN self-centres on its land to within ~0.05 mm, and the Hall "
                         "point is at the die centre (recipes/chips.toml)",
    "lip_clearance_mm": "spec pad.lip_clearance_mm: the fingertip may sit off-centre in the pad's lip by this much",
    "pocket_clearance_mm": "spec elastomer.pocket_clearance_mm: the magnet may sit off-centre in its pocket",
    "weight": "the prediction's normal curves (predictions.json normal.curve soft/nominal/stiff, "
              "normal.magnet_displacement_mm): force -> magnet travel; F = W g0, g0 = 9.80665 m/s^2",
}


def default_weight_g(prediction_data: Mapping[str, Any]) -> float:
    """50 g, or the largest of 1-2-5 x 10^k grams within ``WEIGHT_RANGE_FRACTION`` of the softest material's
    predicted range when 50 g would press further."""
    return _weight_for(min(prediction_data["normal"]["range_by_material_N"].values()))


def _weight_for(range_N: float) -> float:
    limit = WEIGHT_RANGE_FRACTION * range_N / G0 * 1000.0
    if limit >= DEFAULT_WEIGHT_G:
        return DEFAULT_WEIGHT_G
    k = math.floor(math.log10(limit)) if limit > 0 else -3
    for exponent in (k, k - 1):
        for m in (5, 2, 1):
            w = m * 10.0**exponent
            if w <= limit:
                return float(f"{w:.3g}")
    return float(f"{limit:.3g}")


def _data(prediction: Prediction | Mapping[str, Any]) -> Mapping[str, Any]:
    """predictions.json's content, from a Prediction or as read from the file."""
    return prediction.as_json() if hasattr(prediction, "as_json") else prediction


def _bz(radius: float, height: float, br: float, d: ArrayLike) -> np.ndarray:
    """Bz in G on the axis, at distances ``d`` (mm) below the magnet's lower face."""
    d = np.asarray(d, dtype=float)
    if np.any(d <= 0.05):
        raise ModelLimitError(f"the magnet's lower face would reach the Hall point (d = {float(d.min()):.3g} mm)")
    return np.asarray(fieldmod.bz_br(fieldmod.Magnet(radius, height, br), d, 0.0, model=fieldmod.FieldModel.EXACT)[0],
                      dtype=float)


def _lateral_G(radius: float, height: float, br: float, d: float, offset_mm: float, tilt_deg: float) -> float:
    """|Bxy| in G at the Hall point for a magnet offset sideways by ``offset_mm`` and magnetised ``tilt_deg`` off
    its axis, the two aligned so their lateral fields add (magpylib, SI units)."""
    import magpylib

    t = math.radians(tilt_deg)
    magnet = magpylib.magnet.Cylinder(polarization=(br * math.sin(t), 0.0, br * math.cos(t)),
                                      dimension=(2e-3 * radius, 1e-3 * height))
    z = -1e-3 * (height / 2.0 + d)
    points = np.array([[1e-3 * offset_mm, 0.0, z], [-1e-3 * offset_mm, 0.0, z]])
    b = np.asarray(magnet.getB(points)) * GAUSS_PER_TESLA
    return float(np.max(np.hypot(b[:, 0], b[:, 1])))


def _r(x: float, digits: int = 3) -> float:
    return round(float(x), digits) + 0.0


@dataclass(frozen=True)
class _Inputs:
    """The tolerances resolved against the design, the prediction and the recipes (mm, T, G, fractions)."""

    br_lo: float
    br_hi: float
    br_nom: float
    t_print: float  # +/- per printed surface, mm
    depth_dev: tuple[float, float]  # (minus, plus), mm
    sens: tuple[float, float]  # (minus, plus), %
    temp: list[float]  # remanence factor at the coldest and the warmest ambient, sorted
    gain: tuple[float, float]  # lowest and highest multiplicative factor (sensitivity x temperature)
    earth_G: float
    glue: float  # glue thickness, mm
    seating: float  # mm below the pocket roof
    R: float  # magnet radius, mm
    H: float  # magnet height, mm
    dR: float
    dH: float
    d_rest: float  # mm

    def seat_max(self, h: float) -> float:
        """How far below the roof a magnet of height h can sit: above the floor."""
        return max(0.0, self.seating + (self.H - h))


def _resolve(design: Design, data: Mapping[str, Any], tol: Tolerances) -> _Inputs:
    """Every tolerance as a number: the override in ``tol`` or the recipe's and the spec's value."""
    spec = design.spec
    chip, printer = design.chip, design.printer
    rem = data["field"]["remanence_T"]
    br_lo, br_hi = tol.remanence_T if tol.remanence_T is not None else (rem["low"], rem["high"])
    br_nom = float(rem["nominal"])
    if not 0 < br_lo <= br_hi:
        raise ValueError(f"remanence band must be 0 < low <= high; instead received {(br_lo, br_hi)}")
    t_print = tol.printer_mm if tol.printer_mm is not None else max(
        printer["fit_clearance_mm"].nominal / 2.0, printer["layer_height_mm"].nominal)
    depth = chip["sensing_depth_mm"]
    depth_dev = tol.sensing_depth_mm if tol.sensing_depth_mm is not None else (
        depth.nominal - depth.low, depth.high - depth.nominal)
    sens = tol.sensitivity_pct if tol.sensitivity_pct is not None else (
        -chip["sensitivity_drift_pct"].low, chip["sensitivity_drift_pct"].high)
    alpha = design.magnet_grade.br_temperature_coefficient_pct_per_C.nominal / 100.0
    temp = sorted(1.0 + alpha * (t - BR_REFERENCE_C) for t in tol.ambient_C)
    gain = ((1.0 - sens[0] / 100.0) * temp[0], (1.0 + sens[1] / 100.0) * temp[1])
    return _Inputs(
        br_lo=br_lo, br_hi=br_hi, br_nom=br_nom, t_print=t_print, depth_dev=depth_dev, sens=sens, temp=temp,
        gain=gain, earth_G=tol.earth_field_uT / UT_PER_GAUSS, glue=spec.pad.glue_thickness_mm,
        seating=tol.seating_mm if tol.seating_mm is not None else spec.elastomer.pocket_clearance_mm,
        R=design.magnet_radius_mm, H=design.magnet_height_mm, dR=tol.magnet_diameter_mm / 2.0,
        dH=tol.magnet_height_mm, d_rest=design.d_rest_mm)


def _stack(inp: _Inputs, tol: Tolerances) -> list[tuple[str, float, float]]:
    """Stack-up terms: (name, lowest, highest change of d in mm), summed worst case."""
    return [
        ("pad thickness", -inp.t_print, inp.t_print),
        ("pocket roof (mould core length)", -inp.t_print, inp.t_print),
        ("glue thickness", -tol.glue_fraction * inp.glue, tol.glue_fraction * inp.glue),
        ("Hall point: sensing depth", -inp.depth_dev[0], inp.depth_dev[1]),
        ("Hall point: solder joint under the chip", -tol.solder_standoff_mm[1], -tol.solder_standoff_mm[0]),
    ]


def _corners(inp: _Inputs, stack: list[tuple[str, float, float]]) -> list[tuple[float, float, float, float]]:
    """Every corner of remanence x radius x height x stack-up x seating, as (radius, height, br, d)."""
    stack_lo, stack_hi = sum(s[1] for s in stack), sum(s[2] for s in stack)
    R, H, dR, dH = inp.R, inp.H, inp.dR, inp.dH
    corners = []
    for br, r, h, ds in itertools.product((inp.br_lo, inp.br_hi), (R - dR, R + dR), (H - dH, H + dH),
                                          (stack_lo, stack_hi)):
        for s in sorted({0.0, inp.seat_max(h)}):
            corners.append((r, h, br, inp.d_rest + ds - (h - H) - s))
    return corners


def _lateral(design: Design, inp: _Inputs, tol: Tolerances, strongest: tuple[float, float, float, float]
             ) -> tuple[list[tuple[str, float]], float, float, float]:
    """(offsets, their sum in mm, tilt in deg, the |Bxy| bound in G): offsets summed, tilt = magnetisation
    angle + the magnet's tilt in its pocket, at the strongest corner, plus the Earth's field."""
    spec = design.spec
    offsets = [("chip placement", tol.chip_placement_mm), ("pad on its dowel pins", inp.t_print),
               ("fingertip in the pad's lip", spec.pad.lip_clearance_mm),
               ("magnet in its pocket", spec.elastomer.pocket_clearance_mm), ("core in the mould", inp.t_print)]
    offset = sum(o[1] for o in offsets)
    pocket_tilt = math.degrees(math.atan2(2.0 * spec.elastomer.pocket_clearance_mm, 2.0 * inp.R))
    tilt = tol.magnetisation_angle_deg + pocket_tilt
    bxy_max_G = _lateral_G(*strongest, offset, tilt) * inp.gain[1] + inp.earth_G
    return offsets, offset, tilt, bxy_max_G


@dataclass(frozen=True)
class _Weight:
    """The known weight and the rise it gives: forces in N, travel in mm, fields in G."""

    w: float  # g
    force: float
    f_range: float
    grid: np.ndarray  # forces tabulated
    at: int  # the weight's index in grid
    delta_min: np.ndarray
    delta_max: np.ndarray
    delta_nom: np.ndarray
    travel_w: dict[str, float]  # magnet travel under the weight, per material band
    prediction_delta_G: float  # the prediction's own rise at the nominal travel


def _travel_curves(normal: Mapping[str, Any]) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """The prediction's magnet travel u (mm) and, per material band, the force at each u (N)."""
    u = np.asarray(normal["magnet_displacement_mm"], dtype=float)
    curves = {k: np.asarray([p[1] for p in v], dtype=float) for k, v in normal["curve"].items()}
    for k, f in curves.items():
        if len(f) != len(u) or np.any(np.diff(f) <= 0) or np.any(np.diff(u) < 0):
            raise ModelLimitError(f"the prediction's normal curve '{k}' is not increasing: no force -> travel mapping")
    return u, curves


def _weight(data: Mapping[str, Any], inp: _Inputs, corners: list[tuple[float, float, float, float]],
            weight_g: float | None) -> _Weight:
    """The weight (chosen or checked against the range) and the rise over every corner and material band."""
    normal = data["normal"]
    u, curves = _travel_curves(normal)
    f_range = min(normal["range_by_material_N"].values())
    # Keep every corner's magnet clear of the Hall point (0.1 mm): a closer corner ends the table earlier.
    u_cap = min(c[3] for c in corners) - 0.1
    if u_cap < float(u[-1]):
        f_range = min(f_range, min(float(np.interp(u_cap, u, f)) for f in curves.values()))
    w = _weight_for(f_range) if weight_g is None else float(weight_g)
    force = w * G0 / 1000.0
    if not (math.isfinite(w) and w > 0):
        raise ValueError(f"weight_g must be a positive number of grams; instead received {weight_g!r}")
    if force > f_range:
        raise ModelLimitError(f"a {w:g} g weight ({force:.3g} N) presses beyond the predicted range of the softest "
                         f"material ({f_range:.3g} N = {f_range / G0 * 1000:.0f} g): use a lighter weight")
    grid = np.unique(np.concatenate([np.linspace(0.0, f_range, TABLE_POINTS), [force]]))
    travel = {k: np.interp(grid, f, u) for k, f in curves.items()}  # magnet travel at each force, mm

    def rise(r: float, h: float, br: float, d: float, k: str) -> np.ndarray:
        b = _bz(r, h, br, np.concatenate([[d], d - travel[k]]))
        return b[1:] - b[0]

    rises = np.array([rise(*c, k) for c in corners for k in curves])
    at = int(np.searchsorted(grid, force))
    bz_pred = np.asarray(fieldmod.bz_br(fieldmod.Magnet(inp.R, inp.H, inp.br_nom), np.maximum(inp.d_rest - u, 1e-3),
                                        0.0, model=fieldmod.FieldModel.EXACT)[0])
    travel_w = {k: float(travel[k][at]) for k in curves}
    return _Weight(w=w, force=force, f_range=f_range, grid=grid, at=at,
                   delta_min=rises.min(axis=0) * inp.gain[0], delta_max=rises.max(axis=0) * inp.gain[1],
                   delta_nom=rise(inp.R, inp.H, inp.br_nom, inp.d_rest, "nominal"), travel_w=travel_w,
                   prediction_delta_G=float(np.interp(travel_w["nominal"], u, bz_pred)) - float(bz_pred[0]))


def _effects(inp: _Inputs, tol: Tolerances, stack: list[tuple[str, float, float]], nominal_G: float
             ) -> tuple[dict[str, tuple[float, float]], dict[str, tuple[float, float]]]:
    """One tolerance at a time: Bz at rest (uT) at each end of each tolerance, then of each stack-up term."""
    R, H, br_nom, d_rest = inp.R, inp.H, inp.br_nom, inp.d_rest

    def alone(r=R, h=H, br=br_nom, ds=0.0) -> float:
        return float(_bz(r, h, br, [d_rest + ds - (h - H)])[0]) * UT_PER_GAUSS

    nom_uT = nominal_G * UT_PER_GAUSS
    sens, temp = inp.sens, inp.temp
    effects = {
        "remanence_T": (alone(br=inp.br_lo), alone(br=inp.br_hi)),
        "magnet_diameter_mm": (alone(r=R - inp.dR), alone(r=R + inp.dR)),
        "magnet_height_mm": (alone(h=H - inp.dH), alone(h=H + inp.dH)),
        "seating_mm": (nom_uT, alone(ds=-inp.seating)),
        "sensitivity_pct": (nom_uT * (1 - sens[0] / 100), nom_uT * (1 + sens[1] / 100)),
        "ambient_C": (nom_uT * temp[0], nom_uT * temp[1]),
        "earth_field_uT": (nom_uT - tol.earth_field_uT, nom_uT + tol.earth_field_uT),
    }
    stack_effects = {name: (alone(ds=hi), alone(ds=lo)) for name, lo, hi in stack}
    return effects, stack_effects


def _item(key: str, band: list, unit: str, effect: tuple[float, float] | None) -> dict[str, Any]:
    out = {"name": key, "band": [_r(x, 6) for x in band], "unit": unit, "source": SOURCES[key]}
    if effect is not None:
        out["rest_Bz_uT"] = [_r(min(effect)), _r(max(effect))]
    return out


def _assumptions(design: Design, inp: _Inputs, tol: Tolerances, w: float, nom_uT: float,
                 effects: dict[str, tuple[float, float]], stack_effects: dict[str, tuple[float, float]]
                 ) -> list[dict[str, Any]]:
    """Every tolerance with its band, unit, source and what it alone is worth at rest."""
    spec, chip = design.spec, design.chip
    return [
        _item("remanence_T", [inp.br_lo, inp.br_hi], "T", effects["remanence_T"]),
        _item("magnet_diameter_mm", [-tol.magnet_diameter_mm, tol.magnet_diameter_mm], "mm",
              effects["magnet_diameter_mm"]),
        _item("magnet_height_mm", [-inp.dH, inp.dH], "mm", effects["magnet_height_mm"]),
        _item("printer_mm", [-inp.t_print, inp.t_print], "mm (pad thickness; pocket roof)",
              (stack_effects["pad thickness"][0], stack_effects["pad thickness"][1])),
        _item("glue_fraction", [-tol.glue_fraction, tol.glue_fraction], f"x {inp.glue:g} mm glue",
              stack_effects["glue thickness"]),
        _item("sensing_depth_mm", [-inp.depth_dev[0], inp.depth_dev[1]], "mm",
              stack_effects["Hall point: sensing depth"]),
        _item("chip_height_mm", [chip["height_mm"].low, chip["height_mm"].high], "mm", (nom_uT, nom_uT)),
        _item("solder_standoff_mm", list(tol.solder_standoff_mm), "mm",
              stack_effects["Hall point: solder joint under the chip"]),
        _item("seating_mm", [0.0, inp.seating], "mm below the pocket roof", effects["seating_mm"]),
        _item("sensitivity_pct", [-inp.sens[0], inp.sens[1]], "%", effects["sensitivity_pct"]),
        _item("ambient_C", list(tol.ambient_C), "C", effects["ambient_C"]),
        _item("earth_field_uT", [-tol.earth_field_uT, tol.earth_field_uT], "uT", effects["earth_field_uT"]),
        _item("magnetisation_angle_deg", [0.0, tol.magnetisation_angle_deg], "deg", None),
        _item("chip_placement_mm", [0.0, tol.chip_placement_mm], "mm", None),
        _item("lip_clearance_mm", [0.0, spec.pad.lip_clearance_mm], "mm", None),
        _item("pocket_clearance_mm", [0.0, spec.elastomer.pocket_clearance_mm], "mm", None),
        _item("weight", [w, w], "g", None),
    ]


def _rss_band(nom_uT: float, tol: Tolerances, effects: dict[str, tuple[float, float]],
              stack_effects: dict[str, tuple[float, float]]) -> tuple[float, float]:
    """The rest band the check uses, (low, high) in G: each tolerance's effect alone, combined root-sum-square
    on each side (the usual statistical stack for independent tolerances), then the Earth's field added in
    full. The worst case of every corner at once is so wide that a grade four steps stronger reads inside it."""
    rss_effects = [v for k, v in effects.items() if k != "earth_field_uT"] + list(stack_effects.values())
    down = math.sqrt(sum(min(a - nom_uT, b - nom_uT, 0.0) ** 2 for a, b in rss_effects))
    up = math.sqrt(sum(max(a - nom_uT, b - nom_uT, 0.0) ** 2 for a, b in rss_effects))
    return (nom_uT - down - tol.earth_field_uT) / UT_PER_GAUSS, (nom_uT + up + tol.earth_field_uT) / UT_PER_GAUSS


def _grade_table(nominal_G: float, br_nom: float, rest_lo_G: float, rest_hi_G: float) -> dict[str, dict[str, Any]]:
    """Every grade of recipes/magnets.toml at the nominal geometry, and whether the rest band holds it."""
    table = {}
    for name, g in catalogue("magnets").items():
        b = g["remanence_T"].nominal
        rest_uT = _r(nominal_G * b / br_nom * UT_PER_GAUSS)
        table[name] = {"remanence_T": b, "rest_Bz_uT": rest_uT,
                       "inside_rest_band": bool(rest_lo_G * UT_PER_GAUSS <= rest_uT <= rest_hi_G * UT_PER_GAUSS)}
    return table


def _weight_section(data: Mapping[str, Any], wt: _Weight) -> dict[str, Any]:
    """acceptance.json's ``weight``: the rise under the weight and its table over force, in uT."""
    at = wt.at
    return {
        "weight_g": wt.w,
        "force_N": _r(wt.force, 9),
        "g0_m_s2": G0,
        "delta_Bz_uT": {"min": _r(wt.delta_min[at] * UT_PER_GAUSS), "nominal": _r(wt.delta_nom[at] * UT_PER_GAUSS),
                        "max": _r(wt.delta_max[at] * UT_PER_GAUSS)},
        "travel_mm": {k: _r(v, 6) for k, v in wt.travel_w.items()},
        "prediction_delta_Bz_uT": _r(wt.prediction_delta_G * UT_PER_GAUSS),
        "max_weight_g": _r(wt.f_range / G0 * 1000.0, 2),
        "table": {
            "force_N": [_r(f, 9) for f in wt.grid],
            "delta_Bz_min_uT": [_r(x * UT_PER_GAUSS) for x in wt.delta_min],
            "delta_Bz_nominal_uT": [_r(x * UT_PER_GAUSS) for x in wt.delta_nom],
            "delta_Bz_max_uT": [_r(x * UT_PER_GAUSS) for x in wt.delta_max],
        },
        "material_mu_kPa": dict(data["material_mu_kPa"]),
    }


# The steps below are the module doc's, in its order; this only wires them and lays out acceptance.json.
def tolerance_bands(design: Design, prediction: Prediction | Mapping[str, Any],
                    tolerances: Tolerances | None = None) -> dict[str, Any]:
    """The tolerance bands the acceptance test builds from, as a model fitted to the sensor takes its priors
    (:mod:`magfab.models.weighing`): ``remanence_T`` (low, high, nominal); ``rest_distance_mm`` (the stack-up's
    mean change of d, its root-sum-square half-width: the stack-up's terms, the magnet's height and its seating);
    ``offset_mm`` the summed lateral offsets and ``tilt_deg`` the magnetisation's tilt (as :func:`acceptance`'s
    lateral bound)."""
    tol = tolerances or Tolerances()
    data = _data(prediction)
    inp = _resolve(design, data, tol)
    terms = [(lo, hi) for _, lo, hi in _stack(inp, tol)] + [(-inp.dH, inp.dH), (-inp.seat_max(inp.H), 0.0)]
    mid = sum((lo + hi) / 2.0 for lo, hi in terms)
    half = math.sqrt(sum(((hi - lo) / 2.0) ** 2 for lo, hi in terms))
    nominal = (inp.R, inp.H, inp.br_nom, inp.d_rest)
    _, offset, tilt, _ = _lateral(design, inp, tol, nominal)
    return {"remanence_T": (inp.br_lo, inp.br_hi, inp.br_nom), "rest_distance_mm": (mid, half),
            "offset_mm": offset, "tilt_deg": tilt}


def acceptance(design: Design, prediction: Prediction | Mapping[str, Any], weight_g: float | None = None,
               tolerances: Tolerances | None = None) -> dict[str, Any]:
    """The acceptance bands for ``design`` (module doc): a JSON-ready dict, format ``magfab-acceptance/1``.

    ``prediction`` is :func:`magfab.models.predict.predict`'s result or its ``data`` (predictions.json).
    ``weight_g`` is the known weight (default :func:`default_weight_g`: 50 g for MagOne); ``tolerances``
    overrides any of the tolerances. Deterministic. Raises ValueError for a weight outside the predicted range.
    """
    tol = tolerances or Tolerances()
    data = _data(prediction)
    spec = design.spec
    inp = _resolve(design, data, tol)
    stack = _stack(inp, tol)
    corners = _corners(inp, stack)

    # at rest: the every-corner worst case (kept for reference), then the root-sum-square band the check uses
    rest_G = np.array([float(_bz(r, h, br, [d])[0]) for r, h, br, d in corners])
    nominal_G = float(_bz(inp.R, inp.H, inp.br_nom, [inp.d_rest])[0])
    worst_band = [_r((float(rest_G.min()) * inp.gain[0] - inp.earth_G) * UT_PER_GAUSS),
                  _r((float(rest_G.max()) * inp.gain[1] + inp.earth_G) * UT_PER_GAUSS)]
    d_all = [c[3] for c in corners]
    offsets, offset, tilt, bxy_max_G = _lateral(design, inp, tol, corners[int(np.argmax(rest_G))])
    wt = _weight(data, inp, corners, weight_g)
    nom_uT = nominal_G * UT_PER_GAUSS
    effects, stack_effects = _effects(inp, tol, stack, nominal_G)
    rest_lo_G, rest_hi_G = _rss_band(nom_uT, tol, effects, stack_effects)
    grade_table = _grade_table(nominal_G, inp.br_nom, rest_lo_G, rest_hi_G)
    rest_band = [_r(rest_lo_G * UT_PER_GAUSS), _r(rest_hi_G * UT_PER_GAUSS)]
    weight = _weight_section(data, wt)
    noise = data["noise_G"]
    warmup = acceptance_steps.warmup_section(data)
    return {
        "format": FORMAT,
        "magfab_version": __version__,
        "spec_name": spec.name,
        "units": "microtesla in the chip's axes (+z out of the package top, towards the magnet); 1 G = 100 uT",
        # The three figures the checklist quotes.
        "rest_Bz_uT": rest_band,
        "weight_g": wt.w,
        "delta_Bz_uT": [weight["delta_Bz_uT"]["min"], weight["delta_Bz_uT"]["max"]],
        "rest": {
            "Bz_uT": {"min": rest_band[0], "nominal": _r(nom_uT), "max": rest_band[1]},
            "worst_case_Bz_uT": worst_band,
            "sign": 1,
            "orientation": "north pole up, away from the chip (towards the fingertip): Bz > 0 at rest. A negative "
                           "Bz means the magnet is upside down.",
            "Bxy_max_uT": _r(bxy_max_G * UT_PER_GAUSS),
            "lateral_offset_mm": _r(offset, 4),
            "lateral_offsets": dict(offsets),
            "tilt_deg": _r(tilt, 3),
            "distance_mm": {"min": _r(min(d_all), 4), "nominal": _r(inp.d_rest, 4), "max": _r(max(d_all), 4)},
            "stack_mm": {name: [_r(lo, 4), _r(hi, 4)] for name, lo, hi in stack},
            "gain": [_r(inp.gain[0], 5), _r(inp.gain[1], 5)],
            "earth_field_uT": tol.earth_field_uT,
            "grades_inside_band": [n for n, g in grade_table.items() if g["inside_rest_band"]],
        },
        "weight": weight,
        "rotation": acceptance_steps.rotation_section(design, data, weight),
        **({} if warmup is None else {"warmup": warmup}),
        "magnet": {"grade": spec.magnet.grade,
                   "remanence_T": {"low": inp.br_lo, "nominal": inp.br_nom, "high": inp.br_hi},
                   "diameter_mm": 2 * inp.R, "height_mm": inp.H},
        "grades": grade_table,
        "measurement": {
            "noise_z_uT": _r(noise["total_z_G"] * UT_PER_GAUSS, 4),
            "noise_xy_uT": _r(noise["total_xy_G"] * UT_PER_GAUSS, 4),
            "allowance_sigmas": 4.0,
            "note": "the check widens each band by allowance_sigmas x the noise of its mean (noise / sqrt(samples), "
                    "x sqrt 2 for a difference) and half a count",
        },
        "tolerances": {k: (list(v) if isinstance(v, tuple) else v) for k, v in asdict(tol).items()},
        "assumptions": _assumptions(design, inp, tol, wt.w, nom_uT, effects, stack_effects),
        "combination": "rest: each tolerance's effect on the exact field alone, root-sum-square on each side, "
                       "then +/- the Earth's field (rest.worst_case_Bz_uT keeps the every-corner worst case); "
                       "weight: worst case over every corner of the tolerance box and the material band, x the "
                       "sensitivity and temperature band; deterministic",
    }
