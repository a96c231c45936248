"""What the JSON format validators share: the error naming file, key path, value and what is allowed, and the
checks of one value.

Standard library only, and no import of magfab outside this folder: this module, calibration_json.py and
acceptance_json.py are copied byte for byte into every build's readout package, so the build and the host
refuse exactly the same files.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # typing.TypeGuard is new in 3.10; the readout runs from 3.8, where this is never imported
    from typing import TypeGuard

# This file is type-checked twice: inside magfab, where the import resolves and the fallback's type differs, and
# in the readout package as shipped, where there is no parent package; each ignore is for one of the two.
try:  # inside magfab: an InputError (exit 2); in the readout package, where magfab.errors is absent: ValueError
    from ..errors import CalibrationFormatError as _Base  # type: ignore[import-not-found, unused-ignore]
except (ImportError, ValueError):  # Python 3.8 raises ValueError for a relative import above the top package
    _Base = ValueError  # type: ignore[misc, assignment, unused-ignore]

__all__ = ["FormatError", "is_number", "lookup", "finite"]


class FormatError(_Base):
    """A file that does not hold what its format requires: ``file``, the dotted ``key`` path inside it (empty for
    the whole document), the offending ``value`` and what is ``allowed``."""

    file = "a JSON file"

    def __init__(self, key: str, value: object, allowed: str) -> None:
        self.key = key
        self.value = value
        self.allowed = allowed
        shown = repr(value)
        if len(shown) > 80:
            shown = shown[:77] + "..."
        super().__init__("{}: {} = {}: {}".format(self.file, key or "(top level)", shown, allowed))


def is_number(x: object) -> TypeGuard[int | float]:
    """A JSON number (bool is not one)."""
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def lookup(data: dict, path: str, error: type) -> object:
    """The value at the dotted ``path``; ``error(path, None, "is missing")`` where a step is absent."""
    node: object = data
    for part in path.split("."):
        if not isinstance(node, dict) or part not in node:
            raise error(path, None, "is missing")
        node = node[part]
    return node


def finite(data: dict, path: str, error: type, *, positive: bool = False, nonnegative: bool = False) -> float:
    """The finite number at the dotted ``path`` (optionally > 0 or >= 0), else ``error`` naming the path."""
    node = lookup(data, path, error)
    if not is_number(node) or not math.isfinite(node):
        raise error(path, node, "must be a finite number")
    if positive and not node > 0:
        raise error(path, node, "must be greater than 0")
    if nonnegative and node < 0:
        raise error(path, node, "must be at least 0")
    return float(node)
