"""Which findings stop a build."""

from __future__ import annotations

from ..errors import Finding, Severity

__all__ = ["errors_in"]


def errors_in(findings: list[Finding], strict: bool = False) -> list[Finding]:
    """The findings that stop a build (warnings too when ``strict``)."""
    stop = {Severity.ERROR, Severity.WARNING} if strict else {Severity.ERROR}
    return [f for f in findings if f.severity in stop]
