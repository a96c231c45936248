"""acceptance.json (format ``magfab-acceptance/1``): the one validator is the readout package's module
(``magfab/readout/src/magfab_readout/acceptance_json.py``), which every build ships verbatim and its ``check``
command runs."""

from ..readout.src.magfab_readout.acceptance_json import (
    FORMAT,
    KEYS,
    SECTIONS,
    AcceptanceError,
    drift_flags,
    loads,
    validate,
)

__all__ = ["FORMAT", "KEYS", "SECTIONS", "AcceptanceError", "drift_flags", "loads", "validate"]
