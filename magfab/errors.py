"""The one error type for bad input, and the finding record for design checks."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class SpecError(ValueError):
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
        text = f"{self.key} = {_show(self.value)}: {self.allowed}"
        return f"{text} ({self.hint})" if self.hint else text


def _show(value: object) -> str:
    if isinstance(value, str):
        return repr(value)
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


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


class BuildError(RuntimeError):
    """Error-level findings stopped the build (exit 2: the spec asks for something we will not make)."""

    def __init__(self, findings: list[Finding]) -> None:
        self.findings = findings
        first = findings[0]
        where = f"{first.key}: " if first.key else ""
        more = f" (and {len(findings) - 1} more error(s))" if len(findings) > 1 else ""
        super().__init__(f"{where}{first.message}{more}")
