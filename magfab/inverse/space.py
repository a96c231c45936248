"""The design variables: how a point of the search becomes a spec ``magfab build`` accepts.

A point is a plain dict (picklable, JSON-able, what Optuna stores as a trial's params)::

    {"magnet": "d5_h2", "grade": "N35", "material": "ecoflex-00-30", "tip": "hemisphere",
     "d_max_mm": 6.0, "d_min_mm": 2.5, "elastomer_diameter_mm": 12.0, "cover_mm": 1.9}

:func:`candidate_spec` puts it into the base spec: the magnet from the stock catalogue, the rest distances, the
elastomer's diameter, tip and material, and its height from the stack (magnet top + cover); the pad grows with the
elastomer so its centring lip and alignment holes still fit. Everything else is the base spec's.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Iterator
from functools import lru_cache
from typing import Any

import numpy as np

from ..check import preflight
from ..design import SECOND_HOLE_EXTRA_MM, derive
from ..errors import SpecError
from ..models.chip import chip_setting
from ..models.field import Magnet, saturation_gap
from ..recipes import catalogue
from ..recipes.resolve import magnet_grade
from ..recipes.resolve import printer as printer_recipe
from ..spec import Spec, spec_from_dict
from .ranges import fraction_within, has_value, lowest_at_least, max_of, nearest_allowed, pick, range_within, span_of
from .targets import Chip, Targets, Variables

# Imported lazily, inside the functions that use it, for speed: scipy takes a
# noticeable time to import, and importing this module should not.

__all__ = ["NUMERIC", "CATEGORICAL", "stock_disc", "saturation_floor", "candidate_spec", "suggest", "grid",
           "latin_hypercube", "base_point", "magnet_moment", "Space", "FRACTIONS", "FRACTION_OF", "MAGNET_FRACTION",
           "POINT"]

#: The numeric variables (mm), in the order tables show them.
NUMERIC = ("d_max_mm", "d_min_mm", "elastomer_diameter_mm", "cover_mm")
#: The categorical variables of a point (a trial's params carry magnet and grade as one, "DISC:GRADE").
CATEGORICAL = ("magnet", "grade", "material", "tip")

#: The pad's margins when it grows with the elastomer (MagOne's: 0.85 mm from the lip to the first alignment hole's
#: edge, 1.0 mm from the second hole's edge to the pad's rim).
_HOLE_MARGIN_MM = 0.85
_RIM_MARGIN_MM = 1.0


def stock_disc(key: str) -> tuple[float, float, tuple[str, ...]]:
    """(diameter_mm, height_mm, grades sold) of a stock disc of recipes/magnet_stock.toml."""
    r = catalogue("magnet_stock")[key]
    grades = tuple(g for g in r.texts.get("grades", "").replace(",", " ").split() if g)
    return r["diameter_mm"].nominal, r["height_mm"].nominal, grades


def magnets(variables: Variables) -> list[str]:
    """The magnets a design may use: each stock disc in each of its grades the variables allow, as "DISC:GRADE"."""
    out = [f"{k}:{g}" for k in variables.magnet_keys() for g in stock_disc(k)[2] if g in variables.grades]
    if not out:
        raise SpecError("variables.grades", " ".join(variables.grades),
                        "no stock disc of variables.magnets is sold in these grades")
    return out


def choices(variables: Variables) -> dict[str, list[Any]]:
    """The categorical variables' choices (the magnet as "DISC:GRADE": the grades a disc is sold in)."""
    return {"magnet": magnets(variables), "material": variables.material_keys(),
            "tip": [t.value for t in variables.tips]}


def point_of(params: dict[str, Any]) -> dict[str, Any]:
    """The point of a trial's params (the magnet split into disc and grade)."""
    disc, grade = str(params["magnet"]).split(":")
    return {**params, "magnet": disc, "grade": grade}


def params_of(point: dict[str, Any]) -> dict[str, Any]:
    """A point as a trial's params (what Optuna enqueues)."""
    params = {k: v for k, v in point.items() if k != "grade"}
    params["magnet"] = f"{point['magnet']}:{point['grade']}"
    return params


def suggest(trial, variables: Variables) -> dict[str, Any]:
    """A point drawn by an Optuna trial (ask-and-tell)."""
    params: dict[str, Any] = {k: trial.suggest_categorical(k, v) for k, v in choices(variables).items()}
    for name in NUMERIC:
        c = getattr(variables, name)
        params[name] = (float(trial.suggest_categorical(name, list(c))) if isinstance(c, list)
                        else trial.suggest_float(name, c[0], c[1]))
    return point_of(params)


def grid(variables: Variables, levels: int) -> Iterator[dict[str, Any]]:
    """Every combination: the categorical choices, listed values, and ``levels`` even steps over each range."""
    axes = dict(choices(variables))
    for name in NUMERIC:
        c = getattr(variables, name)
        axes[name] = list(c) if isinstance(c, list) else [float(x) for x in np.linspace(c[0], c[1], levels)]
    for combo in itertools.product(*axes.values()):
        yield point_of(dict(zip(axes, combo)))


def latin_hypercube(variables: Variables, n: int, seed: int) -> list[dict[str, Any]]:
    """``n`` points of a Latin hypercube (scipy.stats.qmc) over every variable: categorical ones by equal strata."""
    from scipy.stats import qmc

    axes = {**choices(variables), **{k: getattr(variables, k) for k in NUMERIC}}
    u = qmc.LatinHypercube(d=len(axes), seed=seed).random(n)
    points = []
    for row in u:
        point: dict[str, Any] = {}
        for x, (name, c) in zip(row, axes.items()):
            if name in NUMERIC and isinstance(c, tuple):
                point[name] = float(c[0] + x * (c[1] - c[0]))
            else:
                point[name] = c[min(int(x * len(c)), len(c) - 1)]
        points.append(point_of(point))
    return points


def base_point(base: Spec, variables: Variables) -> dict[str, Any] | None:
    """The base spec as a point, if its magnet is a stock disc the variables allow (the study starts from it)."""
    m = base.magnet
    keys = [k for k in variables.magnet_keys() if stock_disc(k)[:2] == (m.diameter_mm, m.height_mm)]
    if not keys or f"{keys[0]}:{m.grade}" not in magnets(variables):
        return None
    # a base the build would refuse (its cost, its reference chip, its board) stops the study before it starts
    design = preflight(derive(base))
    point = {"magnet": keys[0], "grade": m.grade, "material": base.elastomer.material, "tip": base.elastomer.tip.value,
             "d_max_mm": base.sensor.d_max_mm, "d_min_mm": base.sensor.d_min_mm,
             "elastomer_diameter_mm": base.elastomer.diameter_mm, "cover_mm": round(design.cover_mm, 9)}
    allowed = choices(variables)
    if any(point[k] not in allowed[k] for k in ("material", "tip")):
        return None
    for name in NUMERIC:
        c = getattr(variables, name)
        if (point[name] not in c) if isinstance(c, list) else not c[0] <= point[name] <= c[1]:
            return None
    return point


def candidate_spec(point: dict[str, Any], base: Spec, targets: Targets, name: str) -> Spec:
    """The spec of a point (module doc). :class:`SpecError` when the point cannot be a spec (e.g. d_min >= d_max)."""
    diameter, height, grades = stock_disc(point["magnet"])
    if grades and point["grade"] not in grades:
        raise SpecError("magnet.grade", point["grade"], f"stock disc {point['magnet']} is sold in " + ", ".join(grades))
    raw = base.toml_dict()
    raw["name"] = name
    raw["magnet"].update(diameter_mm=diameter, height_mm=height, grade=point["grade"])
    el = raw["elastomer"]
    el.pop("cover_mm", None)
    if el.get("material") != point["material"]:
        el.pop("shear_modulus_kPa", None)  # a batch's own modulus belongs to the base's material
    d_e = float(point["elastomer_diameter_mm"])
    # The stack (pad + glue above the sensing point) does not depend on the point: the base's.
    stack = _stack_offset(base)
    roof = float(point["d_max_mm"]) + height - stack  # the magnet's top, above the elastomer's base
    el.update(material=point["material"], tip=point["tip"], diameter_mm=d_e,
              height_mm=round(roof + float(point["cover_mm"]), 9))
    raw["sensor"].update(d_max_mm=float(point["d_max_mm"]), d_min_mm=float(point["d_min_mm"]),
                         **targets.chip.model_dump())
    raw["predict"].update(noise_G=targets.require.noise_G)
    if targets.require.normal_resolution_mN is not None:
        raw["predict"]["required_resolution_mN"] = targets.require.normal_resolution_mN
    raw["pad"].update(_pad_for(base, d_e))
    return spec_from_dict(raw)


@lru_cache(maxsize=8)
def _stack_offset(base: Spec) -> float:
    """Height of the elastomer's base above the sensing point, mm (pad + glue - sensing point), derived once per base
    (a frozen spec is hashable)."""
    design = derive(base)
    return design.z_elastomer_base_mm - design.z_sense_mm


def _pad_for(base: Spec, d_e: float) -> dict[str, float]:
    """The base's pad, grown (never shrunk) so the centring lip and the two alignment holes fit round a ``d_e``
    elastomer."""
    pad = base.pad
    lip_outer = d_e / 2.0 + pad.lip_clearance_mm + (pad.lip_width_mm if pad.lip_height_mm > 0 else 0.0)
    d1 = pad.alignment_hole_diameter_mm
    half = max(pad.alignment_hole_spacing_mm / 2.0, lip_outer + d1 / 2.0 + _HOLE_MARGIN_MM)
    d2 = d1 + SECOND_HOLE_EXTRA_MM
    radius = max(pad.diameter_mm / 2.0, half + d2 / 2.0 + _RIM_MARGIN_MM)
    return {"alignment_hole_spacing_mm": round(2.0 * half, 6),
            "diameter_mm": round(2.0 * math.ceil(radius * 10) / 10, 6)}


# --- The search's own coordinates: buildable by construction ------------------------------------------------------

#: The user attribute a trial keeps its mm point in.
POINT = "point"
#: A trial's numeric params: fractions in [0, 1] of the interval the other choices leave each mm variable, in the
#: order they are resolved (the elastomer's diameter first, then the rest distance, the cover, the closest distance).
#: A variable given as listed values is a categorical param of its own name instead, moved to the nearest allowed.
FRACTIONS = ("f_elastomer_diameter", "f_d_max", "f_cover", "f_d_min")
FRACTION_OF = {"elastomer_diameter_mm": FRACTIONS[0], "d_max_mm": FRACTIONS[1], "cover_mm": FRACTIONS[2],
                "d_min_mm": FRACTIONS[3]}
#: The magnet as the search sees it: a fraction over the magnets a tip can be built with, in order of their moment
#: (volume x nominal remanence), so that neighbouring values are neighbouring fields and the sampler's model of the
#: fraction carries over between magnets (as a categorical param it learns each of a dozen or more on its own).
MAGNET_FRACTION = "f_magnet"
#: The smallest gap kept between d_min and what bounds it (d_max above, the elastomer's base below), mm.
_GAP_MM = 0.01
#: How far a hemisphere's height is kept above its radius at the space's edge, mm: more than the spec's rounding of
#: the height (9 decimals), so that a point at the edge is not refused for a height a rounding below the radius.
_EDGE_MM = 1e-6
#: Steps the elastomer's diameter range is scanned in for the sub-range every other choice can follow.
_SCAN = 401


class Space:
    """The variables as the search sees them: the categorical choices and four fractions, each mapped onto the part
    of its mm range that the choices before it leave buildable (the geometry :func:`magfab.design.derive` checks:
    the pocket's skin in the elastomer, the magnet's roof between the minimum skin and the cover, a hemisphere tip
    no taller than the elastomer, d_min between the elastomer's base and d_max, the mould's fill and vent holes round
    the channel and its funnel), within the required maximum diameter and height, and with d_min no nearer than where
    the grade's strongest magnet saturates the chip (:meth:`saturation_floor`: the check refuses every design
    nearer). Any point of the unit cube is then a design the geometry accepts, save a listed-values choice with no
    value inside its interval (rare; the design then fails as before).

    The base spec fixes the stack (pad + glue above the sensing point), the pocket's clearance, the minimum skin and
    the insertion channel; the targets the ranges and the required maxima."""

    def __init__(self, targets: Targets, base: Spec):
        self.variables = v = targets.variables
        el = base.elastomer
        self.stack = _stack_offset(base)
        self.clearance, self.skin = el.pocket_clearance_mm, el.min_skin_mm
        self.channel = el.insert_channel_diameter_mm / 2.0
        vent = max(1.0, printer_recipe(base.mould.printer.value)["min_hole_mm"].nominal)
        self.annulus = max(1.0, vent + 0.6) + 1e-6  # the mould's fill and vent holes round the channel (derive)
        r = targets.require
        self.max_height = r.max_height_mm if r.max_height_mm is not None else math.inf
        self.max_diameter = r.max_diameter_mm if r.max_diameter_mm is not None else math.inf
        self.max_diameter = min(self.max_diameter, _board_limit(base, float(max(v.elastomer_diameter_mm))))
        self.full_scale_G = _full_scale_z_G(base, targets)
        #: Memos of pure functions of this space's designs, by name (the model step's coordinates of each design
        #: evaluated: magfab.inverse.propose._physical_of).
        self.memo: dict[str, dict[Any, Any]] = {}
        self._saturation: dict[str, float] = {}
        self.all_choices = choices(v)
        self._d_range: dict[tuple[str, str], tuple[float, float] | None] = {}
        buildable = [m for m in self.all_choices["magnet"]
                     if any(self.diameter_range(m, t) is not None for t in self.all_choices["tip"])]
        if not buildable:
            raise SpecError("variables.magnets", ", ".join(self.all_choices["magnet"]),
                            "no magnet listed fits a buildable elastomer within the ranges and requirements")
        tips = [t for t in self.all_choices["tip"] if any(self.diameter_range(m, t) is not None for m in buildable)]
        self.choices = {**self.all_choices, "magnet": buildable, "tip": tips}
        #: each tip's buildable magnets, weakest moment first (ties: the catalogue's order)
        self.magnet_order = {t: sorted((m for m in buildable if self.diameter_range(m, t) is not None),
                                       key=lambda m: (magnet_moment(m), buildable.index(m))) for t in tips}

    def magnet_at(self, tip: str, fraction: float) -> str:
        """The magnet at ``fraction`` of the tip's buildable magnets in order of moment (equal strata)."""
        tips = self.choices["tip"]
        return self.choices["magnet"][int(self.magnets_at(np.array([tips.index(tip)]), np.array([fraction]))[0])]

    def magnets_at(self, tip: np.ndarray, fraction: np.ndarray) -> np.ndarray:
        """:meth:`magnet_at` for many: ``tip`` indexes self.choices["tip"]; indices into self.choices["magnet"]."""
        out = np.empty(len(tip), dtype=int)
        magnets = self.choices["magnet"]
        for i, name in enumerate(self.choices["tip"]):
            rows = tip == i
            order = np.array([magnets.index(m) for m in self.magnet_order.get(name, [])], dtype=int)
            if rows.any():
                stratum = (np.clip(fraction[rows], 0.0, 1.0) * len(order)).astype(int)
                out[rows] = order[np.minimum(stratum, len(order) - 1)]
        return out

    def magnet_fraction(self, tip: str, magnet: str) -> float:
        """The middle of ``magnet``'s stratum among the tip's buildable magnets (the inverse of :meth:`magnet_at`)."""
        order = self.magnet_order[tip]
        return (order.index(magnet) + 0.5) / len(order)

    # the bounds each choice leaves -------------------------------------------------------------------------------

    def _magnet(self, magnet: str) -> tuple[float, float]:
        d, h, _ = stock_disc(magnet.split(":")[0])
        return d / 2.0, h

    def saturation_floor(self, magnet: str) -> float:
        """The least d_min (mm) at which the chip, at the targets' gain and resolution, does not saturate with the
        grade's strongest magnet of this disc (the check's M9, chip-saturates: the exact Bz on the axis against the
        chip's full scale); nearer, every design is refused, so the space starts d_min there."""
        if magnet not in self._saturation:
            disc, grade = magnet.split(":")
            self._saturation[magnet] = _saturation_floor(disc, grade, self.full_scale_G)
        return self._saturation[magnet]

    def _cover_floor(self, r_e: Any, r_p: Any, hemi: Any) -> Any:
        """The least cover the skin allows (over a hemisphere tip, the dome's skin above the pocket's rim). Here and in
        the bounds below the elastomer's radius and the rest distance may be arrays, and so may the magnet's figures
        and ``hemi`` (whether the tip is a hemisphere: :meth:`mm`'s designs, element by element)."""
        dome = np.maximum(self.skin, r_e - np.sqrt(np.maximum((r_e - self.skin) ** 2 - r_p**2, 0.0)))
        return pick(hemi, dome, self.skin)

    def _of(self, magnet: str, tip: str) -> tuple[float, float, float, bool]:
        """What the bounds take of a (magnet, tip): the magnet's radius and height, its saturation floor, and whether
        the tip is a hemisphere."""
        r_m, h_m = self._magnet(magnet)
        return r_m, h_m, self.saturation_floor(magnet), tip == "hemisphere"

    def d_max_bounds(self, magnet: str, tip: str, d_e: Any) -> tuple[Any, Any]:
        return self._d_max_within(*self._of(magnet, tip), d_e)

    def _d_max_within(self, r_m: Any, h_m: Any, floor: Any, hemi: Any, d_e: Any) -> tuple[Any, Any]:
        r_p, r_e, s = r_m + self.clearance, d_e / 2.0, self.stack
        cover_lo = lowest_at_least(self.variables.cover_mm, self._cover_floor(r_e, r_p, hemi))
        d_min_floor = max_of(s + _GAP_MM, floor)
        lo = max_of(s + self.skin + self.clearance, lowest_at_least(self.variables.d_min_mm, d_min_floor) + _GAP_MM)
        # the pocket's floor high enough that the channel's funnel, clipped at the base, leaves the mould's fill and
        # vent holes their annulus (design: the core's base radius is R_p less the floor's height when it is low)
        lo = np.maximum(lo, s + self.clearance + r_p + self.annulus - r_e)
        # a hemisphere: the elastomer at least as tall as the dome's radius, with the most cover allowed
        lo = pick(hemi, np.maximum(lo, r_e - float(max(self.variables.cover_mm)) + s - h_m + 2 * _EDGE_MM), lo)
        return lo, self.max_height + s - h_m - cover_lo

    def cover_bounds(self, magnet: str, tip: str, d_e: Any, d_max: Any) -> tuple[Any, Any]:
        r_m, h_m, _, hemi = self._of(magnet, tip)
        return self._cover_within(r_m, h_m, hemi, d_e, d_max)

    def _cover_within(self, r_m: Any, h_m: Any, hemi: Any, d_e: Any, d_max: Any) -> tuple[Any, Any]:
        r_e, roof = d_e / 2.0, d_max + h_m - self.stack
        lo = self._cover_floor(r_e, r_m + self.clearance, hemi)
        lo = pick(hemi, np.maximum(lo, r_e - roof + _EDGE_MM), lo)
        return lo, self.max_height - roof

    def d_min_bounds(self, magnet: str, d_max: Any) -> tuple[Any, Any]:
        return self._d_min_within(self.saturation_floor(magnet), d_max)

    def _d_min_within(self, floor: Any, d_max: Any) -> tuple[Any, Any]:
        return max_of(self.stack + _GAP_MM, floor), d_max - _GAP_MM

    def _d_ok(self, magnet: str, tip: str, d_e: float) -> bool:
        lo, hi = self.d_max_bounds(magnet, tip, d_e)
        return has_value(self.variables.d_max_mm, lo, hi)

    def diameter_range(self, magnet: str, tip: str) -> tuple[float, float] | None:
        """The elastomer diameters (lowest, highest) a (magnet, tip) can be built with inside the ranges; None:
        none."""
        key = (magnet, tip)
        if key not in self._d_range:
            self._d_range[key] = self._scan(magnet, tip)
        return self._d_range[key]

    def _scan(self, magnet: str, tip: str) -> tuple[float, float] | None:
        r_m, _ = self._magnet(magnet)
        r_p = r_m + self.clearance
        if self.channel > r_p:
            return None
        lo = 2.0 * max(r_p + self.skin, self.channel + self.annulus)
        hi = min(self.max_diameter, 2.0 * self.max_height if tip == "hemisphere" else math.inf)
        c = self.variables.elastomer_diameter_mm
        values = ([x for x in c if lo <= x <= hi] if isinstance(c, list)
                  else [float(x) for x in np.linspace(max(c[0], lo), min(c[1], hi), _SCAN)] if max(c[0], lo) <= min(
                      c[1], hi) else [])
        ok = [x for x in values if self._d_ok(magnet, tip, x)]
        return (ok[0], ok[-1]) if ok else None

    def pairs(self) -> list[tuple[str, str]]:
        """Every (material, tip) pair of the choices, materials first, in the choices' order."""
        return [(m, t) for m in self.choices["material"] for t in self.choices["tip"]]

    def buildable(self) -> list[tuple[str, str, str]]:
        """Every (magnet, material, tip) combination with a buildable design, in a fixed order."""
        return [(m, mat, t) for mat in self.choices["material"] for t in self.choices["tip"]
                for m in self.choices["magnet"] if self.diameter_range(m, t) is not None]

    # fractions <-> mm ----------------------------------------------------------------------------------------------

    def point(self, params: dict[str, Any]) -> dict[str, Any]:
        """The mm point of a trial's params (categories and fractions; a listed-values variable's own value, moved to
        the nearest allowed one)."""
        tip = str(params["tip"])
        # a study stored before the magnet's fraction names the magnet itself
        magnet = str(params["magnet"]) if "magnet" in params else self.magnet_at(tip, float(params[MAGNET_FRACTION]))
        numeric = {k: np.array([float(params[k])]) for k in self.numeric_params()}
        row = self.mm([(magnet, tip)], np.zeros(1, dtype=int), numeric)[0]
        return point_of({"magnet": magnet, "material": params["material"], "tip": tip,
                         **{name: float(x) for name, x in zip(NUMERIC, row)}})

    def numeric_params(self) -> list[str]:
        """Each numeric variable's param, in :data:`NUMERIC`'s order: its fraction, or a listed variable's name."""
        return [name if isinstance(getattr(self.variables, name), list) else FRACTION_OF[name] for name in NUMERIC]

    def mm(self, combos: list[tuple[str, str]], which: np.ndarray, numeric: dict[str, np.ndarray]) -> np.ndarray:
        """The numeric variables in mm (an array of rows in :data:`NUMERIC`'s order) of many designs at once:
        ``combos`` lists (magnet, tip) combinations and ``which`` each design's index into it; ``numeric`` holds each
        :meth:`numeric_params` param's values, one per design. Each variable is resolved after the ones it depends on
        (the elastomer's diameter, the rest distance, the cover, the closest distance), each within the bounds the
        choices before it leave, by :meth:`point`'s rules, element by element: the search's model step maps its
        ~2,000 candidates a proposal with this (bench: the mapping had taken half a study's main loop). All designs
        at once, each with its (magnet, tip)'s figures as arrays (a loop over the (magnet, tip)s the designs use, 34
        for the whole box's candidates, had cost 1.7 ms a call, about a sixth of a proposal); the same numbers."""
        v = self.variables

        def value(name: str, lo: Any, hi: Any) -> np.ndarray:
            c = getattr(v, name)
            x = numeric[name if isinstance(c, list) else FRACTION_OF[name]]
            if isinstance(c, list):
                return nearest_allowed(c, lo, hi, x)
            a, b = range_within(c, lo, hi)
            return a + np.clip(x, 0.0, 1.0) * (b - a)

        kinds = np.unique(which)  # each (magnet, tip) the designs use: its figures, then each design's
        span = span_of(v.elastomer_diameter_mm)
        per = np.array([[*self._of(magnet, tip), *(self.diameter_range(magnet, tip) or span)]
                        for magnet, tip in (combos[int(k)] for k in kinds)])
        r_m, h_m, floor, hemi, d_lo, d_hi = per[np.searchsorted(kinds, which)].T
        hemi = hemi.astype(bool)
        with np.errstate(invalid="ignore"):  # no height limit less an infinite cover: not a number (range_within)
            d_e = value("elastomer_diameter_mm", d_lo, d_hi)
            d_max = value("d_max_mm", *self._d_max_within(r_m, h_m, floor, hemi, d_e))
            cover = value("cover_mm", *self._cover_within(r_m, h_m, hemi, d_e, d_max))
            d_min = value("d_min_mm", *self._d_min_within(floor, d_max))
        return np.column_stack([d_max, d_min, d_e, cover])

    def params(self, point: dict[str, Any]) -> dict[str, Any]:
        """A trial's params for a mm point (the inverse of :meth:`point` for a point inside the bounds)."""
        magnet, tip = f"{point['magnet']}:{point['grade']}", str(point["tip"])
        v = self.variables
        d_e, d_max = float(point["elastomer_diameter_mm"]), float(point["d_max_mm"])
        bounds = {"elastomer_diameter_mm": self.diameter_range(magnet, tip) or span_of(v.elastomer_diameter_mm),
                  "d_max_mm": self.d_max_bounds(magnet, tip, d_e),
                  "cover_mm": self.cover_bounds(magnet, tip, d_e, d_max),
                  "d_min_mm": self.d_min_bounds(magnet, d_max)}
        out: dict[str, Any] = {"material": point["material"], "tip": tip,
                               MAGNET_FRACTION: self.magnet_fraction(tip, magnet)}
        for name, (lo, hi) in bounds.items():
            c = getattr(v, name)
            out.update({name: float(point[name])} if isinstance(c, list)
                       else {FRACTION_OF[name]: fraction_within(c, lo, hi, float(point[name]))})
        return out

    def param_names(self) -> list[str]:
        """A trial's params, in :meth:`suggest`'s order: the material, the tip, the magnet's fraction, then
        :meth:`numeric_params`."""
        return ["material", "tip", MAGNET_FRACTION, *self.numeric_params()]

    def distributions(self) -> dict[str, Any]:
        """Each param's Optuna distribution (:meth:`param_names`): the choices', the listed values', and [0, 1] for
        every fraction."""
        from optuna.distributions import CategoricalDistribution, FloatDistribution

        out: dict[str, Any] = {k: CategoricalDistribution(self.choices[k]) for k in ("material", "tip")}
        out[MAGNET_FRACTION] = FloatDistribution(0.0, 1.0)
        for name in NUMERIC:
            c = getattr(self.variables, name)
            out.update({name: CategoricalDistribution(list(c))} if isinstance(c, list)
                       else {FRACTION_OF[name]: FloatDistribution(0.0, 1.0)})
        return out

    def suggest(self, trial) -> dict[str, Any]:
        """The mm point an Optuna trial draws (ask-and-tell), each of :meth:`distributions` in turn. The trial keeps
        the point as its user attribute :data:`POINT` (what tables and the front read)."""
        from optuna.distributions import CategoricalDistribution

        params: dict[str, Any] = {}
        for name, d in self.distributions().items():
            params[name] = (trial.suggest_categorical(name, d.choices) if isinstance(d, CategoricalDistribution)
                            else trial.suggest_float(name, d.low, d.high))
        point = self.point({k: float(v) if k in NUMERIC else v for k, v in params.items()})
        trial.set_user_attr(POINT, point)
        return point

    def latin_hypercube(self, n: int, seed: int) -> list[dict[str, Any]]:
        """``n`` trials' params of a Latin hypercube in the search's coordinates: the (material, tip) pairs in equal
        strata (every pair at least once when ``n`` is at least their number), the magnet's and the numeric
        variables' fractions in ``n`` strata each. Only combinations with a buildable design."""
        from scipy.stats import qmc

        combos = self.buildable()
        pairs = sorted({(mat, t) for _, mat, t in combos}, key=lambda p: (self.choices["material"].index(p[0]),
                                                                           self.choices["tip"].index(p[1])))
        u = qmc.LatinHypercube(d=2 + len(NUMERIC), seed=seed).random(n)
        out = []
        for row in u:
            mat, tip = pairs[min(int(row[0] * len(pairs)), len(pairs) - 1)]
            params: dict[str, Any] = {"material": mat, "tip": tip, MAGNET_FRACTION: float(row[1])}
            for name, x in zip(NUMERIC, row[2:]):
                c = getattr(self.variables, name)
                params.update({name: float(c[min(int(x * len(c)), len(c) - 1)])} if isinstance(c, list)
                              else {FRACTION_OF[name]: float(x)})
            out.append(params)
        return out


def magnet_moment(magnet: str) -> float:
    """A "DISC:GRADE" magnet's moment up to a constant: its volume times its grade's nominal remanence."""
    disc, grade = magnet.split(":")
    d, h, _ = stock_disc(disc)
    return d * d * h * magnet_grade(grade).remanence_T.nominal


@lru_cache(maxsize=8)
def _board_limit(base: Spec, top: float) -> float:
    """The largest elastomer diameter (up to ``top``) whose grown pad the base's board still holds (its connector
    outside the pad's keep-out): bisected on the base design with a flat tip, 0.01 mm; ``top`` when it fits."""

    def fits(d_e: float) -> bool:
        raw = base.toml_dict()
        raw["elastomer"].update(diameter_mm=d_e, tip="flat")
        raw["elastomer"].pop("cover_mm", None)
        raw["pad"].update(_pad_for(base, d_e))
        try:
            preflight(derive(spec_from_dict(raw)))
        except SpecError as exc:
            return not str(exc.key).startswith("pcb.")
        return True

    if fits(top):
        return top
    lo, hi = base.elastomer.diameter_mm, top
    if not fits(lo):
        return lo
    while hi - lo > 0.01:
        mid = (lo + hi) / 2.0
        lo, hi = (mid, hi) if fits(mid) else (lo, mid)
    return lo


@lru_cache(maxsize=256)
def _saturation_floor(disc: str, grade: str, full_scale_G: float) -> float:
    d, h, _ = stock_disc(disc)
    strongest = Magnet(d / 2.0, h, magnet_grade(grade).remanence_T.high)
    return saturation_gap(strongest, full_scale_G)


def saturation_floor(point: dict[str, Any], base: Spec, targets: Targets) -> float:
    """:meth:`Space.saturation_floor` of a point's magnet (``magnet`` a stock disc, ``grade``), without the space."""
    return _saturation_floor(str(point["magnet"]), str(point["grade"]), _full_scale_z_G(base, targets))


def _full_scale_z_G(base: Spec, targets: Targets) -> float:
    """The chip's Bz full scale (G) at the targets' register fields ([chip]), on the base design."""
    return _full_scale_of(base, targets.chip)


@lru_cache(maxsize=8)
def _full_scale_of(base: Spec, chip: Chip) -> float:
    """:func:`_full_scale_z_G`, derived once per base and chip (both frozen, hashable): :func:`saturation_floor`
    asks for it on every verified design."""
    raw = base.toml_dict()
    raw["sensor"].update(**chip.model_dump())
    return chip_setting(derive(spec_from_dict(raw))).full_scale_z_G
