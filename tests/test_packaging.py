"""The wheel a user installs with `pip install .` (the README's first command) holds every module and data file
of the source tree: a subpackage missing from pyproject.toml would pass every editable-install test and still
break a new user's build."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel_files(tmp_path_factory) -> set[str]:
    out = tmp_path_factory.mktemp("wheel")
    proc = subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--quiet",
                           "-w", str(out), str(ROOT)], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    (wheel,) = out.glob("magfab-*.whl")
    return set(zipfile.ZipFile(wheel).namelist())


def _tracked(pattern: str, under: str = "magfab") -> set[str]:
    return {str(p.relative_to(ROOT)) for p in (ROOT / under).rglob(pattern) if "__pycache__" not in p.parts}


def test_every_module_and_data_file_is_in_the_wheel(wheel_files):
    wanted = _tracked("*.py") | _tracked("*.toml") | _tracked("*.json")
    assert wanted - wheel_files == set()


def test_templates_ship_as_magfab_templates(wheel_files):
    wanted = {"magfab/templates/" + str(p.relative_to(ROOT / "templates"))
              for p in (ROOT / "templates").rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    assert wanted and wanted - wheel_files == set()


def test_the_generic_firmware_image_ships(wheel_files):
    """A pip-only machine (no avr-gcc) still writes a ready-to-flash .hex: the generic image and the record of the
    toolchain that made it are package data."""
    assert {"magfab/export/generic_image/magfab-atmega328p.hex",
            "magfab/export/generic_image/toolchain.json"} <= wheel_files


def test_the_readout_source_tree_ships(wheel_files):
    """The readout package's one source tree, which every build copies verbatim: templates included."""
    tree = ROOT / "magfab" / "readout"
    wanted = {str(p.relative_to(ROOT)) for p in tree.rglob("*") if p.is_file() and "__pycache__" not in p.parts}
    assert "magfab/readout/README.md.j2" in wanted and "magfab/readout/pyproject.toml" in wanted
    assert wanted - wheel_files == set()
