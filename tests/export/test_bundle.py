"""The firmware-plus-calibration bundle as a build ships it, end to end:

simulated MLX90393 -> the firmware's C core (host build) -> serial frames -> the generated readout
package -> forces, equal to what magfab.models.calibration computes; and `magfab calibrate` on a scan CSV."""

from __future__ import annotations

import importlib
import importlib.util
import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import require_tool
from readout_support import assert_reads_zero_at_rest, imported, install

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
    ours = lambda name: name == "magfab_readout" or name.startswith("magfab_readout.")
    saved = {name: mod for name, mod in sys.modules.items() if ours(name)}
    for name in saved:
        del sys.modules[name]
    try:
        with imported({}, out) as module:
            return module
    finally:
        sys.modules.update(saved)


def test_the_readout_is_its_source_tree_plus_data_files(bundle):
    """A build's readout/ is the package's one source tree (magfab/readout/: modules, format validators,
    pyproject.toml) byte for byte, its README template rendered in its place, plus only data files; no module is
    generated or gathered from elsewhere."""
    out, _ = bundle
    tree = readout.source_files()
    tree_root = Path(readout.__file__).resolve().parents[1] / readout.SOURCE
    tracked = subprocess.run(["git", "ls-files", "."], cwd=tree_root, capture_output=True, text=True)
    if tracked.returncode == 0 and tracked.stdout:  # a checkout: every file of the folder is the package's
        assert set(tracked.stdout.split()) == set(tree)
    assert all((tree_root / p).read_bytes() == data for p, data in tree.items())
    shipped = {p.relative_to(out / "readout").as_posix(): p.read_bytes() for p in (out / "readout").rglob("*")
               if p.is_file() and "__pycache__" not in p.parts}
    templates = {p for p in tree if p.endswith(readout.TEMPLATE_SUFFIX)}
    assert templates == {"README.md.j2"}
    assert {p: d for p, d in shipped.items() if p in tree} == {p: d for p, d in tree.items() if p not in templates}
    data = {f"src/magfab_readout/{name}"
            for name in ("build.json", "calibration.json", "acceptance.json", "weigh_plan.json")}
    assert set(shipped) - set(tree) == {"README.md"} | data
    package = out / "readout" / "src" / "magfab_readout"
    build = json.loads((package / "build.json").read_text())
    assert build["calibration_sha256"] == calibration_json.calibration_sha256(
        json.loads((package / "calibration.json").read_text()))


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
    # the simulated scan stays (deterministic, and it may be the scan a calibration was given)
    assert (target / "calibration" / "scan_simulated.csv").read_bytes() == (out / "calibration" /
                                                                           "scan_simulated.csv").read_bytes()
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


# --- the readout package as the bench uses it --------------------------------------------------------------

def test_pip_install_from_a_copy_of_the_build_leaves_it_as_it_was(bundle, tmp_path):
    """``pip install ./readout`` run in (a copy of) the build folder writes nothing there (setuptools wrote
    readout/build/ and readout/src/*.egg-info), and the installed package carries the build's data files."""
    out, cal = bundle
    files = {p.relative_to(out).as_posix(): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    installed = install(files, tmp_path)
    assert installed.after == installed.before
    run = subprocess.run([str(installed.script), "info", "--simulate"], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0 and "calibration: match" in run.stdout, run.stderr
    assert calibration_json.calibration_sha256(cal)[:16] in run.stdout
    probe = ("import json, pkgutil; print(json.dumps([json.loads(pkgutil.get_data('magfab_readout', n)) "
             "for n in ('calibration.json', 'acceptance.json')]))")
    data = subprocess.run([str(installed.python), "-c", probe], capture_output=True, text=True, timeout=60,
                          cwd=tmp_path)
    assert data.returncode == 0, data.stderr
    shipped = [json.loads((out / "calibration" / name).read_text()) for name in ("calibration.json", "acceptance.json")]
    assert json.loads(data.stdout) == shipped


def test_the_simulated_board_reads_zero_at_rest_with_the_builds_calibration(bundle):
    """The build's own calibration: at rest the simulated board read Fx +37 mN until --zero."""
    out, cal = bundle
    assert_reads_zero_at_rest(_decoder(out), cal)


# --- the bundle's READMEs: commands as a person types them -----------------------------------------------------

BENCH = """\
sh firmware/flash.sh uno /dev/ttyACM0
pip install ./readout
magfab-readout upload
magfab-readout info
magfab-readout stream --zero 200            # Ctrl-C ends it
magfab-readout record scan.csv              # during the scan; Ctrl-C ends it
magfab calibrate scan.csv --reference reference.csv --sensor magone-01
magfab-readout upload --sensor magone-01
magfab-readout info
magfab-readout check --weight-g 50 --rotation --warmup --sensor magone-01
"""


def _blocks(text: str, language: str) -> list:
    return re.findall(rf"^```{language}\n(.*?)^```$", text, re.S | re.M)


def _commands(text: str) -> list:
    """The ```sh blocks' commands, comments kept, in order."""
    return [line for block in _blocks(text, "sh") for line in block.splitlines() if line.strip()]


def _runs_until_ctrl_c(line: str) -> bool:
    words = shlex.split(line, comments=True)
    if words[:2] in (["magfab-readout", "stream"], ["magfab-readout", "record"], ["magfab-readout", "view"]):
        return not {"--count", "--seconds"} & set(words)
    return False


@pytest.mark.parametrize("page", ["readout/README.md", "firmware/README.md"])
def test_bundle_readmes_give_every_command_as_typed(bundle, page):
    """Every command in a ```sh block, runnable as written from the page's folder: no placeholders, the
    board's port written out, no tool CI cannot install (PlatformIO fetches its toolchain: prose only), each
    command that runs until Ctrl-C says so, paths that exist; Python in ```python blocks that compile; no
    indented (untagged) code blocks."""
    out, _ = bundle
    text = (out / page).read_text()
    folder = (out / page).parent if page.startswith("firmware") else out
    commands = _commands(text)
    fences = re.findall(r"^```(\w*)$", text, re.M)
    assert set(fences[0::2]) <= {"sh", "python", "bat"} and set(fences[1::2]) == {""} and len(fences) % 2 == 0
    assert not re.search(r"^\s+```|^    \S", re.sub(r"^```\w+\n.*?^```$", "", text, flags=re.S | re.M), re.M)
    assert commands
    built = {"host/magfab_host"}  # made by the block's `make -C host`
    for line in commands:
        words = shlex.split(line, comments=True)
        assert words and not re.search(r"[\[\]<>]|\bPORT\b|NEW|\.\.\.", " ".join(words)), line
        assert words[0] not in ("pio", "platformio", "sudo", "cd"), line
        assert _runs_until_ctrl_c(line) == ("Ctrl-C ends it" in line), line
        for word in words:
            if "/" in word and not word.startswith(("/dev/", "-")) and word not in built:
                assert (folder / word).exists(), f"{page}: {word} (from {folder.name}/) does not exist"
    for block in _blocks(text, "python"):
        compile(block, page, "exec")


def test_the_readout_readme_gives_the_bench_sequence_from_the_build_folder(bundle):
    out, _ = bundle
    text = (out / "readout" / "README.md").read_text()
    assert BENCH in _blocks(text, "sh")
    assert "from the build folder" in text and "MAGFAB_READOUT_PORT" in text
    assert "Fx_sensor_N" in text and "host_time_s" in text and "--reference" in text
    firmware_text = (out / "firmware" / "README.md").read_text()
    assert "from this folder, `firmware/`" in firmware_text
    assert _commands(firmware_text)[:4] == ["sh flash.sh uno /dev/ttyACM0", "pip install ../readout",
                                            "magfab-readout upload", "magfab-readout info"]


def test_the_firmware_readme_states_the_rate_every_page_states(bundle):
    """One conversion time (models/chip.py via the firmware's context): the firmware README's us and Hz are the
    readout's build.json rate and the report's predictions.json rate, rounded as the report rounds them."""
    out, _ = bundle
    rate = json.loads((out / "predictions.json").read_text())["chip"]["rate_Hz"]
    build = json.loads((out / "readout" / "src" / "magfab_readout" / "build.json").read_text())
    assert build["sample_rate_Hz"] == pytest.approx(rate, rel=1e-9)
    measured = json.loads((out / "predictions.json").read_text())["readout_measured"]
    assert build["readout_measured"] == measured and measured["worst"]["delivered"] >= 0.99  # the one record
    us, hz = round(1e6 / rate), f"{rate:.0f}"
    assert (us, hz) == (1840, "543")  # MagOne: OSR 0, DIG_FILT 2, T+X+Y+Z (the datasheet's table)
    assert f"one sample every {us} us, {hz} Hz" in (out / "firmware" / "README.md").read_text()
    assert f"{hz} samples a second" in (out / "readout" / "README.md").read_text()
    assert f"({hz} Hz)" in (out / "report.html").read_text()


def test_the_firmware_readmes_host_build_runs_as_written(bundle, tmp_path):
    """The host build's two commands, run from a copy of firmware/: three text lines with a force."""
    require_tool("cc")
    require_tool("make")
    out, _ = bundle
    text = (out / "firmware" / "README.md").read_text()
    lines = [line for line in _commands(text) if "host" in line]
    assert len(lines) == 2
    folder = tmp_path / "firmware"
    for path in (out / "firmware").rglob("*"):
        if path.is_file():
            target = folder / path.relative_to(out / "firmware")
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(path.read_bytes())
    runs = [subprocess.run(line, shell=True, cwd=folder, capture_output=True, timeout=120) for line in lines]
    assert all(r.returncode == 0 for r in runs), [r.stderr.decode()[-400:] for r in runs]
    frames = runs[1].stdout.decode().splitlines()
    assert len(frames) == 3 and all(f.startswith("F,") for f in frames)
