"""What the JSON format validators share: the error naming file, key path, value and what is allowed, and the
checks of one value.

Standard library only: this module and the validators beside it (calibration_json.py, acceptance_json.py,
array_json.py) are the readout package's own, shipped verbatim in every build, and magfab imports the same files
(``magfab.formats``), so the build and the host refuse exactly the same files.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # typing.TypeGuard is new in 3.10; the readout runs from 3.8, where this is never imported
    from typing import TypeGuard

if __name__.startswith("magfab."):  # magfab's import of this file (magfab.formats): an InputError, exit 2
    from magfab.errors import CalibrationFormatError as _Base
else:  # the readout package on the user's Python, where magfab is not needed
    _Base = ValueError  # type: ignore[misc, assignment]

__all__ = ["FormatError", "is_number", "is_finite", "lookup", "finite"]


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


def is_finite(x: object) -> TypeGuard[int | float]:
    """A JSON number a float holds finitely: not NaN or infinity, and not an integer too large for a float (JSON
    allows 10**400 written out in digits, where ``math.isfinite`` raises OverflowError)."""
    if not is_number(x):
        return False
    try:
        return math.isfinite(x)
    except OverflowError:
        return False


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
    if not is_finite(node):
        raise error(path, node, "must be a finite number")
    if positive and not node > 0:
        raise error(path, node, "must be greater than 0")
    if nonnegative and node < 0:
        raise error(path, node, "must be at least 0")
    return float(node)
