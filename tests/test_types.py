"""mypy finds nothing in the readout package's source tree, which every build ships verbatim, checked against the
oldest Python mypy knows (the test command's own `mypy` checks magfab, as pyproject.toml's [tool.mypy] says).

The cache lives in .mypy_cache at the top of the checkout (ignored by git): a cold check takes about a minute,
a check after a small change a few seconds."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from magfab.export.readout import PACKAGE

ROOT = Path(__file__).resolve().parents[1]
CACHE = ROOT / ".mypy_cache"
# The oldest Python mypy can check for: the readout runs on 3.8 (ruff holds its syntax to that), and checking
# it against 3.10's standard library still catches the newer names (tomllib, typing.Self, ...) it must not use.
READOUT_PYTHON = "3.10"


def _mypy(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "mypy", "--config-file", str(ROOT / "pyproject.toml"),
                           "--cache-dir", str(CACHE), *args], cwd=cwd, capture_output=True, text=True, timeout=600)


def test_readout_package_type_checks():
    """The package's source tree, which a build copies verbatim (its data files are not code)."""
    proc = _mypy("--python-version", READOUT_PYTHON, PACKAGE, cwd=ROOT / "magfab" / "readout" / "src")
    assert proc.returncode == 0, proc.stdout[-6000:] + proc.stderr[-2000:]
