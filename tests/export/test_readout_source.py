"""The readout package from its one source tree (magfab/readout/), without a magfab build: the tree alone imports
and installs (the format validators work, the rest says which data it lacks), and the tree plus data files written
here (build.json, calibration.json: what a build adds) runs the package's own checks, as a build ships it."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from conftest import ref_crc16
from readout_support import PKG, assert_reads_zero_at_rest, imported, install, make_calibration, ref_decode, ref_frame

from magfab.errors import MagfabError
from magfab.export import readout
from magfab.formats import calibration_json

#: build.json as a build writes it (export/readout.py's _build_data), for a made-up spec: the package's settings.
BUILD = {
    "spec_name": "bench", "spec_sha256": "00" * 32, "magfab_version": "0.0.0", "version": "0.0.0+cal.test",
    "baud": 250000, "output": "binary", "temperature": True, "gain_sel": 0, "resolution": 2, "osr": 0, "dig_filt": 2,
    "lsb_xy_uT": 3.004, "lsb_z_uT": 4.84, "full_scale_counts": 22000, "sample_rate_Hz": 543.478261,
    "temperature_raw_25C": 46244, "temperature_lsb_per_C": 45.2,
    "image_settings": {"name": "bench", "gain_sel": 0, "resolution": 2, "osr": 0, "dig_filt": 2},
}
TREE_SRC = readout.source_files()


def _tree(data: dict[str, bytes] | None = None) -> dict[str, bytes]:
    """The source tree's files under ``readout/`` (templates left out: they are not the package), plus ``data``."""
    files = {f"readout/{p}": d for p, d in TREE_SRC.items() if not p.endswith(readout.TEMPLATE_SUFFIX)}
    return {**files, **(data or {})}


def _with_data(calibration: dict) -> dict[str, bytes]:
    build = dict(BUILD, calibration_sha256=calibration_json.calibration_sha256(calibration))
    return _tree({f"{PKG}/build.json": json.dumps(build).encode(),
                  f"{PKG}/calibration.json": json.dumps(calibration).encode()})


def test_the_source_tree_holds_the_whole_package():
    """Every module the package imports, the format validators included, is in the tree; nothing else of magfab."""
    modules = {p.rsplit("/", 1)[1] for p in TREE_SRC if p.startswith("src/magfab_readout/")}
    assert {"json_checks.py", "calibration_json.py", "acceptance_json.py", "array_json.py", "__init__.py",
            "_build.py", "cli.py", "frames.py"} <= modules
    assert set(TREE_SRC) - {f"src/magfab_readout/{m}" for m in modules} == {"pyproject.toml", "README.md.j2"}
    assert all(not name.endswith(".json") for name in modules)  # data comes only from a build


def test_the_bare_source_tree_imports_its_validators_and_names_what_it_lacks(tmp_path):
    """Imported from the tree itself (no copy, no build data, no bytecode written): the validators work and raise
    plain ValueErrors; the parts that need a build's settings say so."""
    src = os.path.join(os.path.dirname(readout.__file__), os.pardir, readout.SOURCE, "src")
    code = """
import json, sys
import magfab_readout
from magfab_readout import acceptance_json, array_json, calibration_json
assert magfab_readout.__version__ == "0+source", magfab_readout.__version__
cal = json.loads(sys.argv[1])
assert calibration_json.validate(cal).sha256 == calibration_json.calibration_sha256(cal)
try:
    calibration_json.validate(dict(cal, shear_sign=0))
except ValueError as exc:
    assert type(exc).__mro__[2] is ValueError and "shear_sign" in str(exc), type(exc).__mro__
try:
    magfab_readout.Device
except AttributeError as exc:
    print(exc)
"""
    env = dict(os.environ, PYTHONPATH=os.path.abspath(src), PYTHONDONTWRITEBYTECODE="1")
    proc = subprocess.run([sys.executable, "-c", code, json.dumps(make_calibration())], capture_output=True,
                          text=True, timeout=60, cwd=tmp_path, env=env)
    assert proc.returncode == 0, proc.stderr
    assert "has no build.json" in proc.stdout and "install the readout/ folder of a magfab build" in proc.stdout


def test_magfab_and_the_package_run_the_same_validator_files():
    """magfab.formats' validators are the tree's modules (one copy); inside magfab their errors are magfab's."""
    from magfab.formats import acceptance_json, array_json, json_checks

    for module in (calibration_json, acceptance_json, array_json, json_checks):
        name = module.__name__.rsplit(".", 1)[1]
        assert module.__all__
        origin = sys.modules[f"magfab.readout.src.magfab_readout.{name}"]
        assert all(getattr(module, n) is getattr(origin, n) for n in module.__all__)
        assert origin.__file__.endswith(f"readout/src/magfab_readout/{name}.py")
    assert issubclass(calibration_json.CalibrationError, MagfabError)


def test_the_source_tree_with_data_runs_the_package_checks(tmp_path):
    """The tree plus a build.json and calibration.json written here, imported as a build's package: frames are
    the documented layout with the CRC, the embedded calibration loads, the simulated board reads zero at rest."""
    calibration = make_calibration()
    with imported(_with_data(calibration), tmp_path) as pkg:
        assert pkg.__version__ == BUILD["version"] and pkg.SPEC_NAME == "bench"
        assert pkg.crc16_ccitt_false(b"123456789") == ref_crc16(b"123456789") == 0x29B1
        frame = ref_frame(7, 123456, 0, (100, -200, 3000), 46244, (0.5, -0.25, 1.0))
        assert pkg.encode_frame(7, 123456, 0, (100, -200, 3000), 46244, (0.5, -0.25, 1.0)) == frame
        assert ref_decode(frame)[0]["counts"] == (100, -200, 3000)
        (sample,) = pkg.decode_frames(frame)
        assert sample.seq == 7 and sample.counts == (100, -200, 3000)
        assert pkg.Calibration.embedded().sha256 == calibration_json.calibration_sha256(calibration)
        assert_reads_zero_at_rest(pkg, calibration)


@pytest.mark.slow
def test_pip_installs_the_bare_source_tree(tmp_path):
    """``pip install`` of the tree itself: version 0+source, the validators import; a build's readout/ is the
    same tree with its data (test_readout.py installs that one)."""
    env = install(_tree(), tmp_path)
    code = "import magfab_readout, magfab_readout.calibration_json as c; print(magfab_readout.__version__, c.FORMAT)"
    proc = subprocess.run([str(env.python), "-c", code], capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.split() == ["0+source", "magfab-calibration/1"]
