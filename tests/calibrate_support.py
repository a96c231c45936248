"""What the calibrate tests share: a project folder with a copy of the session's default build, a sensor root beside
it, and ``magfab calibrate``/``build`` whose plan is the session's build (as tests/test_output.py does), so each
command takes about a second. Uses only what main had before the sensor commands (the defect tests run against it)."""

from __future__ import annotations

import dataclasses
import importlib
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from magfab import derive
from magfab.cli import main
from magfab.formats import sensor_records as records
from magfab.models.scan import simulate_scan


def tree(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def make_bench(default_build, tmp_path, monkeypatch):
    """A project folder: a copy of the default build in build/magone, no sensor root yet, and the magfab command
    whose plan is the session's build. Returns (project, build folder, plan calls, run)."""
    project = tmp_path / "project"
    out = project / "build" / "magone"
    shutil.copytree(default_build.out_dir, out)
    calls = []

    def plan(spec, progress=None, scan=None):
        calls.append((spec, scan))
        return dataclasses.replace(default_build, out_dir=None, timings_s=dict(default_build.timings_s))

    monkeypatch.setattr(importlib.import_module("magfab.pipeline"), "plan", plan)
    monkeypatch.chdir(project)
    monkeypatch.delenv(records.ROOT_ENV, raising=False)
    return project, out, calls, lambda *args: CliRunner().invoke(main, [*args])


def add(project: Path, out: Path, sensor_id: str, spec_sha256: str | None = None) -> records.Sensor:
    """A record as ``magfab sensor add ID --build OUT`` makes it (the agreed added event)."""
    sha = spec_sha256 or json.loads((out / "manifest.json").read_text())["spec_sha256"]
    files = {"spec.json": (out / "spec.json").read_bytes(), "design.json": (out / "design.json").read_bytes(),
             "acceptance.json": (out / "calibration" / "acceptance.json").read_bytes()}
    return records.create(project / "sensors", sensor_id, {"spec_sha256": sha}, files)


def n52_scan(magone_design, magone_prediction):
    """The MagOne fingertip with an N52 magnet (another grade: 20 % more field at rest), scanned."""
    spec = magone_design.spec
    other = derive(spec.model_copy(update={"magnet": spec.magnet.model_copy(update={"grade": "N52"})}))
    return simulate_scan(other, magone_prediction)


# Fixtures of the calibrate tests (tests/conftest.py registers this module as a plugin).


@pytest.fixture
def bench(default_build, tmp_path, monkeypatch):
    """A project folder with a copy of the session's MagOne build (:func:`make_bench`)."""
    return make_bench(default_build, tmp_path, monkeypatch)


@pytest.fixture(scope="module")
def n52(magone_design, magone_prediction):
    """MagOne's simulated scan with an N52 magnet (:func:`n52_scan`)."""
    return n52_scan(magone_design, magone_prediction)


def weigh_simulated(cwd, out, *args):
    """``magfab-readout weigh ARGS --simulate --yes`` from the package of the build in ``out``."""
    env = {k: v for k, v in os.environ.items() if k != "MAGFAB_SENSORS"}
    env["PYTHONPATH"] = str(out / "readout" / "src")
    return subprocess.run([sys.executable, "-m", "magfab_readout", "weigh", *args, "--simulate", "--yes"],
                          capture_output=True, text=True, timeout=300, env=env, cwd=cwd)


@pytest.fixture(scope="module")
def weigh_package(default_build):
    """The default build's readout package imported in this process, and its weight plan, once for the module."""
    from types import SimpleNamespace

    from readout_support import imported

    with imported({}, default_build.out_dir):
        from magfab_readout import _build, cli, weigh
        from magfab_readout.cli_shared import UsageError

        yield SimpleNamespace(build=_build, cli=cli, weigh=weigh, UsageError=UsageError, plan=weigh.load_plan())
