"""Shared fixtures. Tests that need a Debian tool call :func:`require_tool`: it skips with a reason when
the tool is missing, and fails instead when MAGFAB_REQUIRE_TOOLS=1 (set by .ci/run), so CI always runs them."""

from __future__ import annotations

import os
import shutil

import pytest

from magfab import build, load_spec


def require_tool(name: str) -> str:
    path = shutil.which(name)
    if path:
        return path
    reason = f"{name} is not installed (Debian package; .ci/run installs it)"
    if os.environ.get("MAGFAB_REQUIRE_TOOLS") == "1":
        pytest.fail(f"MAGFAB_REQUIRE_TOOLS=1 but {reason}")
    pytest.skip(reason)


@pytest.fixture(scope="session")
def default_build(tmp_path_factory):
    """The default (MagOne) build, written once per session."""
    out = tmp_path_factory.mktemp("default") / "magone"
    return build(load_spec(None), out)
