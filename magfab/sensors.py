"""Physical sensors (docs/sensors.md): what ``magfab sensor ...`` does with the records of
:mod:`magfab.formats.sensor_records`. A record is made from a build folder (its spec, design and acceptance bands,
and any calibration measured into it), and read back as a history: one row per event, a summary per sensor, and the
comparison of a new skin's calibration with the previous skin's against the design's bands.

Pure functions over records and build folders; the CLI (:mod:`magfab.sensor_cli`) prints."""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import __version__
from .design import Design, derive
from .errors import InputError
from .export.sensor_history import check_error_mN, check_rest_uT
from .formats import bounded
from .formats import sensor_records as rec
from .formats.calibration_json import calibration_sha256
from .formats.scan_csv import ScanError, read_scan_csv
from .models.calibration import Calibration
from .models.scan_guards import MERGED
from .output import is_build
from .sensor_calibration import calibration_figures
from .spec import spec_from_json

__all__ = ["SensorError", "add_from_build", "comparisons", "history", "is_measured",
           "records_checked", "summary", "bands"]


class SensorError(InputError):
    """A sensor record cannot be read or written as asked (exit 2, one line): a :class:`rec.RecordError` as magfab
    reports it."""


@contextmanager
def records_checked() -> Iterator[None]:
    """The records' own error (the readout package's, standard library only) as magfab's input error."""
    try:
        yield
    except rec.RecordError as exc:
        raise SensorError(str(exc)) from None


# ---- adding a sensor from a build folder ---------------------------------------------------------------------------


def is_measured(source: str) -> bool:
    """Whether a calibration's scan ``source`` (calibration.json ``scan.source``) is a measurement: not the build's
    simulated scan, nor a copy of its file."""
    return not source.startswith("simulated") and not Path(source.split(MERGED)[0]).name.startswith("scan_simulated")


def _read(path: Path, what: str = "JSON") -> bytes:
    """A build folder's file (within ``what``'s limit, :mod:`.formats.bounded`)."""
    try:
        return bounded.read_bytes(path, what)
    except OSError as exc:
        raise SensorError(f"{path}: {exc.strerror}: the build folder is incomplete; rebuild it") from None


@dataclass(frozen=True)
class Adopted:
    """A measured calibration found in a build folder: its event's data and files."""

    data: dict[str, Any]
    files: dict[str, bytes]


def _scan_files(folder: Path, source: str, sha256: str, kept: str | None) -> dict[str, bytes]:
    """The files behind a measured calibration that the build folder still holds: the merged scan the build kept
    (``kept``), the recording and the reference log named in ``source``, a plain scan by its name."""
    files: dict[str, bytes] = {}
    if kept is not None and (folder / kept).is_file():
        files["scan_merged.csv" if MERGED in source else "scan.csv"] = _read(folder / kept, "scan CSV")
    names = source.split(MERGED)
    for role, name in zip(("scan.csv", "reference.csv"), names):
        for where in (folder / name, folder / "calibration" / name):
            if role not in files and where.is_file():
                files[role] = _read(where, "scan CSV" if role == "scan.csv" else "reference log")
    if MERGED not in source and "scan.csv" in files and rec.sha256_hex(files["scan.csv"]) != sha256:
        del files["scan.csv"]  # a file of the same name, not the one fitted
    return files


def _adopt(folder: Path, rel: str, taxel: int | None, design: Design, kept: str | None) -> Adopted | None:
    path = folder / rel
    if not path.is_file():
        return None
    raw = _read(path, "calibration.json")
    cal = bounded.loads_json(raw, "calibration.json", path)
    scan = cal.get("scan", {})
    source = str(scan.get("source", "simulated"))
    if not is_measured(source):
        return None
    files = {"calibration.json": raw, **_scan_files(folder, source, str(scan.get("sha256", "")), kept)}
    fitted = files.get("scan_merged.csv", files.get("scan.csv"))
    try:
        figures = ({} if fitted is None else
                   calibration_figures(read_scan_csv(fitted), Calibration.from_json(cal), design, taxel))
    except (ScanError, ValueError, KeyError):  # a scan or calibration the figures cannot be read from: kept without
        figures = {}
    err = cal.get("errors", {})
    data = {"taxel": taxel, "spec_sha256": design.spec.sha256(), "source": f"adopted from the build folder: {source}",
            "method": cal.get("method"), "order": cal.get("order"),
            "rms_holdout_Fz_mN": _mN(err.get("Fz_N", {}).get("rms_holdout")),
            "rms_holdout_Fr_mN": _mN(err.get("Fr_N", {}).get("rms_holdout")),
            "calibration_sha256": calibration_sha256(cal), "provisional": False,
            **{k: figures.get(k) for k in ("rest_field_uT", "sensitivity_normal_uT_per_N",
                                           "sensitivity_shear_uT_per_N", "range_normal_N", "range_shear_N")}}
    return Adopted(data, files)


def _mN(x: object) -> float | None:
    return round(1000.0 * x, 3) if isinstance(x, (int, float)) and math.isfinite(x) else None


def measured_calibrations(folder: Path, taxels: int | None, design: Design) -> list[Adopted]:
    """Every calibration a lab measured into the build folder ``folder`` (one for a single taxel, one per measured
    taxel of an array), as calibration events to append."""
    if taxels is None:
        found = [_adopt(folder, "calibration/calibration.json", None, design, "calibration/scan_merged.csv")]
    else:
        found = [_adopt(folder, f"calibration/taxel_{k:02d}.json", k, design,
                        f"calibration/scan_taxel_{k:02d}.csv") for k in range(taxels)]
    return [a for a in found if a is not None]


def build_folder(explicit: Path | None, default: Path) -> Path:
    """The build folder ``sensor add`` reads: ``explicit`` (--build), else the one we stand in, else ``default``
    (build/<name> of the default spec); :class:`SensorError` when it is not a magfab build."""
    for folder in ((explicit,) if explicit is not None else (Path.cwd(), default)):
        if is_build(folder):
            return folder
    where = explicit if explicit is not None else default
    raise SensorError(f"--build = {where}: is not a magfab build folder (no manifest.json magfab wrote): build the "
                      "design first (magfab build SPEC), or name its folder with --build DIR")


def add_from_build(root: Path, sensor_id: str, folder: Path, date: str | None = None) -> tuple[rec.Sensor, int]:
    """A new record of ``sensor_id`` in ``root`` made from the build folder ``folder``: the added event keeping its
    spec, design and acceptance bands (and an array's layout), then one calibration event per measured calibration
    found there, so nothing a lab measured is lost. Returns the sensor and the number of calibrations adopted."""
    with records_checked():
        rec.check_id(sensor_id)
        if (Path(root) / sensor_id / "sensor.json").exists():
            raise SensorError(f"sensor = {sensor_id}: already has a record in {root}: pick another ID, or use that one")
        manifest = bounded.loads_json(_read(folder / "manifest.json"), "JSON", folder / "manifest.json")
        spec_raw, design_raw = _read(folder / "spec.json", "spec.json"), _read(folder / "design.json")
        spec = bounded.loads_json(spec_raw, "spec.json", folder / "spec.json")
        design = derive(spec_from_json(spec, str(folder / "spec.json")))
        taxels = None if design.spec.array is None else design.spec.array.taxels  # spec.json states rows and cols
        files = {"spec.json": spec_raw, "design.json": design_raw}
        for role, rel in (("acceptance.json", "calibration/acceptance.json"), ("array.json", "calibration/array.json")):
            if (folder / rel).is_file():
                files[role] = _read(folder / rel, role)
        spec_sha = str(manifest.get("spec_sha256") or rec.sha256_hex(spec_raw))
        adopted = measured_calibrations(folder, taxels, design)
        info = {"spec_name": spec.get("name"), "spec_sha256": spec_sha, "design_sha256": rec.sha256_hex(design_raw),
                "magfab_version": manifest.get("magfab_version", __version__), "taxels": taxels, "build": str(folder)}
        when = rec.parse_date(date) if date else rec.now_utc()
        sensor = rec.create(root, sensor_id, info, files, date=when,
                            then=[("calibration", a.data, a.files) for a in adopted])
        return sensor, len(adopted)


# ---- reading a record back -----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Row:
    """One event as the history shows it."""

    number: int
    date: str
    kind: str
    epoch: int
    taxel: int | None
    figures: str


def _g(x: object, unit: str = "", digits: int = 4) -> str:
    if not isinstance(x, (int, float)) or isinstance(x, bool):
        return "-"
    return f"{x:.{digits}g}{unit}"


def _figures(event: Mapping[str, Any]) -> str:
    kind = event["kind"]
    if kind == "added":
        return f"design {event.get('spec_name')} (spec {str(event.get('spec_sha256', ''))[:12]})"
    if kind == "calibration":
        rest = event.get("rest_field_uT") or [None] * 3
        text = (f"Fz {_g(event.get('rms_holdout_Fz_mN'), ' mN', 3)}, Fr {_g(event.get('rms_holdout_Fr_mN'), ' mN', 3)}"
                f" held out; Bz rest {_g(rest[2], ' uT', 6)}; S {_g(event.get('sensitivity_normal_uT_per_N'))}/"
                f"{_g(event.get('sensitivity_shear_uT_per_N'))} uT/N; range {_g(event.get('range_normal_N'), '', 3)}/"
                f"{_g(event.get('range_shear_N'), ' N', 3)}")
        return text + (" (provisional)" if event.get("provisional") else "")
    if kind in ("check", "drift"):
        figures = event.get("figures") or {}
        shown = [f"Bz rest {_g(check_rest_uT(event), ' uT', 6)}"] if check_rest_uT(event) is not None else []
        if isinstance(figures.get("Bz_rise_uT"), (int, float)):
            shown.append(f"rise {_g(figures['Bz_rise_uT'], ' uT')} under {_g(figures.get('weight_g'), ' g')}")
        if check_error_mN(event) is not None:
            shown.append(f"error {_g(check_error_mN(event), ' mN', 3)} turned over or warmed")
        return f"{str(event.get('verdict', '?')).upper()}" + (f": {', '.join(shown)}" if shown else "")
    if kind == "upload":
        return f"calibration {str(event.get('calibration_sha256', ''))[:12]} to the board"
    return str(event.get("note") or event.get("text") or "")


def history(sensor: rec.Sensor) -> list[Row]:
    """Every event of the record, oldest first, with the skin epoch it belongs to."""
    rows, epoch = [], 0
    with records_checked():
        for event in sensor.events():
            epoch += event["kind"] == "reskin"
            rows.append(Row(event["number"], str(event.get("date", "")), event["kind"], epoch, event.get("taxel"),
                            _figures(event)))
    return rows


def summary(sensor: rec.Sensor) -> dict[str, Any]:
    """One line's worth of a sensor (``magfab sensor list``): design, skin epoch, calibrations and checks counted,
    the last calibration's date and held-out error, the last check's verdict."""
    with records_checked():
        events = sensor.events()
        info = sensor.info
    calibrations = [e for e in events if e["kind"] == "calibration"]
    checks = [e for e in events if e["kind"] in ("check", "drift")]
    last = calibrations[-1] if calibrations else {}
    return {"id": sensor.id, "design": info.get("spec_name"), "epoch": sum(e["kind"] == "reskin" for e in events),
            "calibrations": len(calibrations), "checks": len(checks), "last_calibration": last.get("date"),
            "last_rms_holdout_Fz_mN": last.get("rms_holdout_Fz_mN"),
            "last_check": checks[-1].get("verdict") if checks else None}


# ---- a new skin against the old one ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Comparison:
    """One quantity of the newest calibration of the skin in use against the last one of the skin before it.

    ``allowed`` is the largest change the design's bands explain (in ``unit``); ``band`` the design's band of the
    value itself, when acceptance.json gives one; ``flagged`` says the change, or the new value, is beyond them."""

    taxel: int | None
    quantity: str
    unit: str
    before: float
    after: float
    allowed: float
    band: tuple[float, float] | None
    flagged: bool

    @property
    def line(self) -> str:
        where = "" if self.taxel is None else f"taxel {self.taxel}: "
        change = self.after - self.before
        text = (f"{where}{self.quantity} {self.before:.5g} -> {self.after:.5g} {self.unit} ({change:+.4g}, "
                f"{100.0 * change / self.before if self.before else math.inf:+.1f} %)")
        if not self.flagged:
            return f"{text}: within the design's bands"
        if self.band is not None and not self.band[0] <= self.after <= self.band[1]:
            return (f"{text}: CHANGED beyond the design's bands: the new value is outside "
                    f"{self.band[0]:.5g}-{self.band[1]:.5g} {self.unit}")
        return f"{text}: CHANGED beyond the design's bands, which allow {self.allowed:.4g} {self.unit}"


def bands(sensor: rec.Sensor) -> dict[str, Any]:
    """The design's acceptance bands the record keeps (acceptance.json of its added event), or {}."""
    added = next((e for e in sensor.events() if e["kind"] == "added"), {})
    sha = added.get("files", {}).get("acceptance.json")
    if not sha:
        return {}
    with records_checked():
        data = sensor.json_file(sha, "acceptance.json")
    if not isinstance(data, dict):
        raise SensorError(f"acceptance.json of {sensor.id} = {sha}: is kept in the record but is not a JSON object")
    return data


def _limits(bands: Mapping[str, Any]) -> dict[str, tuple[float, tuple[float, float] | None]]:
    """{quantity: (allowed change, band or None)} from acceptance.json (docs/sensors.md section 5): the rest field's
    band, the lateral rest field's limit, and the rise under the known weight as a sensitivity band; the shear
    sensitivity and the ranges, which acceptance.json gives no band of, may change by the normal sensitivity band's
    relative width (the silicone's stiffness band drives them all)."""
    out: dict[str, tuple[float, tuple[float, float] | None]] = {}
    rest = bands.get("rest", {})
    bz = rest.get("Bz_uT", {})
    if {"min", "max"} <= set(bz):
        out["rest Bz"] = (bz["max"] - bz["min"], (bz["min"], bz["max"]))
    if "Bxy_max_uT" in rest:
        out["rest Bxy"] = (rest["Bxy_max_uT"], (0.0, rest["Bxy_max_uT"]))
    weight = bands.get("weight", {})
    rise, force = weight.get("delta_Bz_uT", {}), weight.get("force_N")
    if {"min", "max", "nominal"} <= set(rise) and force:
        lo, hi = rise["min"] / force, rise["max"] / force
        out["normal sensitivity"] = (hi - lo, (lo, hi))
        out["relative"] = ((rise["max"] - rise["min"]) / rise["nominal"], None)
    return out


def _values(event: Mapping[str, Any]) -> dict[str, tuple[float | None, str]]:
    rest = event.get("rest_field_uT") or [None, None, None]
    bxy = math.hypot(rest[0], rest[1]) if None not in rest[:2] else None
    return {"rest Bz": (rest[2], "uT"), "rest Bxy": (bxy, "uT"),
            "normal sensitivity": (event.get("sensitivity_normal_uT_per_N"), "uT/N"),
            "shear sensitivity": (event.get("sensitivity_shear_uT_per_N"), "uT/N"),
            "normal range": (event.get("range_normal_N"), "N"), "shear range": (event.get("range_shear_N"), "N")}


def comparisons(sensor: rec.Sensor) -> list[Comparison]:
    """For each taxel whose skin in use has a calibration and whose previous skin had one: the newest of each,
    quantity by quantity, flagged when the change is beyond what the design's bands predict (empty before a
    re-skin, or when the record keeps no acceptance bands)."""
    with records_checked():
        epoch = sensor.epoch()
        if epoch == 0:
            return []
        limits = _limits(bands(sensor))
        taxels = sorted({e.get("taxel") for e in sensor.events() if e["kind"] == "calibration"},
                        key=lambda t: -1 if t is None else t)
        out = []
        for taxel in taxels:
            cals = list(sensor.calibrations(taxel))
            now = [c for c in cals if c["epoch"] == epoch]
            then = [c for c in cals if c["epoch"] == epoch - 1]
            if now and then:
                out += _compare(taxel, then[-1], now[-1], limits)
        return out


def _compare(taxel: int | None, before: Mapping[str, Any], after: Mapping[str, Any],
             limits: Mapping[str, tuple[float, tuple[float, float] | None]]) -> list[Comparison]:
    out = []
    old, new = _values(before), _values(after)
    for quantity, (a, unit) in old.items():
        b = new[quantity][0]
        if a is None or b is None:
            continue
        if quantity in limits:
            allowed, band = limits[quantity]
        elif "relative" in limits:
            allowed, band = limits["relative"][0] * abs(a), None
        else:
            continue
        outside = band is not None and not band[0] <= b <= band[1]
        out.append(Comparison(taxel, quantity, unit, float(a), float(b), float(allowed), band,
                              abs(b - a) > allowed or outside))
    return out
