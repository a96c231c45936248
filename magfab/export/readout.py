"""The host readout package of a build: ``magfab_readout``, pip-installable, rendered from ``templates/readout/``.

The package embeds the build's calibration.json and the firmware's settings (spec name, baud rate, chip
register fields, microtesla per count); it decodes the firmware's frames (docs/bundle.md), evaluates the
calibration in Python, and has a ``magfab-readout`` command with a simulated device.

calibration.json and acceptance.json are checked by :mod:`magfab.formats.calibration_json` and
:mod:`magfab.formats.acceptance_json`, the validators the package itself runs, so the build and the host refuse
exactly the same files; the errors come out as :class:`~magfab.errors.SpecError` keyed by file and key path.

With the acceptance bands (:func:`magfab.models.acceptance.acceptance`) the package also carries ``acceptance.json``
next to calibration.json, which its ``magfab-readout check`` command (the acceptance test) compares a sensor
with; without them the command says the package was built without it.
"""

from __future__ import annotations

import json
import math
from typing import Any, Callable, Mapping

from .. import __version__
from ..errors import SpecError
from ..formats import acceptance_json, calibration_json
from ..formats.json_checks import FormatError
from .templating import render as render_template
from .templating import templates_dir

__all__ = ["PACKAGE", "TEMPLATES", "render", "calibration_sha256", "validate_calibration", "validate_acceptance",
           "TEMPERATURE_RAW_25C", "TEMPERATURE_LSB_PER_C"]

PACKAGE = "magfab_readout"
TEMPLATES = "readout"  # folder under templates/; every file in it ends in .j2 and renders to readout/<path>
# MLX90393 temperature (TCMP off): T = 25 C + (raw - T25) / TRES, from recipes/chips.toml.
from .firmware import TEMPERATURE_LSB_PER_C, TEMPERATURE_RAW_25C  # noqa: E402 - from recipes/chips.toml


def _plain(value: object) -> object:
    """numpy scalars and arrays as Python numbers and lists (what the JSON files hold)."""
    if hasattr(value, "tolist"):
        return value.tolist()
    raise TypeError(f"{type(value).__name__} is not a JSON value")


def _as_plain_json(data: Mapping[str, Any], error: type[FormatError]) -> object:
    try:
        return json.loads(json.dumps(dict(data), allow_nan=True, default=_plain))
    except TypeError as exc:  # not JSON-serialisable
        raise error("", "(contents)", f"must be plain JSON ({exc})") from None


def _validated(data: Mapping[str, Any], validate: Callable[[object], Any], error: type[FormatError]) -> Any:
    """``validate`` (a magfab.formats validator) of ``data`` made plain JSON; the readout API's error for a
    bad file is a :class:`SpecError` keyed ``<file>:<key path>``."""
    if not isinstance(data, Mapping):
        raise SpecError(error.file, type(data).__name__, "must be a JSON object (a dict)")
    try:
        return validate(_as_plain_json(data, error))
    except error as exc:
        raise SpecError(f"{exc.file}:{exc.key}" if exc.key else exc.file, exc.value, exc.allowed) from None


def validate_calibration(calibration: Mapping[str, Any]) -> calibration_json.Checked:
    """The calibration's values (:func:`magfab.formats.calibration_json.validate`, the check the readout package
    itself runs); :class:`SpecError` naming the key path in calibration.json when the readout could not
    evaluate it."""
    return _validated(calibration, calibration_json.validate, calibration_json.CalibrationError)


def validate_acceptance(acceptance: Mapping[str, Any]) -> dict:
    """The acceptance bands as plain JSON data (what acceptance.json will hold), checked by
    :func:`magfab.formats.acceptance_json.validate` (the check the package's ``check`` command runs);
    :class:`SpecError` naming the key path inside acceptance.json."""
    return _validated(acceptance, acceptance_json.validate, acceptance_json.AcceptanceError)


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
    data = json.loads(calibration_object.canonical)
    # the layout of the bundle's own calibration/calibration.json, so the two files are byte for byte the same
    files[f"readout/src/{PACKAGE}/calibration.json"] = (json.dumps(data, indent=1, sort_keys=True, allow_nan=False)
                                                       + "\n").encode("ascii")
    if accepted is not None:
        files[f"readout/src/{PACKAGE}/acceptance.json"] = (json.dumps(accepted, indent=1, sort_keys=True,
                                                                      allow_nan=False) + "\n").encode("utf-8")
    return dict(sorted(files.items()))
