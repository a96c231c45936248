"""Input files read safely (type, size, nesting depth, keys): the one implementation is the readout package's module
(``magfab/readout/src/magfab_readout/bounded.py``), so magfab and ``magfab-readout`` refuse the same files. Inside
magfab its :class:`InputFileError` is an :class:`~magfab.errors.InputError` (exit 2, one line); TOML is parsed
through :func:`magfab.spec.loads_toml`, which runs these checks around tomllib."""

from ..readout.src.magfab_readout.bounded import (
    LIMITS,
    MAX_DEPTH,
    MAX_KEYS,
    InputFileError,
    check_toml,
    check_tree,
    loads_json,
    read_bytes,
    read_text,
    size_text,
)

__all__ = ["LIMITS", "MAX_DEPTH", "MAX_KEYS", "InputFileError", "check_toml", "check_tree", "loads_json", "read_bytes",
           "read_text", "size_text"]
