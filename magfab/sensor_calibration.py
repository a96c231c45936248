"""``magfab calibrate``'s guards and its ``--sensor`` path: a measured calibration appended to a sensor's record
(:mod:`magfab.formats.sensor_records`, docs/sensors.md section 3), the build folder left as it is.

The fit for a record needs neither the CAD nor the prediction: the calibration (:func:`magfab.models.calibration.
fit`, for an array's taxel on the field with its neighbours' removed) is a function of the scan and the design
alone, so the command costs the scan's reading and one fit (about 2 s for the MagOne), where a build takes half a
minute. The rest-band guard's bands come from the record's own acceptance.json (kept when the sensor was added),
else from the build folder of the same spec, else they are computed (the prediction: about 15 s).

Every guard here raises an :class:`~magfab.errors.InputError` (exit 2, one line) before anything is written.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .errors import InputError, ModelLimitError, OutputError
from .formats import bounded
from .formats import sensor_records as records
from .formats.calibration_json import calibration_sha256
from .models.acceptance import acceptance
from .models.calibration import fit, fits_mls
from .models.chip import chip_setting
from .models.predict import predict
from .models.rest_guard import RestField, calibrated_range_N, check_rest_band, rest_field, sensitivity_uT_per_N
from .models.taxels import array_field, compensated
from .models.weighing import stated_error
from .spec import spec_from_json

if TYPE_CHECKING:
    from .design import Design
    from .formats.scan_csv import Scan
    from .models.calibration import Calibration, FitResult
    from .spec import Spec

__all__ = ["RecordInputError", "record_errors", "build_of", "acceptance_bands", "check_rest", "open_record",
           "spec_of_record", "check_spec", "check_owner", "fit_taxel", "SensorCalibration", "calibrate_record",
           "calibration_figures",
           "unkept_calibrations", "refuse_discarding"]


class RecordInputError(InputError):
    """A sensor record cannot be used as asked (a :class:`~magfab.formats.sensor_records.RecordError`): exit 2."""


@contextmanager
def record_errors() -> Iterator[None]:
    """A :class:`~magfab.formats.sensor_records.RecordError` (the records module is the readout's, which knows no
    magfab error tree) as a :class:`RecordInputError`: the user's input, exit 2."""
    try:
        yield
    except records.RecordError as exc:
        raise RecordInputError(str(exc)) from None


def _json_bytes(obj: object) -> bytes:
    """A JSON file as the build writes its own (pipeline's)."""
    return (json.dumps(obj, indent=2, sort_keys=True) + "\n").encode()


def _added(sensor: records.Sensor) -> dict[str, Any]:
    return next((e for e in sensor.events() if e["kind"] == "added"), {})


# ---- the rest band -------------------------------------------------------------------------------------------------


def build_of(folder: Path | None, spec: Spec) -> bool:
    """Whether ``folder`` is a build of exactly ``spec`` (its manifest's spec hash)."""
    if folder is None:
        return False
    try:
        path = Path(folder) / "manifest.json"
        manifest = bounded.loads_json(bounded.read_bytes(path, "JSON"), "JSON", path)
    except (OSError, ValueError):
        return False
    return isinstance(manifest, dict) and manifest.get("spec_sha256") == spec.sha256()


def acceptance_bands(spec: Spec, design: Design, folder: Path | None,
                     sensor: records.Sensor | None = None) -> tuple[dict[str, Any] | None, str]:
    """(acceptance.json's content, where it came from) for the rest-band guard: the record's (kept when the sensor
    was added), the build folder's when it is a build of ``spec``, else computed from the prediction; (None, "")
    for a design without acceptance bands (no weight fits its range: the build ships none either)."""
    if sensor is not None:
        sha = _added(sensor).get("files", {}).get("acceptance.json")
        if sha:
            with record_errors():
                where = f"the record of {sensor.id}, acceptance.json"
                return sensor.json_file(sha, "acceptance.json"), where
    path = None if folder is None else Path(folder) / "calibration" / "acceptance.json"
    if path is not None and build_of(folder, spec) and path.is_file():
        return bounded.loads_json(bounded.read_bytes(path, "acceptance.json"), "acceptance.json", path), str(path)

    try:
        return acceptance(design, predict(design)), "the design's acceptance bands"
    except ModelLimitError:
        return None, ""


def check_rest(scan: Scan, design: Design, bands: Mapping[str, Any], where: str,
               taxel: int | None = None) -> RestField:
    """The scan's rest field, or ScanError when it lies outside the design's acceptance band
    (:func:`magfab.models.rest_guard.check_rest_band`); an array's taxel with its polarity and its neighbours'
    field at rest."""

    polarity, offset = 1, (0.0, 0.0, 0.0)
    if design.array is not None and taxel is not None:
        polarity, offset = design.taxels[taxel].polarity, tuple(array_field(design).offset_uT[taxel])
    return check_rest_band(scan, bands, polarity=polarity, offset_uT=offset, lsb_z_uT=chip_setting(design).lsb_z_uT,
                           remanence_per_C=design.magnet_grade.br_temperature_coefficient_pct_per_C.nominal / 100.0,
                           where=where)


# ---- the record ----------------------------------------------------------------------------------------------------


def open_record(root: Path | None, sensor_id: str) -> records.Sensor:
    """The record of ``sensor_id`` (root: ``--sensors``, else $MAGFAB_SENSORS, else the nearest sensors/)."""
    with record_errors():
        return records.open_sensor(records.find_root(root), sensor_id)


def spec_of_record(sensor: records.Sensor) -> Spec | None:
    """The spec the sensor was made from (its added event's spec.json), or None when the record keeps none."""

    sha = _added(sensor).get("files", {}).get("spec.json")
    if not sha:
        return None
    with record_errors():
        raw = sensor.json_file(sha, "spec.json")
    return spec_from_json(raw, f"{sensor.path}/files/{sha}.json")


def _record_spec_sha(sensor: records.Sensor) -> str | None:
    with record_errors():
        return _added(sensor).get("spec_sha256") or sensor.info.get("spec_sha256")


def check_spec(sensor: records.Sensor, spec: Spec) -> None:
    """InputError when the sensor was made from another spec than ``spec`` (the calibration would be another
    design's)."""
    made = _record_spec_sha(sensor)
    if made is not None and made != spec.sha256():
        raise RecordInputError(
            f"sensor {sensor.id} was made from another spec than {spec.name!r} (spec hash {made[:12]} in its record, "
            f"{spec.sha256()[:12]} here): a calibration fitted to this design would not be its own; calibrate it "
            "against the build it was added from (drop --spec, or run from that build folder)")


def check_owner(sensor: records.Sensor, files: Mapping[str, bytes]) -> None:
    """InputError when a scan of ``files`` (``scan.csv``, ``scan_merged.csv``) calibrated another sensor already."""
    for role in ("scan.csv", "scan_merged.csv"):
        if role not in files:
            continue
        with record_errors():
            others = [s for s in records.owner_of(sensor.root, records.sha256_hex(files[role])) if s != sensor.id]
        if others:
            raise RecordInputError(
                f"scan {role} (SHA-256 {records.sha256_hex(files[role])[:12]}) calibrated sensor {others[0]} already "
                f"(its record in {sensor.root} keeps it): a scan belongs to the sensor it was recorded on; scan "
                f"{sensor.id} and calibrate it with its own scan")


# ---- the fit and the event -----------------------------------------------------------------------------------------


def fit_taxel(scan: Scan, design: Design, taxel: int | None) -> FitResult:
    """The calibration of a single taxel, or of taxel ``taxel`` of an array (on its field with the neighbours'
    field at rest removed), as the build fits it."""

    mls = fits_mls(design)
    if design.array is None:
        return fit(scan, design, mls=mls)

    assert taxel is not None
    return fit(compensated(scan, array_field(design), taxel), design, mls=mls)


@dataclass(frozen=True)
class SensorCalibration:
    """What ``magfab calibrate --sensor`` appended: the event as written and the fit."""

    event: dict[str, Any]
    fit: FitResult
    sensor: records.Sensor


def calibrate_record(sensor: records.Sensor, spec: Spec, design: Design, scan: Scan, rest: RestField,
                     files: Mapping[str, bytes], taxel: int | None, date: str | None = None) -> SensorCalibration:
    """Fit ``scan`` and append the calibration event to ``sensor``'s record (docs/sensors.md section 3), keeping
    ``files`` (``scan.csv``, and ``reference.csv`` and ``scan_merged.csv`` for a merged scan) and the fitted
    calibration.json. Raises before appending when the fit fails."""

    result = fit_taxel(scan, design, taxel)
    cal = result.calibration.to_json()
    err: Any = cal["errors"]
    data = {
        "taxel": taxel, "spec_sha256": spec.sha256(), "source": scan.source, "method": cal["method"],
        "order": cal["order"], "rms_holdout_Fz_mN": round(1000 * err["Fz_N"]["rms_holdout"], 2),
        "rms_holdout_Fr_mN": round(1000 * err["Fr_N"]["rms_holdout"], 2), "calibration_sha256": calibration_sha256(cal),
        **calibration_figures(scan, result.calibration, design, taxel, rest), "provisional": False,
        **stated_error(cal),
    }
    with record_errors():
        event = sensor.append("calibration", data, {**files, "calibration.json": _json_bytes(cal)}, date=date)
    return SensorCalibration(event, result, sensor)


def calibration_figures(scan: Scan, calibration: Calibration, design: Design, taxel: int | None,
                        rest: RestField | None = None) -> dict[str, Any]:
    """What a calibration event says of the sensor (docs/sensors.md section 3): its field at rest
    ``rest_field_uT`` [Bx, By, Bz] (``rest``, else the scan's own), the sensitivities at rest from the fitted
    calibration (:func:`~magfab.models.rest_guard.sensitivity_uT_per_N`) and the calibrated ranges
    (:func:`~magfab.models.rest_guard.calibrated_range_N`); an array taxel's with its neighbours' field removed."""
    rest = rest if rest is not None else rest_field(scan)
    offset: tuple[float, ...] = (0.0, 0.0, 0.0)
    fitted_scan = scan
    if design.array is not None and taxel is not None:
        field = array_field(design)
        offset = tuple(float(x) for x in field.offset_uT[taxel])
        fitted_scan = compensated(scan, field, taxel)
    rest_fitted = [float(b - o) for b, o in zip(rest.B_uT, offset)]
    normal, shear = sensitivity_uT_per_N(calibration, rest_fitted, rest.temperature_C)
    range_normal, range_shear = calibrated_range_N(fitted_scan, calibration)
    return {"rest_field_uT": [round(float(b), 3) for b in rest.B_uT],
            "sensitivity_normal_uT_per_N": _rounded(normal), "sensitivity_shear_uT_per_N": _rounded(shear),
            "range_normal_N": round(range_normal, 6), "range_shear_N": round(range_shear, 6)}


def _rounded(x: float) -> float | None:
    return None if x != x else round(x, 3)  # NaN (no change over the step) has no JSON form


# ---- a rebuild over a measured calibration -------------------------------------------------------------------------


def _measured(folder: Path) -> list[tuple[str, bytes]]:
    """(relative path, bytes) of the calibrations in build ``folder`` fitted to a measured scan."""
    out = []
    calibration = Path(folder) / "calibration"
    for path in sorted(calibration.glob("*.json")) if calibration.is_dir() else []:
        if path.name != "calibration.json" and not path.name.startswith("taxel_"):
            continue
        data = bounded.read_bytes(path, "calibration.json")
        try:
            source = bounded.loads_json(data, "calibration.json", path)["scan"]["source"]
        except (ValueError, KeyError, TypeError):
            continue  # a file gone bad: nothing worth keeping
        if not str(source).startswith("simulated"):
            out.append((f"calibration/{path.name}", data))
    return out


def _kept(roots: list[Path]) -> set[str]:
    """Every calibration hash (canonical and of the file's bytes) the calibration events of ``roots`` keep."""
    kept: set[str] = set()
    for root in roots:
        with record_errors():
            for sensor in records.list_sensors(root):
                for event in sensor.events():
                    if event["kind"] in ("calibration", "added"):
                        kept.add(str(event.get("calibration_sha256")))
                        kept.update(str(v) for v in event.get("files", {}).values())
    return kept


def unkept_calibrations(folder: Path, starts: list[Path]) -> list[str]:
    """The measured calibrations of build ``folder`` (relative paths) that no sensor record keeps: the records
    of the sensor roots :func:`~magfab.formats.sensor_records.find_root` finds from each of ``starts``."""

    measured = _measured(folder)
    if not measured:
        return []
    roots = []
    for start in starts:
        with record_errors():
            root = records.find_root(None, start, must_exist=False)
        if (root / records.MARKER).is_file() and root not in roots:
            roots.append(root)
    kept = _kept(roots)
    return [rel for rel, data in measured if hashlib.sha256(data).hexdigest() not in kept
            and calibration_sha256(bounded.loads_json(data, "calibration.json", folder / rel)) not in kept]


def refuse_discarding(folder: Path, starts: list[Path]) -> None:
    """OutputError when a rebuild of ``folder`` would replace a measured calibration no sensor record keeps."""
    unkept = unkept_calibrations(folder, starts)
    if unkept:
        raise OutputError(
            f"{folder} holds a measured calibration ({', '.join(unkept)}) that no sensor record keeps, and this build "
            "would replace it with the provisional one: keep it first with `magfab sensor add ID --build "
            f"{folder}` (or calibrate with --sensor ID), or pass --discard-calibration to replace it")

