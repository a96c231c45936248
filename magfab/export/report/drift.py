"""The report's drift section: the budget's table (temperature, the Earth's field, the stray source, each against the
resolution) and its chart, from the prediction's drift budget (:mod:`magfab.models.drift`, predictions.json's
``drift``)."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from ..drift_figures import FOLDER

if TYPE_CHECKING:
    from ...models.drift import Disturbance, Drift
    from ...models.predict import Prediction

__all__ = ["drift_context", "HEADER"]

HEADER = ("source", "field on an axis (G)", "normal at rest (mN)", "normal at the end (mN)", "shear (mN)",
          "against the resolution")


def _verdict(values: tuple[float, ...], normal_mN: float, shear_mN: float) -> str:
    over = abs(values[0]) > normal_mN or abs(values[1]) > normal_mN or abs(values[2]) > shear_mN
    worst = max(abs(values[0]) / normal_mN, abs(values[1]) / normal_mN, abs(values[2]) / shear_mN)
    return f"{worst:.1f}x the resolution" if over else "within the resolution"


def _row(label: str, field: str, values: tuple[float, ...], d: Drift) -> tuple[str, ...]:
    res = d.resolution_mN
    return (label, field, *(f"{abs(v):.1f}" for v in values), _verdict(values, res["normal"], res["shear"]))


def _disturbance_row(label: str, x: Disturbance, d: Drift) -> tuple[str, ...]:
    return _row(label, f"{x.field_G:.3g}", (x.normal_rest_mN, x.normal_end_mN, x.shear_mN), d)


def _rows(d: Drift) -> list[tuple[str, ...]]:
    t, env = d.temperature, d.conditions
    span = f"{env['temperature_min_C']:g}-{env['temperature_max_C']:g} C"
    per_C = (*(t.per_C[p]["without"] for p in ("normal_rest", "normal_end")),
             max(t.per_C["shear_rest"]["without"], t.per_C["shear_end"]["without"], key=abs))
    rows = [_row("temperature, per C, uncompensated", "-", per_C, d)]
    for case, what in (("without", "uncompensated"), ("with", "compensated, recipe coefficients"),
                       ("fitted", "compensated, fitted coefficients")):
        w = t.worst
        values = (w["normal_rest"][case], w["normal_end"][case], max(w["shear_rest"][case], w["shear_end"][case]))
        rows.append(_row(f"temperature over {span}, {what}", "-", values, d))
    rows += [_disturbance_row(f"turned over in a {b.field_G / 2:g} G Earth field", b, d) for b in d.rotation_band]
    rows.append(_disturbance_row(f"this place and turn: {d.rotation.what}", d.rotation, d))
    if d.stray is not None:
        rows.append(_disturbance_row(f"stray source: {d.stray.what}", d.stray, d))
    return rows


def _reference_rows(section: Mapping[str, Any] | None, d: Drift) -> list[tuple[str, ...]]:
    """The rotation and the stray source again with the reference chip subtracted (predictions.json's
    ``reference``), or none without one."""
    if section is None:
        return []
    picked = [("the same turn, the reference chip subtracted", section["rotation"]["with"])]
    if section["stray"] is not None:
        picked += [(f"the stray source, the reference subtracted ({k[5:]} over its direction)", section["stray"][k])
                   for k in ("with_median", "with_worst")]
    return [_row(label, f"{x['field_G']:.3g}", (x["normal_rest_mN"], x["normal_end_mN"], x["shear_mN"]), d)
            for label, x in picked]


def drift_context(prediction: Prediction, figures: Callable[[str], list]) -> dict | None:
    """What report.html.j2's drift section shows, or None without a budget. ``figures(folder)``: the build's plots
    under a folder, as the report draws them."""
    d = prediction.drift
    if d is None:
        return None

    c, env, p = d.coefficients, d.conditions, d.temperature.per_C_parts
    stated = "the spec's [environment]" if env["stated"] else "a lab bench (no [environment] in the spec)"
    summary = (f"Errors the force model does not see, under the conditions of {stated}; worst cases over the "
               f"coefficients' bands, read through the calibration's inverse (the stiff material, the weakest magnet). "
               f"Per C at rest: the magnet {abs(p['magnet']):.1f} mN (alpha(Br) {c.magnet_pct_per_C:g} %/C), the "
               f"chip's sensitivity {abs(p['chip_sensitivity']):.1f} mN (+/-{c.chip_sensitivity_pct_per_C:.2g} %/C) "
               f"and offset {abs(p['chip_offset']):.1f} mN (+/-{c.chip_offset_z_G_per_C:.2g} G/C). Compensation reads "
               f"the chip's temperature (+/-{c.sensor_linearity_C:g} C linearity over its range) and the magnet may "
               f"lag it by {env['temperature_lag_C']:g} C. Resolution {d.resolution_mN['normal']:.2f} mN normal, "
               f"{d.resolution_mN['shear']:.2f} mN shear; field noise {d.noise_G['z']:.3f} G (z), "
               f"{d.noise_G['xy']:.3f} G (x, y) RMS.")
    ref: Mapping[str, Any] | None = prediction.reference  # the reference section of predictions.json
    if ref is not None:
        chip, rej = ref["chip"], ref["rejection"]
        summary += (f" A reference chip ({chip['designator']}, 0x{chip['i2c_address']:02X}, {chip['separation_mm']:g} "
                    "mm from the sensing chip) is subtracted on the board: a uniform field rejected "
                    f"{rej['uniform']:.0f}x (the chips' mismatch, {100 * rej['mismatch']:g} % assumed, and "
                    f"{100 * rej['cross_axis']:g} % cross-axis); a dipole as near as the reference is not rejected.")
    return {"summary": summary, "header": HEADER, "rows": _rows(d) + _reference_rows(ref, d),
            "figures": figures(FOLDER)}
