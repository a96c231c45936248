"""The README's first command, as a new user runs it: a fresh virtual environment, `pip install .` of a clean
copy of the repository (what a fresh clone holds), and the default build. Slow (it installs every dependency);
CI runs the README's second command, which this suite is."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from pages import install_command

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.slow
def test_readme_install_command_builds_the_default(tmp_path):
    command = install_command((ROOT / "README.md").read_text(encoding="utf-8"))
    assert "pip install ." in command and "magfab build" in command
    clone = tmp_path / "magfab"
    subprocess.run(["git", "clone", "-q", str(ROOT), str(clone)], check=True, timeout=300)
    for changed in subprocess.run(["git", "ls-files", "-m", "-o", "--exclude-standard"], cwd=ROOT, capture_output=True,
                                  text=True, check=True).stdout.split():  # this tree's uncommitted work, too
        if not (ROOT / changed).is_file():
            continue
        (clone / changed).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(ROOT / changed, clone / changed)
    # then, in the same shell, a bare `magfab` as the README's "Using it" types it: the venv's own
    proc = subprocess.run(["bash", "-c", f"{command} && command -v magfab"], cwd=clone, capture_output=True, text=True,
                          timeout=1800, env={k: v for k, v in os.environ.items() if k != "VIRTUAL_ENV"})
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    assert Path(proc.stdout.splitlines()[-1]) == clone / ".venv" / "bin" / "magfab", proc.stdout[-500:]
    out = clone / "build" / "magone"
    assert (out / "manifest.json").is_file() and (out / "firmware" / "magfab-atmega328p.hex").is_file()
    assert "built magone into" in proc.stdout
    assert sorted(p.name for p in (clone / "build").iterdir()) == ["magone"]  # no setuptools build/lib beside it
