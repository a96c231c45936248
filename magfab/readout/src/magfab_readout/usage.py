"""The readout's refusal of what was asked (exit 2, one line): its own module, standard library only, so that the
modules magfab shares (record_formats) raise it without the build's data that ``cli_shared`` reads."""

from __future__ import annotations

__all__ = ["UsageError"]


class UsageError(ValueError):
    """A bad option value, or a command that would write the wrong thing (exit status 2, nothing written)."""
