"""The firmware-plus-calibration bundle as a build ships it, end to end:

simulated MLX90393 -> the firmware's C core (host build) -> serial frames -> the generated readout
package -> forces, equal to what magfab.models.calibration computes; and `magfab calibrate` on a scan CSV."""

from __future__ import annotations

import importlib
import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from readout_support import imported
from click.testing import CliRunner

from conftest import require_tool
from magfab.cli import main
from magfab.errors import MagfabError
from magfab.export import firmware, readout, toolchain
from magfab.formats import calibration_json
from magfab.formats.scan_csv import read_scan_csv
from magfab.models import calibration as C


@pytest.fixture(scope="module")
def bundle(default_build):
    out = default_build.out_dir
    cal = json.loads((out / "calibration" / "calibration.json").read_text())
    return out, cal


def test_build_ships_the_bundle(bundle):
    out, cal = bundle
    assert cal["format"] == "magfab-calibration/1" and cal["scan"]["source"] == "simulated"
    assert (out / "calibration" / "scan_simulated.csv").exists()
    assert (out / "firmware" / "magfab_readout" / "magfab_readout.ino").exists()
    assert (out / "firmware" / "platformio.ini").exists() and (out / "firmware" / "flash.sh").exists()
    assert (out / "readout" / "pyproject.toml").exists()
    embedded = json.loads((out / "readout" / "src" / "magfab_readout" / "calibration.json").read_text())
    assert embedded == cal
    manifest = json.loads((out / "manifest.json").read_text())
    paths = {a["path"] for a in manifest["artifacts"]}
    assert "calibration/calibration.json" in paths and "readout/pyproject.toml" in paths


def test_build_ships_a_flashable_image(bundle):
    require_tool("avr-gcc")
    out, _ = bundle
    text = (out / "firmware" / "magfab-atmega328p.hex").read_text()
    lines = text.splitlines()
    assert lines[-1] == ":00000001FF"
    for line in lines:  # Intel HEX: every record's checksum makes its bytes sum to 0 mod 256
        raw = bytes.fromhex(line[1:])
        assert line[0] == ":" and sum(raw) % 256 == 0


def _decoder(out: Path):
    """The build's generated readout package, imported from its folder without leaving it in sys.modules
    (the readout tests import their own rendering under the same name)."""
    ours = lambda name: name == "magfab_readout" or name.startswith("magfab_readout.")  # noqa: E731
    saved = {name: mod for name, mod in sys.modules.items() if ours(name)}
    for name in saved:
        del sys.modules[name]
    try:
        with imported({}, out) as module:
            return module
    finally:
        sys.modules.update(saved)


def test_the_readout_runtime_is_shipped_verbatim(bundle):
    """The package's modules are magfab's files byte for byte (the runtime's own and the format validators):
    one implementation, no template; only data (build.json, calibration.json, acceptance.json) is generated."""
    out, _ = bundle
    package = out / "readout" / "src" / "magfab_readout"
    shipped = {p.name: p.read_bytes() for p in package.iterdir() if p.is_file()}
    runtime = Path(readout.__file__).parent.joinpath(*readout.RUNTIME)
    formats = Path(calibration_json.__file__).parent
    sources = {p.name: p.read_bytes() for p in runtime.glob("*.py")}
    sources.update({name: (formats / name).read_bytes() for name in readout.SHARED})
    assert {n: d for n, d in shipped.items() if n.endswith(".py")} == sources == readout.runtime_files()
    assert set(shipped) - set(sources) == {"build.json", "calibration.json", "acceptance.json"}
    assert json.loads(shipped["build.json"])["calibration_sha256"] == calibration_json.calibration_sha256(
        json.loads(shipped["calibration.json"]))


def test_the_readout_runtime_passes_pyflakes(bundle):
    out, _ = bundle
    files = sorted(str(p) for p in (out / "readout" / "src" / "magfab_readout").glob("*.py"))
    checker = "pyflakes" if importlib.util.find_spec("pyflakes") else "py_compile"  # the test extra has pyflakes
    command = [sys.executable, "-m", checker, *files]
    run = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr


def test_the_packaged_validator_stands_alone(bundle):
    """Inside the package the validators' errors are plain ValueErrors (magfab is not there to import);
    inside magfab the same bytes give magfab's CalibrationFormatError, and both refuse the same file."""
    out, cal = bundle
    pkg = _decoder(out)
    assert issubclass(pkg.CalibrationError, ValueError) and not issubclass(pkg.CalibrationError, MagfabError)
    bad = dict(cal, shear_sign=0)
    with pytest.raises(pkg.CalibrationError) as host:
        pkg.Calibration(bad)
    with pytest.raises(calibration_json.CalibrationError) as ours:
        calibration_json.validate(bad)
    assert str(host.value) == str(ours.value) and isinstance(ours.value, MagfabError)


def test_end_to_end_simulated_chip_to_host_forces(bundle, tmp_path):
    """Field -> simulated chip -> firmware core -> frames -> readout decoder: the forces equal
    magfab.models.calibration's polynomial evaluation of the same raw readings (float32 on the device)."""
    require_tool("gcc")
    out, cal = bundle
    files = {str(p.relative_to(out / "firmware")): p.read_bytes() for p in (out / "firmware").rglob("*")
             if p.is_file() and not p.name.endswith(".hex")}
    exe = toolchain.build_host(files, tmp_path / "fw")
    scan = read_scan_csv(out / "calibration" / "scan_simulated.csv")
    pick = np.linspace(0, scan.rows - 1, 12).round().astype(int)
    script = "".join(f"B {bx:.4f} {by:.4f} {bz:.4f} 25\nS 1\n" for bx, by, bz in scan.B_uT[pick])
    run = subprocess.run([str(exe)], input=script.encode(), capture_output=True, timeout=120)
    assert run.returncode == 0, run.stderr.decode()
    readout = _decoder(out)
    samples = [s for s in readout.decode_frames(run.stdout) if isinstance(s, readout.Sample)]
    assert len(samples) == len(pick)
    calibration = C.Calibration.from_json(cal)
    for s in samples:
        assert s.status & 0x02 == 0  # no chip error
        # the device's own reading of the field (quantised by the chip), through the host's evaluation
        want, _ = calibration.evaluate(np.array([s.B_uT]), method="poly")
        got = np.array(s.force_N)
        scale = max(float(np.max(np.abs(want))), 1e-3)
        assert np.max(np.abs(got - want[0])) <= 1e-4 * scale, (got, want[0])


def test_calibrate_command_refits_from_a_scan(bundle, tmp_path):
    out, cal = bundle
    scan_file = tmp_path / "bench_scan.csv"
    scan_file.write_text((out / "calibration" / "scan_simulated.csv").read_text())
    target = tmp_path / "calibrated"
    result = CliRunner().invoke(main, ["calibrate", str(scan_file), "--out", str(target)])
    assert result.exit_code == 0, result.output
    new = json.loads((target / "calibration" / "calibration.json").read_text())
    assert new["scan"]["source"] == "bench_scan.csv"
    assert new["coefficients"] == cal["coefficients"]  # same data, same fit
    assert not (target / "calibration" / "scan_simulated.csv").exists()
    firmware_files = "".join(p.read_text() for p in (target / "firmware" / "magfab_readout" / "src").glob("*.h"))
    assert firmware.calibration_sha256(new)[:16] in firmware_files
    assert firmware.calibration_sha256(new) != firmware.calibration_sha256(cal)  # the scan's hash changed


def test_calibrate_command_refuses_a_malformed_scan(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("time_s,Bx_uT,By_uT,Bz_uT,Fx_N,Fy_N,Fz_N\n0,1,2,abc,0,0,0\n")
    target = tmp_path / "never"
    result = CliRunner().invoke(main, ["calibrate", str(bad), "--out", str(target)])
    assert result.exit_code == 2
    assert "line 2" in result.output and "Bz_uT" in result.output and "Traceback" not in result.output
    assert not target.exists()
    result = CliRunner().invoke(main, ["calibrate", str(tmp_path / "missing.csv"), "--out", str(target)])
    assert result.exit_code == 2 and "missing.csv" in result.output
