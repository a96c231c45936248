"""calibration.json (format ``magfab-calibration/1``, docs/bundle.md section 2): the one validator is the readout
package's module (``magfab/readout/src/magfab_readout/calibration_json.py``), which every build ships verbatim,
so magfab and the host refuse exactly the same files."""

from ..readout.src.magfab_readout.calibration_json import (
    AXES,
    FORCES,
    FORMAT,
    INPUTS,
    MAX_ORDER,
    MLS_MAX_ORDER,
    THERMAL_MAX_PER_C,
    CalibrationError,
    Checked,
    MLSPoints,
    Thermal,
    calibration_sha256,
    canonical_json,
    cross,
    loads,
    monomials,
    validate,
)

__all__ = ["FORMAT", "FORCES", "INPUTS", "MAX_ORDER", "MLS_MAX_ORDER", "AXES", "THERMAL_MAX_PER_C", "CalibrationError",
           "Checked", "MLSPoints", "Thermal",
           "calibration_sha256", "canonical_json", "cross", "loads", "monomials", "validate"]
