"""array.json (format ``magfab-array/1``, docs/bundle.md section 5): the one validator and the one compensation
are the readout package's module (``magfab/readout/src/magfab_readout/array_json.py``), which every build ships
verbatim, so the build's tests and the host compute the same numbers."""

from ..readout.src.magfab_readout.array_json import FORMAT, ArrayError, Compensator, validate

__all__ = ["FORMAT", "ArrayError", "Compensator", "validate"]
