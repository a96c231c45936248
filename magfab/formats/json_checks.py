"""What the JSON format validators share (:class:`FormatError`, the checks of one value): the readout package's
module (``magfab/readout/src/magfab_readout/json_checks.py``), the one copy, which every build ships verbatim.
Inside magfab its errors are :class:`~magfab.errors.CalibrationFormatError`."""

from ..readout.src.magfab_readout.json_checks import FormatError, finite, is_finite, is_number, lookup

__all__ = ["FormatError", "is_number", "is_finite", "lookup", "finite"]
