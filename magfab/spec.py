"""The design spec: TOML in, a frozen and validated :class:`Spec` out.

Every problem is raised as one :class:`~magfab.errors.SpecError` that names the dotted key path, the
value and what is allowed. Units are in the key names; geometry is in millimetres.

The JSON Schema shipped beside this module (``spec.schema.json``) is generated from these models:
``magfab schema > magfab/spec.schema.json`` regenerates it, and a test keeps it in step.
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import tomllib
from enum import Enum
from importlib import resources
from pathlib import Path
from typing import Any

from pydantic import Field, ValidationError, field_validator, model_validator

from .errors import SpecError, shorten, shown
from .readout.src.magfab_readout import bounded
from .recipes import catalogue
from .spec_errors import did_you_mean, translate_error
from .spec_options import CalibrationMethod, FieldModel, MaterialLaw, MaterialLawChoice, MechanicsModel
from .spec_sections import Board, Environment, Reference
from .spec_sections import Section as _Section
from .toml_input import loads_toml, read_toml

__all__ = ["Spec", "Board", "Tip", "Density", "Printer", "Array", "Environment", "Skin", "Polarity", "MAX_TAXELS",
           "load_spec",
           "spec_from_json", "parse_spec", "spec_from_dict", "default_spec_text", "translate_error", "spec_schema",
           "NAME_PATTERN", "is_valid_name", "FieldModel", "MechanicsModel", "MaterialLaw", "MaterialLawChoice",
           "CalibrationMethod"]

NAME_PATTERN = r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$"


def is_valid_name(name: str) -> bool:
    """Whether ``name`` matches all of :data:`NAME_PATTERN` (``$`` alone takes a trailing newline: bad TOML)."""
    return re.fullmatch(NAME_PATTERN, name) is not None


class Tip(str, Enum):
    """Shape of the elastomer's top."""

    HEMISPHERE = "hemisphere"
    FLAT = "flat"


class Density(str, Enum):
    """IPC-7351B land-pattern density level: 'most' (largest lands, easiest to hand-solder), 'nominal', 'least'."""

    LEAST = "least"
    NOMINAL = "nominal"
    MOST = "most"


class Printer(str, Enum):
    """Printer kind for the mould and pad; selects a recipe in ``recipes/printers.toml``."""

    SLA = "sla"
    FDM = "fdm"


def _mm(default: float, description: str, *, gt: float | None = 0.0, ge: float | None = None, le: float = 100.0) -> Any:
    if ge is not None:
        gt = None
    return Field(default, gt=gt, ge=ge, le=le, description=description)


class Magnet(_Section):
    """The permanent magnet: an axially magnetised cylinder."""

    diameter_mm: float = _mm(5.0, "Magnet diameter D_m, mm.", le=50.0)
    height_mm: float = _mm(2.0, "Magnet height H_m along its magnetisation axis, mm.", le=50.0)
    grade: str = Field("N35", description="NdFeB grade, a key of recipes/magnets.toml (N35, N42, N45, N52).")


class Elastomer(_Section):
    """The cast silicone body: a cylindrical base with a hemispherical or flat top, magnet pocket inside."""

    material: str = Field("ecoflex-00-30", description="Silicone, a key of recipes/materials.toml.")
    diameter_mm: float = _mm(12.0, "Elastomer diameter D_e, mm.")
    height_mm: float = _mm(7.9, "Total elastomer height H_e, base to the top of the tip on the axis, mm.")
    tip: Tip = Field(Tip.HEMISPHERE, strict=False, description="Top shape: 'hemisphere' (radius D_e/2) or 'flat'.")
    pocket_clearance_mm: float = _mm(0.05, "Clearance between magnet and pocket, on the radius and the height, mm.",
                                     ge=0.0, le=1.0)
    cover_mm: float | None = Field(
        None,
        gt=0.0,
        le=100.0,
        description="Silicone above the magnet on the axis, mm. Omit to derive it from sensor.d_max_mm; "
        "if given, it must reproduce d_max_mm.",
    )
    insert_channel_diameter_mm: float = _mm(
        2.0, "Diameter of the channel from the base to the pocket through which the magnet is pushed in "
        "(silicone stretches), mm. Sealed by the glue to the pad.", le=50.0
    )
    min_skin_mm: float = _mm(0.4, "Thinnest silicone allowed between the pocket and the outer surface, mm.", le=10.0)
    shear_modulus_kPa: tuple[float, float, float] | None = Field(
        None, description="Override the material's neo-Hookean shear modulus band [soft, nominal, stiff], kPa "
        "(e.g. from your own batch's tensile test); omit to use the recipe's.")

    @field_validator("shear_modulus_kPa", mode="before")
    @classmethod
    def _array(cls, v: Any) -> Any:
        """TOML gives an array as a list; strict mode takes only a tuple, so the shipped (commented) line
        ``shear_modulus_kPa = [15.0, 23.0, 39.0]`` was refused."""
        if isinstance(v, list):
            if len(v) != 3 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
                raise ValueError("must be an array of three numbers [soft, nominal, stiff], kPa")
            return tuple(float(x) for x in v)
        return v

    @field_validator("shear_modulus_kPa")
    @classmethod
    def _band(cls, v: tuple[float, float, float] | None) -> tuple[float, float, float] | None:
        if v is not None and not (0 < v[0] <= v[1] <= v[2] <= 1.0e5):
            raise ValueError("must be three moduli in kPa with 0 < soft <= nominal <= stiff <= 100000")
        return v


class Sensor(_Section):
    """The Hall chip and where the magnet sits above it."""

    chip: str = Field("mlx90393", description="Chip, a key of recipes/chips.toml.")
    sensing_depth_mm: float | None = Field(
        None,
        ge=0.0,
        le=5.0,
        description="Depth of the Hall sensing point below the top of the chip package, mm. "
        "Omit to use the chip recipe's value.",
    )
    d_max_mm: float = _mm(6.0, "Rest distance from the magnet's lower face to the sensing point, mm.", le=100.0)
    d_min_mm: float = _mm(2.5, "Closest allowed magnet-to-sensing-point distance under load, mm.", le=100.0)
    option_code: str = Field(
        "011", pattern=r"^[0-9]{3}$",
        description="Chip option code (the -0xx of the order number); sets the I2C base address.",
    )
    i2c_address: int = Field(
        0x0C, ge=0, le=0x7F,
        description="7-bit I2C address: the option code's base plus the A1/A0 pin straps the board wires.",
    )
    gain_sel: int = Field(0, ge=0, le=7, description="GAIN_SEL register field, 0 (least sensitive, widest range) to 7.")
    resolution: int = Field(2, ge=0, le=3,
                            description="RES_XYZ register field (all axes), 0-3: each step doubles the uT per LSB.")
    osr: int = Field(0, ge=0, le=3, description="OSR register field (ADC oversampling 2^OSR), 0-3.")
    dig_filt: int = Field(2, ge=0, le=7, description="DIG_FILT register field (averaging 2^DIG_FILT), 0-7.")


class Pad(_Section):
    """The rigid mounting pad: a disc with a chip recess below, a centring lip above, alignment holes."""

    diameter_mm: float = _mm(20.0, "Pad diameter, mm.")
    thickness_mm: float = _mm(2.0, "Pad thickness from the board to the glue face, mm.", le=20.0)
    recess_clearance_mm: float = _mm(
        0.1, "Clearance around and above the chip package in the recess, mm.", ge=0.0, le=2.0
    )
    glue_thickness_mm: float = _mm(0.1, "Sil-Poxy layer between pad and elastomer, mm.", ge=0.0, le=2.0)
    lip_height_mm: float = _mm(0.6, "Height of the centring lip around the elastomer (0: no lip), mm.", ge=0.0, le=10.0)
    lip_width_mm: float = _mm(0.8, "Radial width of the centring lip, mm.", le=10.0)
    lip_clearance_mm: float = _mm(0.1, "Radial clearance between elastomer and lip, mm.", ge=0.0, le=2.0)
    alignment_hole_diameter_mm: float = _mm(
        1.0, "Diameter of the first alignment hole (dowel pin into the board); the second is 0.5 mm larger "
        "so the pad only fits one way round, mm.", le=10.0
    )
    alignment_hole_spacing_mm: float = _mm(16.5,
                                           "Centre-to-centre spacing of the two alignment holes, on the x axis, mm.")


class Pcb(_Section):
    """The breakout board: outline, design rules and options. The chip sits at the board's centre."""

    width_mm: float = _mm(30.0, "Board width (x), mm.", le=200.0)
    height_mm: float = _mm(30.0, "Board height (y), mm.", le=200.0)
    thickness_mm: float = Field(1.6, ge=0.4, le=3.2, description="Board thickness, mm.")
    clearance_mm: float = Field(0.15, ge=0.1, le=1.0, description="Minimum copper clearance between nets, mm.")
    track_width_mm: float = Field(0.25, ge=0.1, le=1.0, description="Track width, mm.")
    via_drill_mm: float = Field(0.3, ge=0.2, le=1.0, description="Via drill, mm.")
    via_diameter_mm: float = Field(0.6, ge=0.4, le=2.0, description="Via pad diameter, mm.")
    edge_clearance_mm: float = Field(0.3, ge=0.1, le=2.0, description="Copper to board edge, mm.")
    density: Density = Field(
        Density.NOMINAL, strict=False,
        description="IPC-7351B density level of the land patterns: 'least', 'nominal' or 'most'.",
    )
    pullups: bool = Field(True, description="Fit 2.2 kOhm I2C pull-ups to 3.3 V (as on Qwiic boards).")
    mounting_hole_diameter_mm: float = Field(
        2.2, ge=0.0, le=5.0,
        description="Two screw holes at the corners away from the connector (0: none), mm.",
    )
    mounting_hole_inset_mm: float = _mm(3.0, "Mounting-hole centre to the board edges, mm.", le=50.0)


class Mould(_Section):
    """The printed casting mould: a cup with the cavities and a lid that carries the pocket cores."""

    printer: Printer = Field(Printer.SLA, strict=False,
                             description="Printer kind: 'sla' or 'fdm' (recipes/printers.toml).")
    wall_mm: float = _mm(2.0, "Wall around and below each cavity and between cavities, mm.", le=50.0)
    cavities: int = Field(1, ge=1, le=16, description="Cavities per mould, in a row.")
    tessellation_tolerance_mm: float = _mm(
        0.01, "Largest distance between an STL and the exact surface, mm.", le=1.0
    )
    angular_tolerance_deg: float = Field(
        10.0, gt=0.5, le=45.0,
        description="Largest angle between neighbouring STL facet normals on curved faces, degrees."
    )


class Predict(_Section):
    """Predicted sensitivity, resolution and range, and the models behind them."""

    tolerance_pct: float = Field(1.0, gt=0.0, le=50.0,
                                 description="Model error the predictions may carry, % of the value.")
    field_model: FieldModel = Field(FieldModel.AUTO, strict=False,
                                    description="'auto', 'exact', 'surrogate', 'dipole' or 'on_axis'.")
    mechanics_model: MechanicsModel = Field(
        MechanicsModel.AUTO, strict=False, description="'auto', 'fe', 'hertz_column' or 'column'.")
    noise_G: float = Field(0.1, ge=0.0, le=100.0,
                           description="RMS field noise of the environment at the sensor, gauss.")
    required_resolution_mN: float | None = Field(
        None, gt=0.0, le=1.0e4,
        description="Worst-case normal force resolution the application needs, mN (omit: no requirement).")
    material_law: MaterialLawChoice = Field(
        MaterialLawChoice.AUTO, strict=False,
        description="Hyperelastic law of the elastomer FE: 'auto' (the silicone's Yeoh law where "
                    "recipes/materials.toml fits one, neo-Hookean otherwise or with a closed-form mechanics model), "
                    "'yeoh' (the silicone's large-strain law, fitted to a stretch of 4) or 'neo-hookean' (fitted to "
                    "100 % strain, so its data end at a stretch of 2).")
    # Not a limit of the model: the model's own reach is the material law's data end (predict's "material data"
    # limit). No fatigue or working-strain rule for casting silicones was found (recipes/materials.toml), so this is
    # the user's, and the range ends there as "stretch".
    max_stretch: float | None = Field(
        None, gt=1.0, le=10.0,
        description="Your own limit on the largest principal stretch in the elastomer under load, which then ends "
                    "the force range (omit: none; the range still ends where the material law's data do).")


class Calibration(_Section):
    """The force calibration (docs/models.md, M12-M14) and the simulated scan a build ships before a real one exists."""

    method: CalibrationMethod = Field(CalibrationMethod.POLY, strict=False,
                                      description="'poly' (order n), 'auto' (cheapest fit within tolerance_mN) or "
                                                  "'mls'.")
    order: int = Field(4, ge=1, le=8, description="Polynomial order n in (Bz, Br); 'auto' may pick a lower one.")
    tolerance_mN: float = Field(5.0, gt=0.0, le=1.0e4,
                                description="Held-out RMS force error the fit must reach, mN (a warning if not).")
    folds: int = Field(5, ge=2, le=20, description="Folds of the k-fold cross-validation behind the held-out errors.")
    scan_y_mm: float = _mm(4.0, "Lateral (y) extent of the simulated scan track, centred on the axis, mm.", le=50.0)
    scan_z_mm: float = _mm(3.0, "Indentation (z) extent of the simulated scan track, mm (capped at the predicted "
                                "range).", le=50.0)
    scan_step_mm: float = _mm(0.05, "Step of the simulated scan in y and z, mm.", le=5.0)
    reference_resolution_mN: float = Field(
        6.25, ge=0.0, le=1.0e4, description="Resolution of the reference force sensor (ATI Nano17: 6.25 mN), mN.")
    seed: int = Field(0, ge=0, le=2**31 - 1, description="Seed of the simulated scan's noise.")


class Transport(str, Enum):
    """Serial output of the firmware at start-up (the host can switch it)."""

    BINARY = "binary"
    TEXT = "text"


class Acquisition(str, Enum):
    """How the firmware drives the chip: 'burst' (the chip converts continuously) or 'single' measurements."""

    BURST = "burst"
    SINGLE = "single"


class Firmware(_Section):
    """The readout firmware for an ATmega328P board (Arduino Uno / Nano, 16 MHz)."""

    baud: int = Field(250000, ge=9600, le=2000000, description="Serial baud rate.")
    output: Transport = Field(Transport.BINARY, strict=False,
                              description="'binary' frames (with CRC) or 'text' lines at start-up.")
    acquisition: Acquisition = Field(Acquisition.BURST, strict=False,
                                     description="'burst' or 'single' measurement mode.")
    i2c_hz: int = Field(400000, ge=10000, le=1000000,
                        description="I2C clock, Hz (the MLX90393 allows up to 400 kHz fast mode).")
    temperature: bool = Field(True, description="Also convert and report the chip temperature.")


class Fabrication(_Section):
    """What the bench needs: how many sensors, silicone quantities, adhesive; recipe overrides."""

    sensors: int = Field(1, ge=1, le=1000, description="Sensors to make: sets the pours and the bill of materials.")
    waste_pct: float = Field(30.0, ge=0.0, le=300.0, description="Extra silicone mixed beyond what the mould holds, % "
                             "(left in the cup and on the stirrer, overflow from the fill and vent holes).")
    adhesive: str = Field("sil-poxy",
                          description="Adhesive for the magnet seal and the pad, a key of recipes/adhesives.toml.")
    release_agent: str = Field("ease-release-200", description="Mould release, a key of recipes/adhesives.toml.")
    pot_life_min: float | None = Field(None, gt=0.0, le=10000.0, description="Override the silicone's pot life, min.")
    cure_time_h: float | None = Field(None, gt=0.0, le=1000.0, description="Override the silicone's cure time, h.")
    density_g_cm3: float | None = Field(None, gt=0.1, le=10.0, description="Override the silicone's density, g/cm^3.")


class Skin(str, Enum):
    """How an array's taxels are cast: 'separate' fingertips on one base, or one 'continuous' skin with N magnets."""

    SEPARATE = "separate"
    CONTINUOUS = "continuous"


class Polarity(str, Enum):
    """Magnetisation of an array's magnets: all 'same' (+z), or 'alternating' (a checkerboard; by index for
    explicit positions)."""

    SAME = "same"
    ALTERNATING = "alternating"


#: Taxels one array may hold: four option codes times four A1/A0 straps give sixteen addresses on one I2C bus.
MAX_TAXELS = 16


class Array(_Section):
    """Several taxels from one spec: every taxel is the fingertip the other sections describe, each over its own
    MLX90393, on one board. Omit the section for a single taxel."""

    rows: int = Field(1, ge=1, le=MAX_TAXELS, description="Rows of the grid (along y).")
    cols: int = Field(1, ge=1, le=MAX_TAXELS, description="Columns of the grid (along x).")
    pitch_mm: float | None = Field(
        None, gt=0.0, le=100.0, description="Centre-to-centre distance of neighbouring taxels in the grid, mm "
        "(required for a grid of more than one taxel).")
    positions_mm: tuple[tuple[float, float], ...] | None = Field(
        None, description="Explicit taxel centres [[x, y], ...] in the board frame, mm, instead of rows, cols and "
        "pitch_mm (taxel index = order in the list).")
    skin: Skin = Field(Skin.SEPARATE, strict=False, description="'separate' fingertips or one 'continuous' skin.")
    polarity: Polarity = Field(Polarity.SAME, strict=False, description="'same' or 'alternating' magnetisation.")
    buses: int = Field(1, ge=1, le=2, description="I2C buses the chips are split over: 1, or 2 (an RP2040 board's two "
                       "controllers: odd taxels on the second bus, its own connector J2; the taxels then come twice as "
                       "often).")
    crosstalk_mN: float | None = Field(
        None, gt=0.0, le=1.0e4, description="Largest force error at a taxel that its neighbours moving through "
        "their range may cause, mN; omit: the taxel's normal force resolution.")

    @field_validator("positions_mm", mode="before")
    @classmethod
    def _pairs(cls, v: Any) -> Any:
        """TOML gives arrays as lists; strict mode takes only tuples."""
        if v is None:
            return v
        if not isinstance(v, list) or not v or not all(
                isinstance(p, list) and len(p) == 2
                and all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) and abs(x) <= 500
                        for x in p) for p in v):
            raise ValueError(f"must be an array of 1 to {MAX_TAXELS} [x, y] pairs of numbers within +-500 mm")
        if len(v) > MAX_TAXELS:
            raise ValueError(f"must hold at most {MAX_TAXELS} taxels (four option codes x four A1/A0 straps on one "
                             "I2C bus)")
        return tuple((float(x), float(y)) for x, y in v)

    @model_validator(mode="after")
    def _grid(self) -> Array:
        if self.positions_mm is not None:
            if self.rows != 1 or self.cols != 1 or self.pitch_mm is not None:
                raise ValueError("give either positions_mm or rows, cols and pitch_mm, not both")
        elif self.rows * self.cols > MAX_TAXELS:
            raise ValueError(f"rows x cols = {self.rows * self.cols} taxels: at most {MAX_TAXELS} (four option codes "
                             "x four A1/A0 straps on one I2C bus)")
        elif self.rows * self.cols > 1 and self.pitch_mm is None:
            raise ValueError("pitch_mm is required for a grid of more than one taxel")
        if self.buses == 2 and self.taxels < 2:
            raise ValueError("buses = 2 splits the taxels over two I2C buses: it needs at least two taxels")
        return self

    @property
    def taxels(self) -> int:
        return len(self.positions_mm) if self.positions_mm is not None else self.rows * self.cols


class Build(_Section):
    """Build options."""

    step: bool = Field(True, description="Also write STEP files (exact solids) next to the STLs.")
    strict: bool = Field(False, description="Treat warning-level findings as errors.")


class Spec(_Section):
    """A whole design: what ``magfab build`` turns into files. Frozen; make variants with ``model_copy(update=...)``."""

    name: str = Field("magone", pattern=NAME_PATTERN,
                      description="Design name: letters, digits, '.', '_', '-'; names the output folder.")
    magnet: Magnet = Field(default_factory=Magnet)
    elastomer: Elastomer = Field(default_factory=Elastomer)
    sensor: Sensor = Field(default_factory=Sensor)
    pad: Pad = Field(default_factory=Pad)
    pcb: Pcb = Field(default_factory=Pcb)
    mould: Mould = Field(default_factory=Mould)
    predict: Predict = Field(default_factory=Predict)
    calibration: Calibration = Field(default_factory=Calibration)
    firmware: Firmware = Field(default_factory=Firmware)
    fabrication: Fabrication = Field(default_factory=Fabrication)
    build: Build = Field(default_factory=Build)
    array: Array | None = Field(None, description="Several taxels on one board (omit for one).")
    board: Board | None = Field(None, description="The readout board (omit: an Arduino Uno).")
    environment: Environment | None = Field(
        None, description="Where the sensor is used, for the drift prediction (omit: a lab bench).")
    reference: Reference | None = Field(
        None, description="A reference chip for stray-field rejection (omit for none).")

    def dump(self) -> dict[str, Any]:
        """Every key, defaults included, as JSON values (spec.json); a single taxel has no ``array`` key, an array on
        one bus no ``array.buses`` and a spec without ``[environment]`` none either, so its spec, hash and build are
        what they were before those existed."""
        exclude: dict[str, Any] = {name: True for name in ("array", "board", "environment", "reference")
                                   if getattr(self, name) is None}
        if self.array is not None and self.array.buses == 1:  # one bus: the array's spec and hash as before buses
            exclude["array"] = {"buses"}
        return self.model_dump(mode="json", exclude=exclude or None)

    def canonical_json(self) -> str:
        """Every key, defaults included, as sorted JSON: the basis of the spec hash."""
        return json.dumps(self.dump(), sort_keys=True, separators=(",", ":"))

    def sha256(self) -> str:
        return hashlib.sha256(self.canonical_json().encode()).hexdigest()

    def toml_dict(self) -> dict[str, Any]:
        """Every key as a TOML spec file holds it (an omitted optional key stays omitted), as spec_from_dict reads."""
        raw = _without_nulls(self.dump())
        for section, key in _STATED_ONLY:  # their absence means something: kept out unless stated
            if key not in getattr(self, section).model_fields_set:
                raw[section].pop(key, None)
        return raw


#: Keys whose absence from a spec means something other than their default (the board sized to fit, an array's
#: cavities one per taxel): :meth:`Spec.toml_dict` holds them only where the spec states them.
_STATED_ONLY = (("pcb", "width_mm"), ("pcb", "height_mm"), ("mould", "cavities"))

_CATALOGUE_KEYS = {
    ("magnet", "grade"): "magnets",
    ("elastomer", "material"): "materials",
    ("sensor", "chip"): "chips",
    ("fabrication", "adhesive"): "adhesives",
    ("fabrication", "release_agent"): "adhesives",
}


def default_spec_text() -> str:
    """The embedded MagOne spec, with its comments."""
    return resources.files("magfab.examples").joinpath("magone.toml").read_text(encoding="utf-8")


def load_spec(path: str | Path | None = None) -> Spec:
    """Read and validate a spec file; ``None`` gives the embedded MagOne reference design."""
    if path is None:
        return parse_spec(default_spec_text(), default_name="magone")
    path = Path(path)
    text = read_toml(path, "spec")
    return parse_spec(text, default_name=path.stem, where=str(path))


def parse_spec(text: str, default_name: str = "magone", where: str = "<TOML>") -> Spec:
    """Validate TOML text (``where`` names it: its path). A missing ``name`` is taken from ``default_name`` (the
    file's stem)."""
    try:
        raw = loads_toml(text, "spec", where)
    except bounded.InputFileError:
        raise
    except tomllib.TOMLDecodeError as exc:
        raise SpecError("spec", "<TOML>", f"not valid TOML: {exc}") from None
    except ValueError as exc:  # e.g. an integer of more than 4300 digits (Python's int-from-string limit)
        raise SpecError("spec", "<TOML>", f"not valid TOML: {shorten(str(exc), 200)}") from None
    if "name" not in raw:
        raw["name"] = default_name
        if not is_valid_name(default_name):
            raise SpecError("name", shown(default_name), "taken from the file name, must match " + NAME_PATTERN,
                            hint="add name = \"...\" to the spec")
    return _validated(raw)


def load_build_spec(folder: str | Path) -> Spec:
    """The spec a build was made from: its ``spec.json`` (every default filled in), validated like a TOML
    spec. :class:`SpecError` when the folder has none or it does not validate."""
    path = Path(folder) / "spec.json"
    try:
        raw = bounded.loads_json(bounded.read_bytes(path, "spec.json"), "spec.json", path)
    except bounded.InputFileError:
        raise
    except FileNotFoundError:
        raise SpecError("spec", str(path), "file not found: not a magfab build folder") from None
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise SpecError("spec", str(path), f"cannot read it as JSON: {shorten(str(exc), 200)}") from None
    return spec_from_json(raw, str(path))


def spec_from_json(raw: object, where: str = "spec.json") -> Spec:
    """A spec as a build's (or a sensor record's) ``spec.json`` holds it, parsed: every default filled in, nulls for
    omitted keys; validated like a TOML spec. ``where`` names it in the :class:`SpecError`."""
    if not isinstance(raw, dict):
        raise SpecError("spec", where, "must hold a JSON object (the build's spec)")
    return _validated(_without_nulls(raw))


def spec_from_dict(raw: dict[str, Any]) -> Spec:
    """Validate a spec given as a dict (parsed TOML, or :meth:`Spec.toml_dict` changed); SpecError as for a file."""
    return _validated(raw)


def _without_nulls(raw: dict[str, Any]) -> dict[str, Any]:
    """spec.json writes an omitted optional key as null; TOML has no null, so the spec omits it again."""
    return {k: _without_nulls(v) if isinstance(v, dict) else v for k, v in raw.items() if v is not None}


def _validated(raw: dict[str, Any]) -> Spec:
    try:
        spec = Spec.model_validate(raw)
    except ValidationError as exc:
        raise translate_error(exc, raw, Spec) from None
    for (section, key), kind in _CATALOGUE_KEYS.items():
        value = getattr(getattr(spec, section), key)
        known = sorted(catalogue(kind))
        if value not in known:
            raise SpecError(f"{section}.{key}", shown(value), "must be one of " + ", ".join(known),
                            did_you_mean(value, known))
    return spec


def spec_schema() -> dict[str, Any]:
    """JSON Schema of the spec, generated from the models (what ``spec.schema.json`` holds)."""
    schema = Spec.model_json_schema()
    schema.update({"$schema": "https://json-schema.org/draft/2020-12/schema", "title": "magfab design spec"})
    return schema
