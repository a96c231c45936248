"""TARGETS.toml: what the sensor must do, what the search may change, and what it should make best.

    name = "fingertip14"                 # names the output folder (design/<name>/ by default)
    base = "finger.toml"                 # optional: the spec every candidate starts from (default: MagOne),
                                         # relative to this file; keys the search does not set are kept
    objectives = ["normal_resolution_mN", "diameter_mm", "normal_range_N"]

    [require]                            # every returned design meets all of these (omit a key: no requirement)
    normal_resolution_mN = 2.0           # at most: worst case over the material and grade bands
    normal_range_N = 3.0                 # at least: the softest material's range
    max_diameter_mm = 14.0
    max_drift_mN_per_C = 1.0             # at most: normal force drift at rest per degree C
    max_earth_field_mN = 5.0             # at most: normal force error when turned over in the Earth's field
    noise_G = 0.1                        # the environment's RMS field noise, gauss
    margin = "model"                     # each met by at least the models' own error (or a percentage, e.g. 5)

    [variables]                          # what the search may change: a [low, high] range or a list of values
    magnets = "stock"                    # the stock discs (recipes/magnet_stock.toml) or a list of their keys
    grades = ["N35", "N42", "N45", "N52"]
    materials = ["ecoflex-00-30", "dragon-skin-10"]
    tips = ["hemisphere"]
    d_max_mm = [3.0, 10.0]
    d_min_mm = [2.0, 4.0]
    elastomer_diameter_mm = [8.0, 14.0]
    cover_mm = [0.5, 3.0]

    [chip]                               # register fields every candidate uses (sensor.*)
    gain_sel = 0

    [study]
    trials = 250                          # designs the search evaluates (cheap models)
    verify = 8                            # designs near the front re-evaluated by the full model chain (FE)
    seed = 0

Objectives and requirements are the build's own figures (predictions.json): resolution is the worst case over the
bands, range the softest material's, size the elastomer's diameter and height, drift and the Earth field's error
the drift budget's (predictions.json's ``drift``). Every requirement the models predict is met by a margin: the
model chain's own error estimate (``margin = "model"``), or the percentage given.
"""

from __future__ import annotations

import hashlib
import json
import tomllib
from enum import Enum
from pathlib import Path
from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError, field_serializer, field_validator

from ..errors import InputError, SpecError, shown
from ..recipes import catalogue
from ..recipes.resolve import yeoh_fitted
from ..spec import NAME_PATTERN, MaterialLawChoice, Sensor, Spec, Tip, is_valid_name, load_spec, translate_error
from ..toml_input import loads_toml, read_toml

__all__ = ["Objective", "OBJECTIVES", "Targets", "load_targets", "parse_targets"]


class Objective(str, Enum):
    """What a design can be made best at, with its direction (:data:`OBJECTIVES`)."""

    NORMAL_RESOLUTION = "normal_resolution_mN"
    SHEAR_RESOLUTION = "shear_resolution_mN"
    NORMAL_RANGE = "normal_range_N"
    SHEAR_RANGE = "shear_range_N"
    DIAMETER = "diameter_mm"
    HEIGHT = "height_mm"
    DRIFT = "drift_mN_per_C"
    EARTH_FIELD = "earth_field_mN"


Direction = Literal["minimize", "maximize"]
#: Objective -> "minimize" or "maximize".
OBJECTIVES: dict[Objective, Direction] = {
    Objective.NORMAL_RESOLUTION: "minimize", Objective.SHEAR_RESOLUTION: "minimize",
    Objective.NORMAL_RANGE: "maximize", Objective.SHEAR_RANGE: "maximize",
    Objective.DIAMETER: "minimize", Objective.HEIGHT: "minimize",
    Objective.DRIFT: "minimize", Objective.EARTH_FIELD: "minimize"}


class _Table(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False)


Range = tuple[float, float]
Choice = Range | list[float]  # a [low, high] range or (in a table {values = [...]}) listed values


#: The largest margin a requirement may ask, percent.
MAX_MARGIN_PCT = 50.0


class Require(_Table):
    """Requirements every returned design meets (None: no requirement)."""

    normal_resolution_mN: float | None = Field(None, gt=0.0, le=1e4,
                                               description="Worst-case normal resolution, at most, mN.")
    shear_resolution_mN: float | None = Field(None, gt=0.0, le=1e4,
                                              description="Worst-case shear resolution, at most, mN.")
    normal_range_N: float | None = Field(None, gt=0.0, le=1e3, description="Normal force range, at least, N.")
    shear_range_N: float | None = Field(None, gt=0.0, le=1e3, description="Shear force range, at least, N.")
    max_diameter_mm: float | None = Field(None, gt=0.0, le=100.0, description="Largest elastomer diameter, mm.")
    max_height_mm: float | None = Field(None, gt=0.0, le=100.0, description="Largest elastomer height, mm.")
    max_drift_mN_per_C: float | None = Field(None, gt=0.0, le=1e4,
                                             description="Normal force drift at rest per degree C, at most, mN/C "
                                                         "(with the chip-temperature compensation when the firmware "
                                                         "applies it).")
    max_earth_field_mN: float | None = Field(None, gt=0.0, le=1e5,
                                             description="Normal force error when the sensor is turned over in the "
                                                         "strongest Earth field (0.65 G), at most, mN.")
    noise_G: float = Field(0.1, ge=0.0, le=100.0, description="RMS field noise of the environment, gauss.")
    margin: Literal["model"] | float = Field("model", description="How far every design meets each requirement the "
                                             "models predict: \"model\" (the model chain's own error estimate) or "
                                             "a percentage.")

    @field_validator("margin", mode="before")
    @classmethod
    def _margin(cls, v: Any) -> Any:
        if v == "model":
            return v
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise ValueError(f"must be \"model\" (the models' own error) or a percentage from 0 to {MAX_MARGIN_PCT:g}")
        if not 0.0 <= float(v) <= MAX_MARGIN_PCT:
            raise ValueError(f"must be a percentage from 0 to {MAX_MARGIN_PCT:g} (or \"model\")")
        return float(v)


def _range(v: Any, lo: float, hi: float, what: str) -> Any:
    """A [low, high] pair (TOML array) within [lo, hi], or a {values = [...]} table of listed values (and the
    {range = [low, high]} its JSON form writes for a pair)."""
    if isinstance(v, tuple):
        v = list(v)
    if isinstance(v, dict) and set(v) == {"range"}:
        v = v["range"]
    if isinstance(v, dict):
        if set(v) != {"values"} or not isinstance(v["values"], list) or not v["values"]:
            raise ValueError("must be [low, high] or {values = [v1, v2, ...]}")
        values = v["values"]
    elif isinstance(v, list) and len(v) == 2:
        values = v
    else:
        raise ValueError("must be [low, high] or {values = [v1, v2, ...]}")
    if not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in values):
        raise ValueError("must hold numbers")
    try:
        values = [float(x) for x in values]
    except OverflowError:  # an integer past a float's range: pydantic reports ValueError, and it is out of bounds
        raise ValueError(f"must lie within {lo:g} to {hi:g} {what}") from None
    if not all(lo <= x <= hi for x in values):
        raise ValueError(f"must lie within {lo:g} to {hi:g} {what}")
    if isinstance(v, dict):
        return sorted(set(values))
    if values[0] > values[1]:
        raise ValueError("must be [low, high] with low <= high")
    return (values[0], values[1])


class Variables(_Table):
    """What the search may change. Numbers: a [low, high] range or {values = [...]}."""

    magnets: str | list[str] = Field("stock", description="'stock' (every disc of recipes/magnet_stock.toml) "
                                                                "or a list of its keys.")
    grades: list[str] = Field(["N35", "N42", "N45", "N52"], description="Magnet grades, keys of recipes/magnets.toml.")
    materials: list[str] | None = Field(None, description="Silicones, keys of recipes/materials.toml (default: all).")
    tips: list[Tip] = Field([Tip.FLAT, Tip.HEMISPHERE], description="Tip shapes.")
    d_max_mm: Choice = Field((3.0, 10.0), description="Rest distance magnet to sensing point, mm.")
    d_min_mm: Choice = Field((2.0, 4.0), description="Closest distance under load, mm.")
    elastomer_diameter_mm: Choice = Field((8.0, 20.0), description="Elastomer diameter, mm.")
    cover_mm: Choice = Field((0.5, 4.0), description="Silicone above the magnet on the axis, mm.")

    @field_validator("d_max_mm", "d_min_mm", "elastomer_diameter_mm", "cover_mm", mode="before")
    @classmethod
    def _numbers(cls, v: Any, info) -> Any:
        bounds = {"elastomer_diameter_mm": (4.0, 40.0), "cover_mm": (0.2, 20.0)}.get(info.field_name, (0.5, 40.0))
        return _range(v, *bounds, "mm")

    @field_serializer("d_max_mm", "d_min_mm", "elastomer_diameter_mm", "cover_mm")
    def _tagged(self, c: Choice) -> dict[str, list[float]]:
        """JSON keeps a range and listed values apart (both would be arrays): what workers and the study's hash read."""
        return {"values": list(c)} if isinstance(c, list) else {"range": list(c)}

    @field_validator("magnets")
    @classmethod
    def _magnets(cls, v: str | list[str]) -> str | list[str]:
        known = sorted(catalogue("magnet_stock"))
        if isinstance(v, str):
            if v != "stock":
                raise ValueError("must be \"stock\" or a list of keys of recipes/magnet_stock.toml")
            return v
        return _known(v, known, "recipes/magnet_stock.toml")

    @field_validator("grades")
    @classmethod
    def _grades(cls, v: list[str]) -> list[str]:
        return _known(v, sorted(catalogue("magnets")), "recipes/magnets.toml")

    @field_validator("materials")
    @classmethod
    def _materials(cls, v: list[str] | None) -> list[str] | None:
        return None if v is None else _known(v, sorted(catalogue("materials")), "recipes/materials.toml")

    @field_validator("tips", mode="before")
    @classmethod
    def _tips(cls, v: Any) -> Any:
        return sorted(set(_enums(v, Tip)), key=lambda t: t.value)

    def magnet_keys(self) -> list[str]:
        return sorted(catalogue("magnet_stock")) if self.magnets == "stock" else list(self.magnets)

    def material_keys(self) -> list[str]:
        return sorted(catalogue("materials")) if self.materials is None else list(self.materials)


def _enums(v: Any, kind: type[Enum]) -> list:
    """A non-empty TOML array of names to the Enum's members (strict mode takes members only); an unknown name, or
    none, names the choices."""
    names = [m.value for m in kind]
    if not isinstance(v, list) or not v:
        raise ValueError("must be a non-empty array of: " + ", ".join(names))
    out = []
    for x in v:
        if x not in names:
            raise ValueError(f"{shown(x)} is not one of " + ", ".join(names))  # shown: a long name is cut
        out.append(kind(x))
    return out


def _known(values: list[str], known: list[str], where: str) -> list[str]:
    if not values:
        raise ValueError(f"must name at least one of {where}")
    for v in values:
        if v not in known:
            raise ValueError(f"{shown(v)} is not a key of {where} (" + ", ".join(known) + ")")  # shown: cut if long
    return sorted(set(values))


class Chip(_Table):
    """Register fields every candidate uses: the spec's [sensor] fields themselves (defaults, bounds, descriptions)."""

    # pydantic takes a FieldInfo as the field's whole definition; mypy sees only an int declared as a FieldInfo.

    gain_sel: int = Sensor.model_fields["gain_sel"]  # type: ignore[assignment]
    resolution: int = Sensor.model_fields["resolution"]  # type: ignore[assignment]
    osr: int = Sensor.model_fields["osr"]  # type: ignore[assignment]
    dig_filt: int = Sensor.model_fields["dig_filt"]  # type: ignore[assignment]


class Sampler(str, Enum):
    """Optuna's samplers for several objectives with constraints."""

    TPE = "tpe"
    NSGA2 = "nsga2"


class Models(str, Enum):
    """The model chain the search evaluates designs with."""

    SURROGATE = "surrogate"
    FE = "fe"


class Study(_Table):
    """How the search runs."""

    trials: int = Field(300, ge=1, le=1_000_000, description="Designs the search evaluates with the cheap models.")
    verify: int = Field(8, ge=1, le=64, description="Designs near the front re-evaluated by the full chain (FE).")
    seed: int = Field(0, ge=0, le=2**31 - 1)
    sampler: Sampler = Field(Sampler.TPE, strict=False, description="'tpe' or 'nsga2' (Optuna).")
    models: Models = Field(Models.SURROGATE, strict=False,
                           description="'surrogate' (the elastomer surrogate: milliseconds per design) or 'fe' (the "
                                       "full chain for every design: seconds each).")
    storage: str | None = Field(None, description="Optuna storage: a database URL (postgresql://..., sqlite:///...) "
                                                     "that many machines share; default: the journal file study.log "
                                                     "in the output folder.")


class Targets(_Table):
    """A whole TARGETS file (module doc)."""

    name: str = Field("design", pattern=NAME_PATTERN)
    base: str | None = Field(None, description="Spec file every candidate starts from, relative to TARGETS.")
    objectives: list[Objective] = Field([Objective.NORMAL_RESOLUTION, Objective.DIAMETER])
    require: Require = Field(default_factory=Require)
    variables: Variables = Field(default_factory=Variables)
    chip: Chip = Field(default_factory=Chip)
    study: Study = Field(default_factory=Study)

    @field_validator("objectives", mode="before")
    @classmethod
    def _objectives(cls, v: Any) -> Any:
        names = _enums(v, Objective)
        if len(set(names)) != len(names):
            raise ValueError("must name distinct objectives")
        return names

    def directions(self) -> list[Direction]:
        return [OBJECTIVES[o] for o in self.objectives]

    def sha256(self) -> str:
        """What a study's results depend on: everything but how long it runs and where it is stored (a study resumed
        with more trials is the same study)."""
        raw = self.model_dump(mode="json")
        raw["study"] = {k: v for k, v in raw["study"].items() if k not in ("trials", "verify", "storage")}
        return hashlib.sha256(json.dumps(raw, sort_keys=True).encode()).hexdigest()


def _lowest(c: Choice) -> float:
    return float(min(c))


def parse_targets(text: str, default_name: str = "design", where: str = "<TOML>") -> Targets:
    """Validate TARGETS TOML text (``where`` names it: its path); errors are :class:`SpecError` lines naming the
    key."""
    try:
        raw = loads_toml(text, "targets", where)
    except InputError:  # a bound of the file (magfab.formats.bounded), already one line
        raise
    except (tomllib.TOMLDecodeError, ValueError) as exc:
        raise SpecError("targets", "<TOML>", f"not valid TOML: {exc}") from None
    raw.setdefault("name", default_name)
    if not is_valid_name(str(raw["name"])):
        raise SpecError("name", shown(raw["name"]), "must match " + NAME_PATTERN, "add name = \"...\" to the targets")
    try:
        targets = Targets.model_validate(raw)
    except ValidationError as exc:
        raise translate_error(exc, raw, Targets) from None
    lo, top = _lowest(targets.variables.elastomer_diameter_mm), targets.require.max_diameter_mm
    if top is not None and lo > top:
        raise SpecError("variables.elastomer_diameter_mm", shown(lo), f"must start at or below require.max_diameter_mm "
                        f"= {top:g} mm")
    return targets


def load_targets(path: str | Path) -> tuple[Targets, Spec]:
    """The targets and the base spec they start from (its own file, or MagOne)."""
    path = Path(path)
    text = read_toml(path, "targets")
    targets = parse_targets(text, default_name=path.stem if is_valid_name(path.stem) else "design", where=str(path))
    base = load_spec(path.parent / targets.base) if targets.base else load_spec()
    return _with_the_laws_silicones(targets, base), base


def _with_the_laws_silicones(targets: Targets, base: Spec) -> Targets:
    """With a Yeoh base (predict.material_law), the silicones the recipes fit a Yeoh law for: by default those
    alone, and a listed one without a fit refused up front rather than as a failed trial each time it is drawn."""
    if base.predict.material_law != MaterialLawChoice.YEOH:
        return targets
    fitted = yeoh_fitted()
    if targets.variables.materials is None:
        variables = targets.variables.model_copy(update={"materials": list(fitted)})
        return targets.model_copy(update={"variables": variables})
    missing = [m for m in targets.variables.materials if m not in fitted]
    if missing:
        raise SpecError("variables.materials", missing, f"the base spec's predict.material_law = 'yeoh' has no fit "
                        f"for these (fitted: {', '.join(fitted)}); leave them out or use 'neo-hookean'")
    return targets
