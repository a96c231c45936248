"""calibration.json (format ``magfab-calibration/1``, docs/bundle.md section 2): the one validator is the readout
package's module (``magfab/readout/src/magfab_readout/calibration_json.py``), which every build ships verbatim,
so magfab and the host refuse exactly the same files."""

from ..readout.src.magfab_readout.calibration_json import (
    AXES,
    FORCE_MAX_N,
    FORCES,
    FORMAT,
    INPUT_MAX,
    INPUTS,
    MAX_ORDER,
    MLS_MAX_ORDER,
    MLS_MIN_BANDWIDTH,
    THERMAL_MAX_PER_C,
    THERMAL_MIN_DENOMINATOR,
    THERMAL_REFERENCE_C,
    CalibrationError,
    Checked,
    MLSPoints,
    Thermal,
    calibration_sha256,
    canonical_json,
    check_formula,
    cross,
    loads,
    monomials,
    region_box,
    validate,
)

__all__ = ["FORMAT", "FORCES", "INPUTS", "MAX_ORDER", "MLS_MAX_ORDER", "AXES", "THERMAL_MAX_PER_C",
           "THERMAL_REFERENCE_C", "THERMAL_MIN_DENOMINATOR", "INPUT_MAX", "FORCE_MAX_N", "MLS_MIN_BANDWIDTH",
           "CalibrationError", "Checked", "MLSPoints", "Thermal",
           "calibration_sha256", "canonical_json", "check_formula", "cross", "loads", "monomials", "region_box",
           "validate"]
