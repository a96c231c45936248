"""Every error magfab raises, in one tree, and the finding record for design checks.

    MagfabError                    the root: everything magfab raises on purpose derives from it
    +-- InputError (ValueError)    the user's input or environment is at fault: exit 2, one line
    |   +-- SpecError              a spec key: its path, value and what is allowed
    |   +-- BuildError             error-level findings stopped the build
    |   +-- OutputError            the output folder cannot be used
    |   +-- ScanError              a scan CSV that cannot be read or calibrated on
    |   +-- CalibrationFormatError a calibration.json (or acceptance.json) that does not hold what it must
    +-- ModelLimitError (ValueError)  a model asked where it is known to fail (inside the magnet, past an
    |                              error estimate, an inverted FE element): predict turns it into a finding
    +-- ToolError (RuntimeError)   an external tool (KiCad, avr-gcc, gcc, simavr) ran and failed on what we
                                   gave it: our bug, exit 1

The CLI maps these types to exit codes (InputError 2, anything else 1, an interrupt 130); nothing else
decides by class name or catches broadly.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class MagfabError(Exception):
    """The root of every error magfab raises on purpose."""


class InputError(MagfabError, ValueError):
    """The user's input or environment is at fault (exit 2): the message names what and what is allowed."""


class ModelLimitError(MagfabError, ValueError):
    """A model was asked for a point or load where it is known to fail; callers turn it into a finding."""


class ToolError(MagfabError, RuntimeError):
    """An external tool ran and failed on what magfab gave it (exit 1: a bug of ours, not of the input)."""


class SpecError(InputError):
    """An invalid or infeasible spec.

    Carries the dotted key path, the offending value and what is allowed, so the CLI can print
    one line that a user can act on. Exit code 2.
    """

    def __init__(self, key: str, value: object, allowed: str, hint: str = "") -> None:
        self.key = key
        self.value = value
        self.allowed = allowed
        self.hint = hint
        super().__init__(self.message)

    @property
    def message(self) -> str:
        text = f"{self.key} = {shown(self.value)}: {self.allowed}"
        return f"{text} ({self.hint})" if self.hint else text


#: Longest value an error line shows whole; longer ones are cut in the middle with their length.
SHOWN_MAX_CHARS = 60


class _Shown:
    """A value as an error line shows it: exact (floats by their shortest round-trip repr, so a value just past
    a bound is not printed as the bound) and bounded in length. ``raw`` is the value itself."""

    def __init__(self, raw: object) -> None:
        self.raw = raw
        if isinstance(raw, bool):
            text = "true" if raw else "false"
        elif isinstance(raw, (float, str)):
            text = repr(raw)
        else:
            text = str(raw)
        self.text = shorten(text)

    def __str__(self) -> str:
        return self.text

    __repr__ = __str__

    def __eq__(self, other: object) -> bool:
        return self.raw == (other.raw if isinstance(other, _Shown) else other)

    __hash__ = None  # type: ignore[assignment]  # unhashable, the documented way; typeshed types __hash__ as a method


def shorten(text: str, limit: int = SHOWN_MAX_CHARS) -> str:
    if len(text) <= limit:
        return text
    keep = (limit - 5) // 2
    return f"{text[:keep]}...{text[-keep:]} ({len(text)} characters)"


def shown(value: object) -> _Shown:
    """``value`` for a :class:`SpecError`: exact and at most about :data:`SHOWN_MAX_CHARS` characters."""
    return value if isinstance(value, _Shown) else _Shown(value)


def number_text(x: float) -> str:
    """A number for a message: an int with thousands separators; a float exact to 1e-9 without float noise (a
    derived bound prints '6' for 6.0 and '6.0004' for 6.0004, a suggested value '0.0012' for 0.0012000000000000001),
    whole and with separators from 10,000 up."""
    if isinstance(x, int):
        return f"{x:,}"
    r = round(x, 9) + 0.0
    if abs(r) >= 1e4:
        return f"{r:,.0f}"
    return str(int(r)) if r.is_integer() else repr(r)


class Severity(str, Enum):
    """How bad a finding is: errors stop a build, warnings are reported."""

    ERROR = "error"
    WARNING = "warning"
    INFO = "info"


@dataclass(frozen=True)
class Finding:
    """One result of a design or mesh check.

    ``key`` is the spec key a user would change to fix it (empty for checks on our own output).
    """

    severity: Severity
    code: str
    message: str
    key: str = ""

    def as_dict(self) -> dict[str, str]:
        return {"severity": self.severity.value, "code": self.code, "message": self.message, "key": self.key}


class BuildError(InputError):
    """Error-level findings stopped the build (exit 2: the spec asks for something we will not make)."""

    def __init__(self, findings: list[Finding]) -> None:
        self.findings = findings
        first = findings[0]
        where = f"{first.key}: " if first.key else ""
        more = f" (and {len(findings) - 1} more error(s))" if len(findings) > 1 else ""
        super().__init__(f"{where}{first.message}{more}")


class OutputError(InputError):
    """The output directory cannot be used: e.g. it exists and is not a previous magfab build."""


class ScanError(InputError):
    """A scan CSV that cannot be read, or that does not span what a calibration needs."""


class CalibrationFormatError(InputError):
    """A calibration.json or acceptance.json that does not hold what its format requires."""
