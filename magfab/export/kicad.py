"""Calling KiCad itself: find an interpreter that can ``import pcbnew`` and run :mod:`magfab.export.kicad_tool`
in it as a subprocess (KiCad's Python module lives in the system interpreter, not in our venv).

``MAGFAB_KICAD_PYTHON`` names the interpreter explicitly; otherwise the Debian location of KiCad's
``pcbnew`` (the system ``python3``) is tried, then the running interpreter.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from functools import cache
from pathlib import Path

from ..errors import ToolError

__all__ = ["kicad_python", "run_tool", "plot_gerbers", "KicadError", "normalise_plot"]

TOOL = Path(__file__).with_name("kicad_tool.py")
TIMEOUT_S = 300
FIXED_DATE = "2000-01-01T00:00:00+00:00"


class KicadError(ToolError):
    """KiCad failed on what we gave it (exit 1). Callers test ``kicad_python() is None`` first: a missing
    KiCad is a skip or a finding, not this error."""


@cache
def kicad_python() -> str | None:
    """Path of an interpreter that imports ``pcbnew``, or None when KiCad is not installed."""
    candidates = [os.environ.get("MAGFAB_KICAD_PYTHON"), "/usr/bin/python3", sys.executable]
    for exe in candidates:
        if not exe or not os.path.exists(exe):
            continue
        try:
            ok = subprocess.run([exe, "-c", "import pcbnew"], capture_output=True, timeout=60).returncode == 0
        except (OSError, subprocess.TimeoutExpired):
            ok = False
        if ok:
            return exe
    return None


def run_tool(*args: str) -> str:
    """Run a ``kicad_tool.py`` command; returns its stdout (JSON for most commands)."""
    exe = kicad_python()
    if exe is None:
        raise KicadError("KiCad's pcbnew Python module was not found (Debian package 'kicad')")
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE="1")
    proc = subprocess.run([exe, str(TOOL), *args], capture_output=True, text=True, timeout=TIMEOUT_S, env=env)
    if proc.returncode != 0:
        tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
        raise KicadError(f"KiCad {args[0]} failed: " + " | ".join(tail))
    return proc.stdout


_DATES = (
    (re.compile(rb"(%TF\.CreationDate,)[^*]*"), rb"\g<1>" + FIXED_DATE.encode()),
    (re.compile(rb"(G04 Created by KiCad \([^)]*\) date )[^*]*"), rb"\g<1>" + FIXED_DATE.encode()),
    (re.compile(rb"(; #@! TF\.CreationDate,)[^\n]*"), rb"\g<1>" + FIXED_DATE.encode()),
    (re.compile(rb"(; ?DRILL file \{[^}]*\} date )[^\n]*"), rb"\g<1>" + FIXED_DATE.encode()),
)


def normalise_plot(data: bytes) -> bytes:
    """Pin the creation dates KiCad writes into Gerber and Excellon headers, so builds are reproducible."""
    for pattern, repl in _DATES:
        data = pattern.sub(repl, data)
    return data


def plot_gerbers(board_files: dict[str, bytes], board_name: str) -> dict[str, bytes]:
    """Gerbers and drill files for a board (relative name -> bytes), plotted by KiCad.

    ``board_files`` are the board's files as :func:`magfab.pcb.files` renders them; they are written
    to a scratch directory because KiCad reads the board and its project file from disk.
    """
    with tempfile.TemporaryDirectory(prefix="magfab-kicad-") as tmp:
        root = Path(tmp)
        for rel, data in board_files.items():
            path = root / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        out = root / "gerbers"
        out.mkdir()
        names = json.loads(run_tool("plot", str(root / f"{board_name}.kicad_pcb"), str(out)))
        return {name: normalise_plot((out / name).read_bytes()) for name in names}
