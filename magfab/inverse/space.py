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
from ..recipes import catalogue
from ..spec import Spec, spec_from_dict
from .targets import Targets, Variables

# Imported lazily, inside the functions that use it, for speed: scipy takes a
# noticeable time to import, and importing this module should not.

__all__ = ["NUMERIC", "CATEGORICAL", "stock_disc", "candidate_spec", "suggest", "grid", "latin_hypercube",
           "base_point"]

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
