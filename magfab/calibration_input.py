"""What `magfab calibrate` fits: a scan (a file, or a recording merged with a reference log) or, with ``--weights``,
the scan of the sensor's model fitted to known weights (:mod:`magfab.models.weighing`)."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any

from .errors import ScanError

# Part of the command line: magfab's own modules are imported lazily, inside the functions, so that `magfab --help`
# stays fast (as in magfab.cli).

__all__ = ["read_scan", "weights_scan", "kept_from_record"]


def read_scan(scan_path: Path, reference: Path | None, build_dir: Path | None, spec, taxel: int | None = None,
              weights: bool = False, kept: dict[str, float] | None = None):
    """The scan to fit: the file, or a recording merged with the reference sensor's log; refused when its
    forces are the sensor's own (a recording calibrated against itself: by their names in the reader, by their
    values against the build's present calibration here). For an array, {taxel: scan} with the scans the build
    folder's other taxels were fitted to (:func:`magfab.array_bench.taxel_scans`). ``weights``: ``scan_path`` is a
    weighings CSV (:func:`weights_scan`, ``kept`` the parameters a new skin keeps)."""
    from .formats.scan_csv import read_recording, read_scan_csv
    from .models.scan_guards import merge_reference

    if weights:
        return weights_scan(scan_path, spec, kept)
    if spec.array is not None or taxel is not None:
        from .array_bench import check_taxel

        check_taxel(spec, taxel)
    if reference is not None:
        scan = merge_reference(read_recording(scan_path, taxel), reference, spec.calibration.reference_resolution_mN)
    else:
        scan = read_scan_csv(scan_path, taxel=taxel)
    folder = None if build_dir is None else Path(build_dir)
    if spec.array is not None:
        from .array_bench import taxel_scans

        assert taxel is not None  # check_taxel refused an array's scan that names no taxel
        return taxel_scans(folder, spec, taxel, scan)
    present = None if folder is None else folder / "calibration" / "calibration.json"
    if present is not None and present.is_file():
        from .models.scan_guards import reject_self_calibrated_file

        reject_self_calibrated_file(scan, present, spec.calibration.reference_resolution_mN)
    return scan


def weights_scan(path: Path, spec, kept: dict[str, float] | None = None):
    """The model scan of a weight calibration: the weighings of ``path`` read, the design's model fitted to them
    (``kept`` held), and its scan with the fit and the predicted error
    (:func:`magfab.models.weighing.calibration_scan`).
    An array is refused: its taxels press on each other, which the model of one taxel does not hold."""
    from .check import preflight
    from .design import derive
    from .formats import bounded
    from .formats.weights_csv import read_weights_csv
    from .models.predict import predict
    from .models.weighing import calibration_scan

    if spec.array is not None:
        raise ScanError(f"{path.name}: a weight calibration is of a single taxel's sensor; an array's taxels are "
                        "calibrated from scans (magfab calibrate SCAN --taxel K)")
    weighings = read_weights_csv(path)  # its errors name the file
    raw = bounded.read_bytes(path, "weighings CSV")
    design = preflight(derive(spec))
    scan, _, _ = calibration_scan(design, predict(design), weighings, fixed=kept, source=path.name,
                                  sha256=hashlib.sha256(raw).hexdigest())
    return scan


def kept_from_record(sensor: Any) -> dict[str, float] | None:
    """For a sensor on a new skin with no calibration yet (a ``reskin`` event since its last one), the parameters a
    new skin keeps (:data:`magfab.models.weighing.RESKIN_KEPT`) from its newest weight calibration of an earlier skin;
    None when the skin in use has a calibration already, or no earlier one was a weight calibration (a full fit)."""
    from .formats import sensor_records as records
    from .models.weighing import RESKIN_KEPT, weight_fit_of

    epoch = sensor.epoch()
    found = list(sensor.calibrations(None))
    if epoch == 0 or any(e["epoch"] == epoch for e in found):
        return None
    for event in reversed(found):
        sha = event["files"].get("calibration.json")
        try:
            doc = sensor.json_file(sha, "calibration.json") if sha else None
        except records.RecordError:
            continue
        theta = (weight_fit_of(doc) or {}).get("theta") if isinstance(doc, dict) else None
        if isinstance(theta, dict) and all(isinstance(theta.get(k), (int, float)) for k in RESKIN_KEPT):
            return {k: float(theta[k]) for k in RESKIN_KEPT}
    return None
