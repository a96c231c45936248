"""Records for the sensor tests: a sensor with a history written event by event as the other commands write it
(``magfab calibrate --sensor``, ``magfab-readout check --sensor``), dated over weeks."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from magfab.formats import sensor_records as rec


def calibration(taxel: int | None = None, *, bz: float = 18700.0, normal: float = 5800.0, shear: float = 8200.0,
                fz: float = 3.1, n: int = 0) -> tuple[dict[str, Any], dict[str, bytes]]:
    """A calibration event's data and files as ``magfab calibrate --sensor`` writes them (docs/sensors.md)."""
    cal = f'{{"format": "magfab-calibration/1", "n": {n}}}\n'.encode()
    data = {"taxel": taxel, "spec_sha256": "0" * 64, "source": f"scan{n}.csv + reference{n}.csv", "method": "poly",
            "order": 4, "rms_holdout_Fz_mN": fz, "rms_holdout_Fr_mN": 0.7 * fz,
            "calibration_sha256": rec.sha256_hex(cal), "rest_field_uT": [120.0, -80.0, bz],
            "sensitivity_normal_uT_per_N": normal, "sensitivity_shear_uT_per_N": shear, "range_normal_N": 1.0,
            "range_shear_N": 0.6, "provisional": False}
    return data, {"calibration.json": cal, "scan.csv": f"time_s\n{n}\n".encode()}


def check(verdict: str, taxel: int | None = None, *, bz: float = 18700.0, error: float = 4.0) -> dict[str, Any]:
    """A check event's data as ``magfab-readout check --sensor`` writes it."""
    return {"taxel": taxel, "verdict": verdict, "calibration_sha256": "1" * 64,
            "figures": {"Bz_rest_uT": bz, "Bz_rise_uT": 2875.0, "weight_g": 50.0, "turned_dFz_mN": error},
            "steps": ["rest", "weight", "turned"]}


#: Three calibrations and five checks over seven weeks, a new skin in week four (the issue's closing example).
HISTORY = (
    ("2026-10-05T09:30:00Z", "calibration", {"bz": 18650.0, "normal": 5790.0, "shear": 8150.0, "fz": 3.2, "n": 1}),
    ("2026-10-05T10:10:00Z", "check", {"verdict": "pass", "bz": 18655.0, "error": 3.9}),
    ("2026-10-12T09:00:00Z", "check", {"verdict": "pass", "bz": 18610.0, "error": 5.2}),
    ("2026-10-19T09:00:00Z", "calibration", {"bz": 18560.0, "normal": 5620.0, "shear": 7900.0, "fz": 3.6, "n": 2}),
    ("2026-10-19T09:40:00Z", "upload", {}),
    ("2026-10-26T09:00:00Z", "check", {"verdict": "fail", "bz": 18380.0, "error": 14.5}),
    ("2026-10-27T15:00:00Z", "reskin", {"note": "skin torn at the tip; new cast from the same mould"}),
    ("2026-10-28T09:00:00Z", "calibration", {"bz": 19420.0, "normal": 6930.0, "shear": 8800.0, "fz": 2.9, "n": 3}),
    ("2026-10-28T09:45:00Z", "check", {"verdict": "pass", "bz": 19415.0, "error": 3.4}),
    ("2026-11-16T09:00:00Z", "check", {"verdict": "pass", "bz": 19390.0, "error": 4.1}),
)


def write_history(sensor: rec.Sensor, history=HISTORY) -> None:
    for date, kind, args in history:
        if kind == "calibration":
            data, files = calibration(**args)
            sensor.append(kind, data, files, date=date)
        elif kind == "check":
            sensor.append(kind, check(**args), date=date)
        elif kind == "upload":
            sensor.append(kind, {"calibration_sha256": "1" * 64, "taxel": None}, date=date)
        else:
            sensor.append(kind, args, date=date)


def tree(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (temporary files included), by relative path."""
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}
