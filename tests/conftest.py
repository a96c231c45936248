"""Shared fixtures. Tests that need a Debian tool call :func:`require_tool`: it skips with a reason when
the tool is missing, and fails instead when MAGFAB_REQUIRE_TOOLS=1 (set by .ci/run), so CI always runs them.

The suite runs in parallel (pytest-xdist, the README's test command): ``--dist loadfile`` gives each test module
to one worker, so a module's fixtures are made once, as in a serial run; a session fixture, though, runs on every
worker, so the session's builds (:func:`default_build`, :func:`array_builds`) are made once per run by whichever
worker asks first and loaded by the others (:func:`_once_per_run`)."""

from __future__ import annotations

import copyreg
import fcntl
import io
import os
import pickle
import shutil
import signal
from pathlib import Path
from types import MappingProxyType

import pytest

from magfab import build, load_spec, parse_spec

# An xdist worker ignores SIGINT (the controller takes Ctrl-C), and every process it starts inherits that: a command
# the tests Ctrl-C (`magfab-readout stream`, the Ctrl-C tests) would never stop. Its children get the default back.
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


#: The calibrate tests' fixtures (bench, n52), shared by test_calibrate_defects.py and test_calibrate_sensor.py.
pytest_plugins = ("calibrate_support",)

def _missing(reason: str):
    if os.environ.get("MAGFAB_REQUIRE_TOOLS") == "1":
        pytest.fail(f"MAGFAB_REQUIRE_TOOLS=1 but {reason}")
    pytest.skip(reason)


def require_tool(name: str) -> str:
    path = shutil.which(name)
    if path:
        return path
    _missing(f"{name} is not installed (Debian package; .ci/run installs it)")


def require_node_package(harness: Path, package: str) -> str:
    """Node, with ``package`` installed in ``harness`` (its package.json pins it; .ci/run runs ``npm install
    --no-package-lock`` there): node's path (skip, or fail under MAGFAB_REQUIRE_TOOLS=1)."""
    node = require_tool("node")
    if not (harness / "node_modules" / package / "package.json").is_file():
        _missing(f"{package} is not installed in {harness.name} (npm install --no-package-lock there; .ci/run does)")
    return node


def require_kicad() -> str:
    """The interpreter that imports KiCad's pcbnew (skip, or fail under MAGFAB_REQUIRE_TOOLS=1)."""
    from magfab.export.kicad import kicad_python

    exe = kicad_python()
    if exe:
        return exe
    _missing("KiCad's pcbnew Python module is not available (Debian package 'kicad'; .ci/run installs it)")


def require_kicad_library(relative: str) -> str:
    """A file of KiCad's footprint library (Debian package 'kicad-footprints')."""
    path = os.path.join(KICAD_FOOTPRINTS, relative)
    if os.path.exists(path):
        return path
    _missing(f"KiCad's footprint library is not installed (Debian package 'kicad-footprints'): no {relative}")


KICAD_FOOTPRINTS = os.environ.get("KICAD6_FOOTPRINT_DIR", "/usr/share/kicad/footprints")


@pytest.fixture(scope="session")
def magone_design():
    """The MagOne design, derived once per session."""
    from magfab import derive

    return derive(load_spec(None))


@pytest.fixture(scope="session")
def magone_prediction(magone_design):
    """The MagOne prediction, computed once per session (the models are deterministic)."""
    from magfab.models.predict import predict

    return predict(magone_design)


@pytest.fixture(scope="session")
def magone_neo_hookean():
    """MagOne with the neo-Hookean law (the default is the silicone's Yeoh law): (design, prediction), once per
    session, for the tests of that law's own path (its stretch limit, its surrogate table, its calibration scan)."""
    from magfab import derive, parse_spec
    from magfab.models.predict import predict

    design = derive(parse_spec('[predict]\nmaterial_law = "neo-hookean"\n'))
    return design, predict(design)


@pytest.fixture(scope="session")
def design(magone_design):
    """Short name for the MagOne design (a test module may define its own ``design``, which then wins)."""
    return magone_design


@pytest.fixture(scope="session")
def pred(magone_prediction):
    """Short name for the MagOne prediction."""
    return magone_prediction


def _mapping_proxy(mapping: dict) -> MappingProxyType:
    return MappingProxyType(mapping)


def _dumps(value) -> bytes:
    """``pickle.dumps`` that also takes the recipes' read-only tables (``MappingProxyType``, which pickle refuses)."""
    buffer = io.BytesIO()
    pickler = pickle.Pickler(buffer, protocol=pickle.HIGHEST_PROTOCOL)
    pickler.dispatch_table = {**copyreg.dispatch_table, MappingProxyType: lambda m: (_mapping_proxy, (dict(m),))}
    pickler.dump(value)
    return buffer.getvalue()


def _once_per_run(tmp_path_factory, name: str, make):
    """``make(folder)``, once per test run. Under xdist every worker runs a session fixture itself; here the first
    worker to ask makes it in the run's shared temporary folder while holding a lock, and the others, once it is
    done, load the result it saved beside it (each worker gets its own copy of the objects; the folder is shared,
    and read only). Without xdist: ``make`` in this session's temporary folder."""
    if "PYTEST_XDIST_WORKER" not in os.environ:
        return make(tmp_path_factory.mktemp(name))
    shared = tmp_path_factory.getbasetemp().parent / "shared"  # the run's folder, above every worker's own
    shared.mkdir(exist_ok=True)
    saved = shared / f"{name}.pickle"
    with open(shared / f"{name}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # released when the file closes, also when ``make`` raises
        if saved.is_file():
            return pickle.loads(saved.read_bytes())
        result = make(shared / name)
        saved.write_bytes(_dumps(result))
        return result


@pytest.fixture(scope="session")
def default_build(tmp_path_factory):
    """The default (MagOne) build, written once per run (read only: a test that changes it works on a copy)."""
    return _once_per_run(tmp_path_factory, "default", lambda folder: build(load_spec(None), folder / "magone"))


@pytest.fixture(scope="session")
def rp2040_build(tmp_path_factory):
    """MagOne on an Adafruit QT Py RP2040 (examples/magone_qtpy.toml), written once per run (read only)."""
    return _once_per_run(tmp_path_factory, "rp2040",
                         lambda folder: build(load_spec(EXAMPLES / "magone_qtpy.toml"), folder / "magone-qtpy"))


def ref_crc16(data: bytes) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF), bit by bit: the tests' own reference for the frames."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


EXAMPLES = Path(__file__).resolve().parents[1] / "magfab" / "examples"


@pytest.fixture(scope="session")
def two_bus_build(tmp_path_factory):
    """examples/fingertip_2x2.toml split over two I2C buses (``array.buses = 2``: taxels 1 and 3 on J2) on an Adafruit
    QT Py RP2040, written once per run (read only)."""

    def make(folder: Path):
        spec = load_spec(EXAMPLES / "fingertip_2x2.toml")
        assert spec.array is not None
        spec = spec.model_copy(update={"name": "fingertip_2x2_buses", "array": spec.array.model_copy(
            update={"buses": 2}), "board": parse_spec('[board]\nboard = "qtpy-rp2040"').board})
        return build(spec, folder / "fingertip_2x2_buses")

    return _once_per_run(tmp_path_factory, "two-bus", make)


@pytest.fixture(scope="session")
def array_builds(tmp_path_factory):
    """The two array examples built once per session: ``{"fingertip_2x2": BuildResult, "strip_1x5": ...}`` (a 2x2
    continuous skin at 10 mm, alternating; a 1x5 strip of separate tips at 14 mm, same polarity)."""

    def make(root: Path) -> dict:
        names = ("fingertip_2x2", "strip_1x5")
        return {name: build(load_spec(EXAMPLES / f"{name}.toml"), root / name) for name in names}

    return _once_per_run(tmp_path_factory, "arrays", make)
