"""acceptance.json (format ``magfab-acceptance/1``): the one validator.

magfab writes the file from :func:`magfab.models.acceptance.acceptance` and checks it before shipping it in
the readout package; the package's ``check`` command reads it through the same :func:`validate`. Standard
library only: a module of the readout package (shipped verbatim in every build), which magfab imports as
:mod:`magfab.formats.acceptance_json`.
"""

from __future__ import annotations

import json

from . import bounded
from .json_checks import FormatError, is_finite

__all__ = ["FORMAT", "KEYS", "SECTIONS", "AcceptanceError", "drift_flags", "loads", "validate"]

FORMAT = "magfab-acceptance/1"

#: What the ``check`` command reads: (key path, kind). "number" is a finite number, "numbers" a non-empty list
#: of them, "text" a string.
KEYS = (
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
#: The drift steps' sections (turning the sensor over, warming it), each optional (a file written before them has
#: none; ``check`` then leaves the step out), but whole when present. "optional" is a finite number or null.
SECTIONS = {
    "rotation": (("rotation.band_uT", "number"), ("rotation.earth_change_uT", "number"),
                 ("rotation.self_weight_change_uT", "number"), ("rotation.gradient_uT_per_mm", "number"),
                 ("rotation.self_weight_mN", "number"), ("rotation.predicted_normal_rest_mN", "optional")),
    "warmup": (("warmup.min_change_C", "number"), ("warmup.per_C_mN.without", "number"),
               ("warmup.per_C_mN.with", "number"), ("warmup.per_C_mN.fitted", "number"),
               ("warmup.noise_mN", "number"), ("warmup.magnet_pct_per_C", "number"),
               ("warmup.channel_mN_per_uT", "number")),
}
_WHAT = {"number": "must be a finite number", "text": "must be a string",
         "numbers": "must be a non-empty list of finite numbers", "optional": "must be a finite number or null"}


def drift_flags(data) -> str:
    """The check's options for the drift steps this acceptance data has (" --rotation --warmup", or less)."""
    return "".join(f" --{name}" for name in SECTIONS if data.get(name))


class AcceptanceError(FormatError):
    """An acceptance.json that does not hold what format magfab-acceptance/1 requires."""

    file = "acceptance.json"


def _finite_number(x: object) -> bool:
    return is_finite(x)


def _kind_ok(node: object, kind: str) -> bool:
    if kind == "number":
        return _finite_number(node)
    if kind == "text":
        return isinstance(node, str)
    if kind == "optional":
        return node is None or _finite_number(node)
    return isinstance(node, list) and bool(node) and all(_finite_number(x) for x in node)


def validate(data: object) -> dict:
    """``data`` (the parsed file: plain JSON values) itself once it holds the format and every key ``check``
    reads (and the keys of each of :data:`SECTIONS` present), with the band table's columns as long as
    ``force_N`` and increasing; :class:`AcceptanceError`
    naming the first bad key path otherwise."""
    if not isinstance(data, dict):
        raise AcceptanceError("", type(data).__name__, "must be a JSON object (a dict)")
    try:
        json.dumps(data, allow_nan=False)
    except (TypeError, ValueError) as exc:
        raise AcceptanceError("", "(contents)", f"must be plain JSON with finite numbers ({exc})") from None
    if data.get("format") != FORMAT:
        raise AcceptanceError("format", data.get("format"), f"must be {FORMAT!r}")
    keys = KEYS + tuple(k for name, section in SECTIONS.items() if name in data for k in section)
    for path, kind in keys:
        node: object = data
        for part in path.split("."):
            node = node.get(part) if isinstance(node, dict) else None
        if not _kind_ok(node, kind):
            raise AcceptanceError(path, node, _WHAT[kind])
    table = data["weight"]["table"]
    force = table["force_N"]
    if any(len(table[k]) != len(force) for k in ("delta_Bz_min_uT", "delta_Bz_nominal_uT", "delta_Bz_max_uT")):
        raise AcceptanceError("weight.table", "(lengths)", "every column must be as long as force_N")
    if any(b <= a for a, b in zip(force, force[1:])):
        raise AcceptanceError("weight.table.force_N", force[:5], "must be increasing")
    rest = data["rest"]["Bz_uT"]
    if not rest["min"] <= rest["nominal"] <= rest["max"]:
        raise AcceptanceError("rest.Bz_uT", rest, "must have min <= nominal <= max")
    return data


def loads(raw: bytes) -> dict:
    """Parse (UTF-8; nesting and keys bounded, :mod:`.bounded`) and :func:`validate` acceptance.json bytes."""
    try:
        data = bounded.loads_json(raw, "acceptance.json")
    except bounded.InputFileError:
        raise
    except ValueError as exc:  # UnicodeDecodeError is a ValueError too
        raise AcceptanceError("", "(contents)", f"is not valid JSON ({exc})") from None
    return validate(data)
