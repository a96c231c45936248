"""The report's tables as plain rows for the template: key figures, the stack-up's distances and heights,
the predictions, the models, the calibration, the findings by severity, every spec key, the parts on the
board and the build's files (grouped by folder, linked by relative paths)."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any, TypedDict
from urllib.parse import quote

from ...errors import Finding, Severity
from ...models.weighing import weight_fit_of
from ...spec import Spec

if TYPE_CHECKING:
    from ...board.layout import Board
    from ...design import Design
    from ...models.predict import Prediction
    from ...output import Artifact
    from ...spec import Spec

__all__ = ["href", "spec_sections", "stack_rows", "heights", "prediction_tables", "key_figures", "model_rows",
           "calibration_summary", "findings_by_severity", "file_groups", "board_parts"]

_SEVERITY_ORDER = (Severity.ERROR, Severity.WARNING, Severity.INFO)
FORCE_NAMES = {"Fz_N": "Fz (normal)", "Fr_N": "Fr (shear)"}


def href(path: str) -> str:
    """A relative POSIX path as a link target (percent-encoded, slashes kept)."""
    return quote(path, safe="/")


def _spec_value(value: object, key: str) -> str:
    """A spec value as it would be written in TOML (None: omitted, derived or taken from a recipe)."""
    if value is None:
        return "(omitted)"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int) and key.endswith("address"):
        return f"{value} (0x{value:02X})"
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(_spec_value(v, "") for v in value) + "]"
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    return repr(value)


def spec_sections(spec: Spec) -> list[dict[str, object]]:
    """Every section and key of the spec with its value, meaning and whether it differs from the default."""
    values, defaults = spec.dump(), Spec().model_dump(mode="json")
    general: dict[str, Any] = {"title": "general", "doc": "", "rows": []}
    sections = [general]
    for name, info in type(spec).model_fields.items():
        if name not in values:  # a single taxel's spec has no [array]
            continue
        value = values[name]
        if not isinstance(value, dict):
            general["rows"].append({"key": name, "value": _spec_value(value, name), "doc": info.description or "",
                                    "changed": value != defaults[name]})
            continue
        model = type(getattr(spec, name))
        default = defaults[name] or model().model_dump(mode="json")
        rows = [{"key": k, "value": _spec_value(v, k), "doc": model.model_fields[k].description or "",
                 "changed": v != default.get(k)} for k, v in value.items()]
        sections.append({"title": name, "doc": (model.__doc__ or "").strip(), "rows": rows})
    return sections


def stack_rows(design: Design) -> list[tuple[str, str]]:
    d, sen = design, design.spec.sensor
    return [
        ("rest distance d_rest, magnet lower face to sensing point", f"{d.d_rest_mm:.3f} mm"),
        ("closest under load d_min (spec)", f"{sen.d_min_mm:.3f} mm"),
        ("magnet travel to d_min", f"{d.d_rest_mm - sen.d_min_mm:.3f} mm"),
        ("cover: silicone above the magnet on the axis", f"{d.cover_mm:.3f} mm"),
        ("skin: thinnest silicone around the pocket",
         f"{d.skin_mm:.3f} mm (spec minimum {design.spec.elastomer.min_skin_mm:g})"),
        ("d_rest this elastomer, pad and chip allow", f"{d.d_rest_range_mm[0]:.3f} to {d.d_rest_range_mm[1]:.3f} mm"),
        ("magnet, diameter x height", f"{2 * d.magnet_radius_mm:g} x {d.magnet_height_mm:g} mm"),
        ("pocket, diameter x height", f"{2 * d.pocket_radius_mm:.3f} x {d.pocket_height_mm:.3f} mm"),
        ("silicone per cast part", f"{d.elastomer_volume_mm3 / 1000:.3f} mL"),
    ]


def heights(design: Design) -> list[tuple[str, str]]:
    d = design
    return [(name, f"{z:.3f}") for name, z in sorted([
        ("board top face", 0.0), ("Hall sensing point", d.z_sense_mm), ("chip package top", d.chip_height_nominal_mm),
        ("pad top (glue face)", d.z_pad_top_mm), ("elastomer base", d.z_elastomer_base_mm),
        ("magnet lower face", d.z_magnet_low_mm), ("magnet top = pocket roof", d.z_magnet_top_mm),
        ("elastomer top", d.z_elastomer_base_mm + d.elastomer_height_mm)], key=lambda r: r[1])]


def _measured_rows(m: Mapping[str, Any] | None) -> list[tuple[str, str]]:
    """The readout's rate as the shipped image measured it (firmware.measured_rate_for: this build's settings and a
    calibration like its own), where there is one."""
    if m is None:
        return []
    w, cal = m["worst"], m["calibration"]
    return [("readout rate, measured", f"{w['rate_Hz']:.0f} frames/s, {w['delivered']:.1%} of the chip's conversions, "
             f"at the busiest of {m['fields']} fields of {cal['spec']}'s region (order {cal['order']} calibration; "
             f"processor busy {w['busy_us']:.0f} of {w['cycle_us']:.0f} µs a frame; simulated bus, real "
             f"{m['i2c_Hz'] / 1000:.0f} kHz timing)")]


def prediction_tables(pred: Prediction, measured: Mapping[str, Any] | None = None) -> dict[str, list[tuple[str, str]]]:
    """The prediction's tables for the report; ``measured``: the measured readout rate the chip's table quotes
    (firmware.measured_rate_for the build: None for another build's settings, or an array's)."""
    n, s, f, c, nz = pred.normal, pred.shear, pred.field, pred.chip, pred.noise
    band = lambda m, fmt: ", ".join(f"{k} {format(v, fmt)}" for k, v in m.items())
    return {
        "normal": [
            ("sensitivity over the range", f"{n.sensitivity_G_per_N[0]:.1f} – {n.sensitivity_G_per_N[1]:.1f} G/N"),
            ("resolution, worst case", f"{n.resolution_mN:.2f} mN"),
            ("resolution at rest (weakest magnet)", band(n.resolution_at_rest_mN, ".2f") + " mN"),
            ("range, worst case", n.range_text()),
            ("range by material", "at least " * n.range_is_model_reach + band(n.range_by_material_N, ".3f") + " N"),
            ("magnet travel over the range", f"{n.travel_mm:.3f} mm"),
            ("sensitivity at rest (nominal magnet)", band(n.sensitivity_at_rest_G_per_N, ".1f") + " G/N"),
            ("stiffness at rest", band(n.stiffness_at_rest_N_per_mm, ".3f") + " N/mm"),
        ] + ([("where the FE curve ends", n.model_limit)] if n.model_limit else []),
        "shear": [
            ("sensitivity", f"{s.sensitivity_G_per_N[0]:.1f} – {s.sensitivity_G_per_N[1]:.1f} G/N"),
            ("sensitivity at rest (nominal magnet)", band(s.sensitivity_at_rest_G_per_N, ".1f") + " G/N"),
            ("resolution, worst case", f"{s.resolution_mN:.2f} mN"),
            ("range, worst case", f"{s.range_N:.3f} N (ends at: {s.range_limit})"),
            ("range by material", band(s.range_by_material_N, ".3f") + " N"),
            ("stiffness", band(s.stiffness_N_per_mm, ".3f") + " N/mm"),
        ],
        "field": [
            ("Bz at rest (nominal magnet)", f"{f.Bz_rest_G:.1f} G"),
            ("dBz/dz at rest", f"{f.dBz_dz_rest_G_per_mm:.1f} G/mm"),
            ("dBr/dr at rest", f"{f.dBr_dr_rest_G_per_mm:.1f} G/mm"),
            ("Bz at d_min (nominal / strongest magnet)", f"{f.Bz_d_min_G:.1f} / {f.Bz_d_min_strongest_G:.1f} G"),
            ("Bz where the range ends (strongest magnet)", f"{f.Bz_range_end_strongest_G:.1f} G"),
            ("remanence band", band(f.remanence_T, ".3f") + " T"),
            ("elastomer shear modulus band", band(pred.material_mu_kPa, "g") + " kPa"),
        ],
        "chip": [
            ("GAIN_SEL / RES / OSR / DIG_FILT", f"{c.gain_sel} / {c.resolution} / {c.osr} / {c.dig_filt}"),
            ("LSB, xy / z", f"{c.lsb_xy_uT:.3f} / {c.lsb_z_uT:.3f} µT"),
            ("full scale, xy / z", f"{c.full_scale_xy_G:.1f} / {c.full_scale_z_G:.1f} G"),
            ("saturation onset", f"{c.saturation_onset_G:.0f} G"),
            ("conversion (T+X+Y+Z)", f"{c.conversion_ms:.3f} ms ({c.rate_Hz:.0f} Hz)"),
            *_measured_rows(measured),
        ],
        "noise": [
            ("environment", f"{nz.environment_G:.3f} G"),
            ("chip, xy / z", f"{nz.chip_xy_G:.3f} / {nz.chip_z_G:.3f} G"),
            ("quantisation, xy / z", f"{nz.quantisation_xy_G:.4f} / {nz.quantisation_z_G:.4f} G"),
            ("total, xy / z", f"{nz.total_xy_G:.3f} / {nz.total_z_G:.3f} G"),
        ],
    }


def key_figures(design: Design, pred: Prediction, calibration: Mapping[str, Any] | None,
                 findings: Sequence[Finding]) -> list[tuple[str, str, str]]:
    n, s = pred.normal, pred.shear
    out = [
        ("d_rest", f"{design.d_rest_mm:.2f} mm", f"cover {design.cover_mm:.2f} mm, skin {design.skin_mm:.2f} mm"),
        ("Bz at rest", f"{pred.field.Bz_rest_G:.1f} G", f"noise {pred.noise.total_z_G:.3f} G RMS (z)"),
        ("normal sensitivity", f"{n.sensitivity_G_per_N[0]:.1f} – {n.sensitivity_G_per_N[1]:.1f} G/N",
         f"resolution {n.resolution_mN:.2f} mN"),
        ("normal range", *n.range_parts()),
        ("shear sensitivity", f"{s.sensitivity_G_per_N[0]:.1f} – {s.sensitivity_G_per_N[1]:.1f} G/N",
         f"resolution {s.resolution_mN:.2f} mN"),
        ("shear range", f"{s.range_N:.3f} N", f"ends at: {s.range_limit}"),
        ("silicone per part", f"{design.elastomer_volume_mm3 / 1000:.3f} mL",
         f"{design.cavities} cavit{'y' if design.cavities == 1 else 'ies'} per mould"),
    ]
    if pred.drift is not None:
        t, turned = pred.drift.temperature, pred.drift.rotation
        out.append(("drift", f"{abs(t.per_C['normal_rest']['without']):.1f} mN/C",
                    f"normal at rest, uncompensated; {turned.what}: {abs(turned.normal_rest_mN):.1f} mN"))
    if calibration is not None:
        err = calibration["errors"]
        out.append(("calibration, held-out RMS", f"{1000 * err['Fz_N']['rms_holdout']:.2f} mN (Fz)",
                    f"{1000 * err['Fr_N']['rms_holdout']:.2f} mN (Fr), {calibration['scan']['source']} scan"))
    counts = {sev: sum(f.severity is sev for f in findings) for sev in _SEVERITY_ORDER}
    out.append(("design checks", f"{counts[Severity.ERROR]} errors, {counts[Severity.WARNING]} warnings",
                f"{counts[Severity.INFO]} notes"))
    return out


def model_rows(pred: Prediction) -> list[dict[str, str]]:
    return [{"family": m.family, "model": m.name, "chosen_by": m.chosen_by,
             "error": f"{100 * m.error:.2g} %" if math.isfinite(m.error) else "not measured here", "detail": m.detail}
            for m in pred.models]


def calibration_summary(calibration: Mapping[str, Any] | None, tolerance_mN: float) -> dict[str, object] | None:
    if calibration is None:
        return None
    err = calibration["errors"]
    rows = [(FORCE_NAMES[k], *(f"{1000 * err[k][what]:.2f}" for what in ("rms_fit", "rms_holdout", "max_holdout")))
            for k in ("Fz_N", "Fr_N")]
    worst = max(1000 * err[k]["rms_holdout"] for k in ("Fz_N", "Fr_N"))
    scan = calibration["scan"]
    return {"method": str(calibration["method"]), "order": calibration["order"], "folds": err["folds"],
            "source": str(scan["source"]), "rows": scan["rows"], "sha": str(scan["sha256"]), "errors": rows,
            "tolerance_mN": f"{tolerance_mN:g}", "meets": worst <= tolerance_mN,
            "provisional": scan["source"] == "simulated", "weights": _weights_summary(weight_fit_of(calibration))}


def _weights_summary(model: Mapping[str, Any] | None) -> dict[str, object] | None:
    """A weight calibration's fit (calibration.json's ``scan.model``, docs/models.md M25) for the report: the fitted
    parameters with their standard deviations, which were kept from an earlier skin, and the predicted error."""
    if model is None:
        return None
    err = model["predicted_error_mN"]
    kept = {k.removeprefix("log_") for k in model.get("kept", [])}
    params = [(name, f"{p['value']:.4g}", f"{p['sd']:.2g}",
               "kept" if name.removesuffix("_ratio") in kept else "fitted")
              for name, p in sorted(model["parameters"].items())]
    return {"weighings": model["weighings"], "parameters": params,
            "fz": (f"{err['Fz_rms']['median']:g}", f"{err['Fz_rms']['p90']:g}"),
            "shear": (f"{err['shear_rms']['median']:g}", f"{err['shear_rms']['p90']:g}")}


def findings_by_severity(findings: Sequence[Finding]) -> list[dict[str, object]]:
    return [{"severity": sev.value, "items": [f for f in findings if f.severity is sev]} for sev in _SEVERITY_ORDER]


def _size(n: int | None) -> str:
    if n is None:
        return ""
    return f"{n} B" if n < 1000 else f"{n / 1000:.1f} kB" if n < 1_000_000 else f"{n / 1e6:.2f} MB"


class FileRow(TypedDict):
    """One file of the report's file table (its size as text, empty for an extra file)."""

    path: str
    href: str
    description: str
    size: str


class FileGroup(TypedDict):
    """The files under one top folder ("" for the build's root)."""

    folder: str
    rows: list[FileRow]


def file_groups(artifacts: Sequence[Artifact], extra: Sequence[tuple[str, str]]) -> list[FileGroup]:
    """The file table grouped by top folder (the build's root first), each row linked relatively."""
    rows = [(a.path, a.description, len(a.data)) for a in artifacts] + [(p, d, None) for p, d in extra]
    seen: set[str] = set()
    for path, _, _ in rows:
        if path in seen:
            raise ValueError(f"file {path!r} is listed twice (in the artifacts and in extra_files?)")
        if path.startswith("/") or any(part in {"", ".", ".."} for part in path.split("/")) or "\\" in path:
            raise ValueError(f"file {path!r} must be a relative POSIX path inside the build folder")
        seen.add(path)
    groups: dict[str, list[FileRow]] = {}
    for path, description, size in sorted(rows, key=lambda r: ("/" in r[0], r[0])):
        folder = path.split("/", 1)[0] + "/" if "/" in path else ""
        groups.setdefault(folder, []).append({"path": path, "href": href(path), "description": description,
                                              "size": _size(size)})
    return [{"folder": k, "rows": v} for k, v in groups.items()]


def board_parts(board: Board) -> list[dict[str, str]]:
    """What stands on the board: reference, value, side and footprint, in reference order."""
    return [{"ref": p.ref, "value": p.value, "side": "bottom" if p.bottom else "top", "footprint": p.footprint.name}
            for p in sorted(board.parts, key=lambda p: (p.ref[0], int("0" + "".join(filter(str.isdigit, p.ref)))))]
