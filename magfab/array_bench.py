"""Calibrating an array on the bench, one taxel at a time: ``magfab calibrate REC.csv --reference REF.csv --taxel K``
fits taxel K to its rows of the recording, and every other taxel keeps the scan it was fitted to, which the build
folder holds (``calibration/scan_taxel_NN.csv`` for a measured one; a taxel never measured keeps its simulated
scan, made again by the build)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from .errors import SpecError, shown
from .formats import bounded
from .formats.array_json import ArrayError
from .formats.array_json import validate as validate_array
from .formats.scan_csv import read_scan_csv
from .models.scan_guards import reject_self_calibrated_file

if TYPE_CHECKING:
    from .formats.scan_csv import Scan
    from .spec import Spec

__all__ = ["check_taxel", "taxel_scans", "measured_scan_path"]


def measured_scan_path(k: int) -> str:
    """Where a build keeps taxel k's measured scan (relative to the build folder)."""
    return f"calibration/scan_taxel_{k:02d}.csv"


def check_taxel(spec: Spec, taxel: int | None) -> None:
    """``--taxel`` is required for an array, refused for a single taxel, and must name one of the array's."""
    if spec.array is None:
        raise SpecError("--taxel", shown(taxel), f"the build {spec.name!r} is a single taxel", "omit --taxel")
    n = spec.array.taxels
    if taxel is None:
        raise SpecError("--taxel", "<missing>",
                        f"the build {spec.name!r} is an array of {n} taxels: give the taxel the "
                        f"scan pressed, 0 to {n - 1} (the address plan in checklist.md)")
    if taxel >= n:
        raise SpecError("--taxel", shown(taxel), f"must be 0 to {n - 1} for the {n} taxels of {spec.name!r}")


def _offsets(layout: Path) -> list:
    """Each chip's neighbours' field at rest (``offset_uT``) of the build's array.json, validated as the host
    validates it (:mod:`magfab.formats.array_json`): :class:`ArrayError` (exit 2, one line) for a file that is not
    the format's."""
    try:
        array = bounded.loads_json(bounded.read_bytes(layout, "array.json"), "array.json", layout)
    except bounded.InputFileError:
        raise
    except ValueError as exc:  # json's error, or UnicodeDecodeError
        raise ArrayError("", str(layout), f"is not valid JSON ({exc})") from None
    return validate_array(array).offset


def taxel_scans(folder: Path | None, spec: Spec, taxel: int, scan: Scan) -> dict[int, Scan]:
    """{k: scan} for the build: ``scan`` for ``taxel`` (refused by guard B when its forces are the sensor's own,
    compared with the taxel's present calibration on the field with the neighbours' removed), and the measured
    scans the folder keeps for the others."""

    scans = {}
    if folder is not None:
        for k in range(spec.array.taxels if spec.array is not None else 1):
            path = folder / measured_scan_path(k)
            if k != taxel and path.is_file():
                scans[k] = replace(read_scan_csv(path), source=path.name)
        present = folder / "calibration" / f"taxel_{taxel:02d}.json"
        layout = folder / "calibration" / "array.json"
        if present.is_file() and layout.is_file():
            offset = _offsets(layout)
            if taxel >= len(offset):
                raise ArrayError("offset_uT", f"{len(offset)} taxels", f"must hold taxel {taxel} of the spec's array "
                                 f"({layout}); rebuild the folder")
            offset = offset[taxel]
            reject_self_calibrated_file(replace(scan, B_uT=scan.B_uT - offset), present,
                                        spec.calibration.reference_resolution_mN)
    scans[taxel] = scan
    return dict(sorted(scans.items()))
