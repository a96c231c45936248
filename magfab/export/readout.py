"""The host readout package of a build: ``magfab_readout``, pip-installable, rendered from ``templates/readout/``.

The package embeds the build's calibration.json and the firmware's settings (spec name, baud rate, chip
register fields, microtesla per count); it decodes the firmware's frames (docs/bundle.md), evaluates the
calibration in Python, and has a ``magfab-readout`` command with a simulated device.

The calibration is validated by the package's own ``calibration`` module, rendered and run here, so the
build and the host refuse exactly the same files; its errors come out as :class:`~magfab.errors.SpecError`
with the key path inside calibration.json.

With the acceptance bands (:func:`magfab.models.acceptance.acceptance`) the package also carries ``acceptance.json``
next to calibration.json, which its ``magfab-readout check`` command (the acceptance test) compares a sensor
with; without them the command says the package was built without it.
"""

from __future__ import annotations

import json
import math
import types
from functools import lru_cache
from typing import Any, Mapping

from .. import __version__
from ..errors import SpecError
from .templating import render as render_template
from .templating import templates_dir

__all__ = ["PACKAGE", "TEMPLATES", "render", "calibration_sha256", "validate_calibration", "validate_acceptance",
           "TEMPERATURE_RAW_25C", "TEMPERATURE_LSB_PER_C"]

PACKAGE = "magfab_readout"
TEMPLATES = "readout"  # folder under templates/; every file in it ends in .j2 and renders to readout/<path>
# MLX90393 temperature (TCMP off): T = 25 C + (raw - T25) / TRES, from recipes/chips.toml.
from .firmware import TEMPERATURE_LSB_PER_C, TEMPERATURE_RAW_25C  # noqa: E402 - from recipes/chips.toml


@lru_cache(maxsize=1)
def _calibration_module() -> types.ModuleType:
    """The package's calibration module (standard library only), rendered and loaded under a private name."""
    name = f"{TEMPLATES}/src/{PACKAGE}/calibration.py.j2"
    source = render_template(name)
    module = types.ModuleType("_magfab_readout_calibration")
    module.__file__ = str(templates_dir() / name)
    exec(compile(source, module.__file__, "exec"), module.__dict__)  # our own template, no spec values in it
    return module


def _plain(value: object) -> object:
    """numpy scalars and arrays as Python numbers and lists (what calibration.json holds)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not a JSON value")


def validate_calibration(calibration: Mapping[str, Any]):
    """The calibration as the package's ``Calibration`` object; :class:`SpecError` naming the key path in
    calibration.json when the readout could not evaluate it."""
    module = _calibration_module()
    if not isinstance(calibration, Mapping):
        raise SpecError("calibration.json", type(calibration).__name__, "must be a JSON object (a dict)")
    try:
        plain = json.loads(json.dumps(dict(calibration), allow_nan=True, default=_plain))
        return module.Calibration(plain)
    except module.CalibrationError as exc:
        raise SpecError(f"calibration.json:{exc.key or '(top level)'}", exc.value, exc.allowed) from None
    except (TypeError, ValueError) as exc:  # not JSON-serialisable, NaN somewhere outside the checked keys
        raise SpecError("calibration.json", "(contents)", f"must be plain JSON with finite numbers ({exc})") from None


#: What the package's ``check`` command reads from acceptance.json: (key path, kind). "number" is a finite
#: number, "numbers" a non-empty list of them, "text" a string.
ACCEPTANCE_KEYS = (
    ("rest.Bz_uT.min", "number"), ("rest.Bz_uT.nominal", "number"), ("rest.Bz_uT.max", "number"),
    ("rest.Bxy_max_uT", "number"), ("rest.earth_field_uT", "number"),
    ("weight.weight_g", "number"), ("weight.max_weight_g", "number"),
    ("weight.table.force_N", "numbers"), ("weight.table.delta_Bz_min_uT", "numbers"),
    ("weight.table.delta_Bz_nominal_uT", "numbers"), ("weight.table.delta_Bz_max_uT", "numbers"),
    ("measurement.noise_z_uT", "number"), ("measurement.noise_xy_uT", "number"),
    ("measurement.allowance_sigmas", "number"), ("magnet.grade", "text"),
    ("magnet.remanence_T.low", "number"), ("magnet.remanence_T.nominal", "number"),
    ("magnet.remanence_T.high", "number"),
)


def _finite_number(x: object) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def validate_acceptance(acceptance: Mapping[str, Any]) -> dict:
    """The acceptance bands as plain JSON data (what acceptance.json will hold), checked for the format and the
    keys the package's ``check`` reads; :class:`SpecError` naming the key path inside acceptance.json."""
    from ..models.acceptance import FORMAT

    if not isinstance(acceptance, Mapping):
        raise SpecError("acceptance.json", type(acceptance).__name__, "must be a JSON object (a dict)")
    try:
        data = json.loads(json.dumps(dict(acceptance), allow_nan=False, default=_plain))
    except (TypeError, ValueError) as exc:
        raise SpecError("acceptance.json", "(contents)", f"must be plain JSON with finite numbers ({exc})") from None
    if data.get("format") != FORMAT:
        raise SpecError("acceptance.json:format", data.get("format"), f"must be {FORMAT!r}")
    for path, kind in ACCEPTANCE_KEYS:
        node: object = data
        for part in path.split("."):
            node = node.get(part) if isinstance(node, dict) else None
        ok = {"number": _finite_number(node), "text": isinstance(node, str),
              "numbers": isinstance(node, list) and bool(node) and all(_finite_number(x) for x in node)}[kind]
        if not ok:
            what = {"number": "a finite number", "text": "a string", "numbers": "a non-empty list of finite numbers"}
            raise SpecError(f"acceptance.json:{path}", node, f"must be {what[kind]}")
    table = data["weight"]["table"]
    force = table["force_N"]
    if any(len(table[k]) != len(force) for k in ("delta_Bz_min_uT", "delta_Bz_nominal_uT", "delta_Bz_max_uT")):
        raise SpecError("acceptance.json:weight.table", "(lengths)", "every column must be as long as force_N")
    if any(b <= a for a, b in zip(force, force[1:])):
        raise SpecError("acceptance.json:weight.table.force_N", force[:5], "must be increasing")
    rest = data["rest"]["Bz_uT"]
    if not rest["min"] <= rest["nominal"] <= rest["max"]:
        raise SpecError("acceptance.json:rest.Bz_uT", rest, "must have min <= nominal <= max")
    return data


def calibration_sha256(calibration: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of the calibration's canonical JSON (sorted keys, no spaces, ASCII, finite numbers).

    The firmware's info line carries its first 16 hex digits; the readout package compares them with its own.
    """
    return validate_calibration(calibration).sha256


def _context(design, calibration_object, acceptance: Mapping[str, Any] | None = None) -> dict[str, object]:
    from ..models.predict import chip_setting  # numpy; kept out of 'import magfab'

    spec = design.spec
    chip = chip_setting(design)
    limit = design.chip[f"output_limit_res{spec.sensor.resolution}_lsb"].nominal
    numbers = {"lsb_xy_uT": chip.lsb_xy_uT, "lsb_z_uT": chip.lsb_z_uT, "sample_rate_Hz": chip.rate_Hz}
    for key, value in numbers.items():
        if not (math.isfinite(value) and value > 0):
            raise SpecError("sensor", value, f"gives a {key} that is not a positive number")
    sha = calibration_object.sha256
    return {
        "spec_name": spec.name,
        "spec_sha256": spec.sha256(),
        "magfab_version": __version__,
        "version": f"{__version__}+cal.{sha[:12]}",
        "description": f"Host readout for the magfab tactile sensor {spec.name}",
        "baud": int(spec.firmware.baud),
        "output": spec.firmware.output.value,
        "temperature": bool(spec.firmware.temperature),
        "gain_sel": int(chip.gain_sel),
        "resolution": int(chip.resolution),
        "osr": int(chip.osr),
        "dig_filt": int(chip.dig_filt),
        "lsb_xy_uT": float(chip.lsb_xy_uT),
        "lsb_z_uT": float(chip.lsb_z_uT),
        "full_scale_counts": int(round(limit)),
        "sample_rate_Hz": round(float(chip.rate_Hz), 6),
        "temperature_raw_25C": TEMPERATURE_RAW_25C,
        "temperature_lsb_per_C": TEMPERATURE_LSB_PER_C,
        "calibration_sha256": sha,
        "acceptance": None if acceptance is None else {
            "rest_lo": f"{acceptance['rest']['Bz_uT']['min']:.0f}", "rest_hi": f"{acceptance['rest']['Bz_uT']['max']:.0f}",
            "rest_nominal": f"{acceptance['rest']['Bz_uT']['nominal']:.0f}",
            "weight": f"{acceptance['weight']['weight_g']:g}",
            "delta_lo": f"{acceptance['weight']['delta_Bz_uT']['min']:.0f}",
            "delta_hi": f"{acceptance['weight']['delta_Bz_uT']['max']:.0f}",
        },
    }


def render(design, calibration: Mapping[str, Any], acceptance: Mapping[str, Any] | None = None) -> dict[str, bytes]:
    """Every file of the readout package: ``{"readout/<relative path>": bytes}``, sorted, deterministic.

    ``design`` is a :class:`~magfab.design.Design` (from :func:`magfab.derive`); ``calibration`` is the parsed
    calibration.json (docs/bundle.md), which the package embeds (sorted keys, one-space indent); ``acceptance``
    is :func:`magfab.models.acceptance.acceptance`'s result, embedded as acceptance.json for the ``check`` command
    (None: the package has no acceptance data and ``check`` says so). Raises :class:`SpecError` for a
    calibration the readout cannot evaluate or malformed acceptance data, TypeError for a ``design`` of the
    wrong type.
    """
    from ..design import Design

    if not isinstance(design, Design):
        raise TypeError(f"design must be a magfab Design (from magfab.derive); instead received {type(design).__name__}")
    calibration_object = validate_calibration(calibration)
    accepted = None if acceptance is None else validate_acceptance(acceptance)
    context = _context(design, calibration_object, accepted)
    root = templates_dir() / TEMPLATES
    files: dict[str, bytes] = {}
    for path in sorted(root.rglob("*.j2")):
        relative = path.relative_to(root).as_posix()
        text = render_template(f"{TEMPLATES}/{relative}", **context)
        files[f"readout/{relative[:-len('.j2')]}"] = text.encode("utf-8")
    data = calibration_object.to_dict()
    # the layout of the bundle's own calibration/calibration.json, so the two files are byte for byte the same
    files[f"readout/src/{PACKAGE}/calibration.json"] = (json.dumps(data, indent=1, sort_keys=True, allow_nan=False)
                                                       + "\n").encode("ascii")
    if accepted is not None:
        files[f"readout/src/{PACKAGE}/acceptance.json"] = (json.dumps(accepted, indent=1, sort_keys=True,
                                                                      allow_nan=False) + "\n").encode("utf-8")
    return dict(sorted(files.items()))
