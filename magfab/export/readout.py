"""The host readout package of a build: ``magfab_readout``, pip-installable.

The package is one source tree, ``magfab/readout/`` (its pyproject.toml, the README's template and
``src/magfab_readout/``, the format validators included), which every build copies verbatim into ``readout/``;
only data is generated: ``build.json`` (spec name, baud rate, chip register fields, microtesla per count, the
calibration's hash, the shipped image's measured rate), calibration.json, acceptance.json, for an array array.json
and each taxel's calibration, and README.md from the tree's README.md.j2. The package decodes the firmware's frames
(docs/bundle.md), evaluates the calibration in Python, and has a ``magfab-readout`` command with a simulated device.

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
from collections.abc import Callable, Mapping
from importlib import resources
from typing import Any

from .. import __version__
from ..design import Design
from ..errors import SpecError
from ..formats import acceptance_json, calibration_json
from ..formats.json_checks import FormatError

# TEMPERATURE_*, re-exported: MLX90393 temperature (TCMP off), T = 25 C + (raw - T25) / TRES, from recipes/chips.toml.
from . import checklist_rp2040 as rp2040_words
from . import rp2040
from .firmware import TEMPERATURE_LSB_PER_C, TEMPERATURE_RAW_25C, chip_config, image_settings, measured_rate_for
from .templating import environment

__all__ = ["PACKAGE", "SOURCE", "TEMPLATE_SUFFIX", "TREE_FILES", "render", "source_files", "data_files",
           "calibration_sha256", "validate_calibration", "validate_acceptance", "TEMPERATURE_RAW_25C",
           "TEMPERATURE_LSB_PER_C"]

PACKAGE = "magfab_readout"
#: The package's source tree: this folder of magfab (shipped in magfab's wheel), copied verbatim into readout/.
SOURCE = "readout"
#: A file of the tree ending in it is a jinja2 template of the build's file without it (README.md.j2 -> README.md).
TEMPLATE_SUFFIX = ".j2"
#: The tree's files beside ``src/magfab_readout/*.py`` (pyproject.toml's package-data of magfab.readout lists both).
TREE_FILES = ("pyproject.toml", "README.md.j2")
#: The package's own files: its modules, and the page ``magfab-readout view`` serves (view.html).
MODULE_SUFFIXES = (".py", ".html")


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


def _build_data(design, checked: calibration_json.Checked) -> dict[str, object]:
    """build.json: what the package's ``_build`` module reads (the spec, the firmware's settings, the hash)."""
    spec = design.spec
    chip = chip_config(design)  # the firmware's own: its rate is one frame per conversion (the datasheet's table)
    limit = design.chip[f"output_limit_res{spec.sensor.resolution}_lsb"].nominal
    numbers = {"lsb_xy_uT": chip.lsb_xy_uT, "lsb_z_uT": chip.lsb_z_uT, "sample_rate_Hz": chip.sample_rate_Hz}
    for key, value in numbers.items():
        if not (math.isfinite(value) and value > 0):
            raise SpecError("sensor", value, f"gives a {key} that is not a positive number")
    return {
        "spec_name": spec.name,
        "spec_sha256": spec.sha256(),
        "magfab_version": __version__,
        "version": f"{__version__}+cal.{checked.sha256[:12]}",
        "baud": int(spec.firmware.baud),
        "output": spec.firmware.output.value,
        "temperature": bool(spec.firmware.temperature),
        "gain_sel": int(chip.gain_sel),
        "resolution": int(chip.resolution),
        "osr": int(chip.osr),
        "dig_filt": int(chip.dig_filt),
        "lsb_xy_uT": float(chip.lsb_xy_uT),
        "lsb_z_uT": float(chip.lsb_z_uT),
        "full_scale_counts": round(float(limit)),
        "sample_rate_Hz": round(float(chip.sample_rate_Hz), 6),
        "temperature_raw_25C": TEMPERATURE_RAW_25C,
        "temperature_lsb_per_C": TEMPERATURE_LSB_PER_C,
        "calibration_sha256": checked.sha256,
        "image_settings": image_settings(design),
        # what the shipped image delivered on the simulated bus timed like a real one, as predictions.json says it,
        # where it was measured with this build's settings (a single taxel's: an array's rate is docs/bundle.md
        # section 3's table)
        "readout_measured": measured_rate_for(design, {"method": checked.method, "order": checked.order}),
    }


def _context(build: Mapping[str, object], acceptance: Mapping[str, Any] | None, design: Design) -> dict[str, object]:
    """What the tree's templates (README.md.j2) are rendered with: build.json's values, the acceptance bands, and how
    the board is flashed (an RP2040 board's .uf2 is copied onto its drive, an Arduino's .hex written by avrdude)."""
    uf2 = rp2040.is_rp2040(design.spec)
    return {
        **build,
        "flash_command": rp2040_words.flash_commands(design)[0] if uf2 else "sh firmware/flash.sh uno /dev/ttyACM0",
        "flash_step": (f"Copy the firmware onto the {rp2040.short_name(rp2040.readout_board(design.spec))}'s "
                       "RPI-RP2 drive (hold BOOTSEL while you plug it in; `firmware/README.md`)." if uf2 else
                       "Flash the firmware (a Nano: `nano` or `nano-old` instead of `uno`; Windows: "
                       "`firmware/README.md`)."),
        "record_step": ("Write this build's calibration into the board's flash (the .uf2 holds it already: this "
                        "rewrites the same bytes)." if uf2 else
                        "Write this build's calibration into the board's EEPROM (the bootloader leaves the EEPROM "
                        "empty)."),
        "description": f"Host readout for the magfab tactile sensor {build['spec_name']}",
        "acceptance": None if acceptance is None else {
            "rest_lo": f"{acceptance['rest']['Bz_uT']['min']:.0f}",
            "rest_hi": f"{acceptance['rest']['Bz_uT']['max']:.0f}",
            "rest_nominal": f"{acceptance['rest']['Bz_uT']['nominal']:.0f}",
            "weight": f"{acceptance['weight']['weight_g']:g}",
            "delta_lo": f"{acceptance['weight']['delta_Bz_uT']['min']:.0f}",
            "delta_hi": f"{acceptance['weight']['delta_Bz_uT']['max']:.0f}",
            "drift_flags": acceptance_json.drift_flags(acceptance),
        },
    }


def source_files() -> dict[str, bytes]:
    """The package's source tree as every build ships it, ``{path relative to the tree: bytes}``, sorted: its
    top-level :data:`TREE_FILES` and every module and page of ``src/magfab_readout/`` (what magfab's wheel ships of the
    folder; a tool's cache or a local build beside them is not the package)."""
    root = resources.files("magfab").joinpath(SOURCE)
    out = {name: root.joinpath(name).read_bytes() for name in TREE_FILES}
    modules = root.joinpath("src", PACKAGE)
    out.update({f"src/{PACKAGE}/{entry.name}": entry.read_bytes() for entry in modules.iterdir()
                if entry.name.endswith(MODULE_SUFFIXES) and entry.is_file()})
    return dict(sorted(out.items()))


def _json_file(data: object) -> bytes:
    # the layout of the bundle's own calibration/calibration.json, so the two files are byte for byte the same
    return (json.dumps(data, indent=1, sort_keys=True, allow_nan=False) + "\n").encode("ascii")


def render(design, calibration: Mapping[str, Any], acceptance: Mapping[str, Any] | None = None,
           array: Mapping[str, Any] | None = None, taxel_calibrations: tuple = (),
           crosstalk: Mapping[str, Any] | None = None, *, weigh_plan: Mapping[str, Any] | None = None
           ) -> dict[str, bytes]:
    """Every file of the readout package: ``{"readout/<relative path>": bytes}``, sorted, deterministic.

    ``design`` is a :class:`~magfab.design.Design` (from :func:`magfab.derive`); ``calibration`` is the parsed
    calibration.json (docs/bundle.md), which the package embeds (sorted keys, one-space indent); ``acceptance``
    is :func:`magfab.models.acceptance.acceptance`'s result, embedded as acceptance.json for the ``check`` command
    (None: the package has no acceptance data and ``check`` says so). For an array, ``array`` is
    calibration/array.json and ``taxel_calibrations`` every taxel's calibration.json, embedded under the names
    array.json gives them (``calibration`` is then taxel 0's), and ``crosstalk`` array/crosstalk.json, the budget
    the array's ``check`` judges the neighbours against. Raises :class:`SpecError` for a
    calibration the readout cannot evaluate or malformed acceptance data, TypeError for a ``design`` of the
    wrong type.
    """
    if not isinstance(design, Design):
        raise TypeError("design must be a magfab Design (from magfab.derive); instead received "
                        f"{type(design).__name__}")
    checked = validate_calibration(calibration)
    accepted = None if acceptance is None else validate_acceptance(acceptance)
    build = _build_data(design, checked)
    files = {f"readout/{path}": data for path, data in source_files().items()}
    context = _context(build, accepted, design)
    context["weigh_steps"] = len(weigh_plan["steps"]) if weigh_plan is not None else 0
    context["weigh_reskin"] = len(weigh_plan["reskin"]) if weigh_plan is not None else 0
    for path in [p for p in files if p.endswith(TEMPLATE_SUFFIX)]:  # the build's README.md in its template's place
        text = environment().from_string(files.pop(path).decode("utf-8")).render(**context)
        files[path[:-len(TEMPLATE_SUFFIX)]] = text.encode("utf-8")
    files.update(data_files(build, checked, accepted, array, taxel_calibrations, crosstalk))
    if weigh_plan is not None:  # magfab-readout weigh's steps (export/weigh_plan.py)
        files[f"readout/src/{PACKAGE}/weigh_plan.json"] = _json_file(weigh_plan)
    return dict(sorted(files.items()))


def data_files(build: Mapping[str, object], checked: calibration_json.Checked, accepted: Mapping[str, Any] | None,
               array: Mapping[str, Any] | None, taxel_calibrations: tuple,
               crosstalk: Mapping[str, Any] | None = None) -> dict[str, bytes]:
    """The build's data files beside the package's modules, ``{"readout/src/magfab_readout/<name>": bytes}``:
    build.json, calibration.json, acceptance.json (when given), and for an array array.json, every taxel's
    calibration under the names array.json gives them, and crosstalk.json (when given: the array's check)."""
    package = f"readout/src/{PACKAGE}"
    files = {f"{package}/build.json": _json_file(build),
             f"{package}/calibration.json": _json_file(json.loads(checked.canonical))}
    if accepted is not None:
        files[f"{package}/acceptance.json"] = _json_file(accepted)
    if array is not None:  # the compensation of docs/bundle.md section 5 (the package's array_json.py)
        files[f"{package}/array.json"] = _json_file(array)
        for taxel, cal in zip(array["taxels"], taxel_calibrations, strict=True):
            files[f"{package}/{taxel['calibration']}"] = _json_file(json.loads(validate_calibration(cal).canonical))
        if crosstalk is not None:
            files[f"{package}/crosstalk.json"] = _json_file(json.loads(json.dumps(dict(crosstalk), default=_plain)))
    return files
