"""TOML input files read within bounds: the file's type and size, the nesting scanned before tomllib (which recurses
once per level) and the parsed document's depth and keys per table checked before any validation
(``magfab_readout.bounded``, docs/bundle.md section 6). Used by the spec and the targets readers."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from .errors import SpecError
from .readout.src.magfab_readout import bounded

__all__ = ["loads_toml", "read_toml"]


def read_toml(path: Path, what: str) -> str:
    """The text of the TOML file ``path``: a regular file within ``what``'s size limit (:mod:`bounded`), UTF-8;
    :class:`SpecError` naming ``what`` when it cannot be read."""
    try:
        return bounded.read_text(path, what)
    except FileNotFoundError:
        raise SpecError(what, str(path), "file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(what, str(path), f"cannot read it as UTF-8 text: {exc}") from None


def loads_toml(text: str, what: str, where: str) -> dict[str, Any]:
    """``tomllib.loads(text)`` with the bounds of :mod:`bounded` around it: the nesting scanned before the recursive
    parser runs, the parsed document's depth and keys per table checked before any validation; tomllib's errors
    (TOMLDecodeError, ValueError) pass through."""
    bounded.check_toml(text, what, where)
    try:
        raw = tomllib.loads(text)
    except RecursionError:  # unreachable after check_toml; kept so the parser never ends in a traceback
        raise bounded.InputFileError(what, where, f"nests more than {bounded.MAX_DEPTH} deep") from None
    bounded.check_tree(raw, what, where)
    return raw
