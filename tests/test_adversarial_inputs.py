"""Inputs without a size or shape bound (the adversarial pass's first class): every reader of a user's file in magfab
and magfab-readout refuses, in one line and exit 2 and before anything is written, a file that is not a regular file
(a FIFO, /dev/zero, a symlink to it, a directory), one over its kind's limit, TOML or JSON nested deeper than
``MAX_DEPTH`` anywhere (arrays, inline tables, objects, dotted keys, table headers), and a table or object of more
than ``MAX_KEYS`` keys. Generated cases, not only the issue's examples.

The special files run in a child process with its address space limited and a timeout: a reader without the checks
would read /dev/zero until memory runs out, or wait on the FIFO forever, and must fail here without harming the
machine."""

from __future__ import annotations

import importlib
import json
import os
import resource
import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from adversarial_support import KEYS, KINDS, deep_json_document, deep_toml_document, special
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from readout_support import make_calibration

from magfab.cli import main as magfab_main
from magfab.errors import InputError

REPO = Path(__file__).resolve().parents[1]
EXAMPLES = REPO / "magfab" / "examples"
#: Memory a child process may use: far above what refusing a file needs, far below what reading /dev/zero takes.
CHILD_AS_BYTES = 2 * 1024**3
CHILD_TIMEOUT_S = 60
SETTINGS = settings(max_examples=15, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


# --- the readers through their CLIs ---------------------------------------------------------------------------

def one_line_exit_2(code: int, output: str) -> str:
    lines = [line for line in output.splitlines() if line.strip()]
    assert code == 2, output[-2000:]
    assert len(lines) == 1 and "Traceback" not in output, output[-2000:]
    return lines[0]


def magfab(*args: str) -> str:
    result = CliRunner().invoke(magfab_main, list(args))
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise result.exception
    return one_line_exit_2(result.exit_code, result.output)


@pytest.fixture(scope="module")
def readout_src(tmp_path_factory) -> Path:
    """A single taxel's readout package (MagOne's), its source tree."""
    from readout_support import write_tree

    from magfab import derive, load_spec
    from magfab.export.readout import render

    root = tmp_path_factory.mktemp("readout")
    write_tree(render(derive(load_spec(None)), make_calibration()), root)
    return root / "readout" / "src"


def readout(src: Path, capsys, *args: str) -> str:
    """``magfab-readout ARGS --simulate`` in this process (the package imported from ``src``)."""
    sys.path.insert(0, str(src))
    try:
        cli = importlib.import_module("magfab_readout.cli")
        capsys.readouterr()
        code = cli.main([*args, "--simulate"])
    finally:
        sys.path.remove(str(src))
        for name in [n for n in sys.modules if n == "magfab_readout" or n.startswith("magfab_readout.")]:
            del sys.modules[name]
    out = capsys.readouterr()
    return one_line_exit_2(code, out.out + out.err)


# --- nesting, through every reader ----------------------------------------------------------------------------

@SETTINGS
@given(data=st.data())
def test_deep_spec_is_refused_in_one_line(data, tmp_path):
    path = tmp_path / "deep.toml"
    path.write_text(data.draw(deep_toml_document((EXAMPLES / "magone.toml").read_text())))
    assert "deep" in magfab("check", str(path))


@settings(SETTINGS, max_examples=10)
@given(data=st.data())
def test_deep_targets_and_their_base_are_refused_in_one_line(data):
    with tempfile.TemporaryDirectory() as folder:
        deep_targets(data, Path(folder))


def deep_targets(data, tmp_path: Path) -> None:
    targets, spec = tmp_path / "targets.toml", tmp_path / "base.toml"
    deep = data.draw(deep_toml_document((EXAMPLES / "targets.toml").read_text()))
    if data.draw(st.booleans()):  # the deep file is the targets, or the spec its `base` names
        targets.write_text(deep)
    else:
        spec.write_text(data.draw(deep_toml_document((EXAMPLES / "magone.toml").read_text())))
        targets.write_text('base = "base.toml"\n' + (EXAMPLES / "targets.toml").read_text())
    assert "deep" in magfab("design", str(targets), "--out", str(tmp_path / "out"))
    assert not (tmp_path / "out").exists()


@SETTINGS
@given(data=st.data())
def test_deep_calibration_is_refused_by_upload(data, tmp_path, readout_src, capsys):
    path = tmp_path / "deep.json"
    path.write_text(data.draw(deep_json_document(make_calibration())))
    eeprom = tmp_path / "board.eeprom"
    assert "deep" in readout(readout_src, capsys, "upload", str(path), "--simulate-eeprom", str(eeprom))
    assert not eeprom.exists()


@SETTINGS
@given(data=st.data())
def test_deep_json_is_refused_by_every_json_reader(data):
    from magfab.formats import acceptance_json, calibration_json
    from magfab.formats import sensor_records as rec
    from magfab.spec import load_build_spec

    with tempfile.TemporaryDirectory() as folder:
        deep_json_readers(data, Path(folder), acceptance_json, calibration_json, rec, load_build_spec)


def deep_json_readers(data, tmp_path, acceptance_json, calibration_json, rec, load_build_spec):
    cal = data.draw(deep_json_document(make_calibration()))
    other = data.draw(deep_json_document({"format": "x", "rest": {"Bz_uT": {"min": 1}}, "weight": {"g": 50}}))
    (tmp_path / "spec.json").write_text(other)
    root = tmp_path / "sensors"
    sensor = rec.create(root, "finger-01", {}, {})
    (sensor.path / "sensor.json").write_text(other)
    for read in (lambda: calibration_json.loads(cal), lambda: acceptance_json.loads(other.encode()),
                 lambda: load_build_spec(tmp_path), lambda: rec.open_sensor(root, "finger-01").info()):
        with pytest.raises(InputError, match="deep"):
            read()


# --- keys ---------------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("n", [KEYS + 1, 60_000])
@pytest.mark.parametrize("where", ["top", "table", "inline"])
def test_many_unknown_keys_are_counted_before_they_are_validated(tmp_path, n, where):
    keys = [f"u{i} = 1" for i in range(n)]
    text = (EXAMPLES / "magone.toml").read_text()
    if where == "top":
        text = "\n".join(keys) + "\n" + text
    elif where == "table":
        text += "\n[extra]\n" + "\n".join(keys) + "\n"
    else:
        text = "extra = {" + ", ".join(keys) + "}\n" + text
    path = tmp_path / "keys.toml"
    path.write_text(text)
    line = magfab("check", str(path))
    assert "keys" in line and f"{KEYS:,}" in line


def test_an_object_of_many_keys_is_refused_by_upload(tmp_path, readout_src, capsys):
    cal = make_calibration()
    cal["errors"].update({f"u{i}": 1 for i in range(KEYS + 1)})
    path = tmp_path / "keys.json"
    path.write_text(json.dumps(cal))
    assert "keys" in readout(readout_src, capsys, "upload", str(path), "--simulate-eeprom", str(tmp_path / "e"))


# --- special and oversize files, in a child process (see the module's docstring) -----------------------------------

def _limited() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (CHILD_AS_BYTES, CHILD_AS_BYTES))


def child(cwd: Path, env: dict, *argv: str) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=CHILD_TIMEOUT_S,
                              preexec_fn=_limited)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{argv[3:]}: still reading after {CHILD_TIMEOUT_S} s")


MAGFAB = (sys.executable, "-c", "import sys; from magfab.cli import main; sys.argv[0] = 'magfab'; main()")
#: (reader, limit in bytes, its command with {} for the file)
READERS = {
    "spec": (1_000_000, ("check", "{}")),
    "targets": (1_000_000, ("design", "{}", "--out", "out")),
    "scan CSV": (256 * 1024**2, ("calibrate", "{}", "--out", "out")),
    "calibration.json": (64_000_000, ("upload", "{}", "--simulate", "--simulate-eeprom", "board.eeprom")),
}


@pytest.mark.skipif(not hasattr(os, "mkfifo") or not Path("/dev/zero").exists(), reason="needs a POSIX system")
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("reader", list(READERS))
def test_special_and_oversize_files_are_refused_before_a_byte_is_read(tmp_path, kind, reader, readout_src):
    limit, args = READERS[reader]
    path = special(kind, tmp_path, limit + 1)
    if reader == "targets" and kind == "oversize":  # the base spec a targets file names, past its own limit
        base, path = path, tmp_path / "targets.toml"
        path.write_text(f'base = "{base.name}"\n' + (EXAMPLES / "targets.toml").read_text())
    env = dict(os.environ, PYTHONPATH=str(readout_src) if reader == "calibration.json" else str(REPO))
    command = (sys.executable, "-m", "magfab_readout") if reader == "calibration.json" else MAGFAB
    before = sorted(p.name for p in tmp_path.iterdir())
    proc = child(tmp_path, env, *command, *(a.format(path) for a in args))
    assert sorted(p.name for p in tmp_path.iterdir()) == before  # nothing written (no out/, no board.eeprom)
    if kind == "directory" and reader != "calibration.json":  # click refuses it itself (dir_okay=False), with usage
        assert proc.returncode == 2 and "is a directory" in proc.stderr and "Traceback" not in proc.stderr
        return
    line = one_line_exit_2(proc.returncode, proc.stdout + proc.stderr)
    assert "must be a regular file of at most" in line, line


def test_the_reference_log_and_the_record_files_are_bounded_too(tmp_path):
    from magfab.formats import sensor_records as rec
    from magfab.formats.scan_csv import read_reference

    big = special("oversize", tmp_path, 256 * 1024**2 + 1)
    with pytest.raises(InputError, match=r"reference log = .*: must be a regular file of at most 256 MiB"):
        read_reference(big)
    with pytest.raises(InputError, match="a directory"):
        read_reference(tmp_path)
    root = tmp_path / "sensors"
    sensor = rec.create(root, "finger-01", {}, {"scan.csv": b"x"})
    kept = next((sensor.path / "files").iterdir())
    kept.unlink()
    kept.symlink_to("/dev/zero")
    with pytest.raises(InputError, match="character device"):
        sensor.file(kept.name.split(".")[0])
