"""The command contract: exit codes, --json, init/check, and that bad input or an interrupt writes nothing."""

from __future__ import annotations

import hashlib
import importlib
import json
import os
import shutil
import subprocess
import sys

import pytest
from click.testing import CliRunner

from magfab.cli import main
from magfab.cli_progress import PROGRESS_LINE
from magfab.fork import parallel_available


def run(*args: str, cwd=None, env=None):
    """The console script as a user runs it: a fresh process (``env``: added to the environment)."""
    return subprocess.run([sys.executable, "-m", "magfab.cli", *args], capture_output=True, text=True, cwd=cwd,
                          timeout=300, env=None if env is None else {**os.environ, **env})


def _snapshot(path):
    return {p.relative_to(path): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()}


def test_build_default_writes_parts_a_true_manifest_and_a_json_summary(tmp_path, default_build):
    """One fresh process, as a user runs it: the default output folder, every hash true, --json quiet. It runs in
    one process (MAGFAB_JOBS=1) while the session's build ran its physics branch in a forked worker where it could:
    same spec, same bytes, whichever way the work was split and whichever process did it."""
    proc = run("build", "--json", cwd=tmp_path, env={"MAGFAB_JOBS": "1"})
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""  # quiet: no progress when not a terminal
    out = tmp_path / "build" / "magone"
    manifest = json.loads((out / "manifest.json").read_text())
    listed = {a["path"] for a in manifest["artifacts"]}
    for stem in ("elastomer", "mould_cup", "mould_lid", "pad"):
        assert {f"{stem}.stl", f"{stem}.step"} <= listed
    for a in manifest["artifacts"]:
        assert hashlib.sha256((out / a["path"]).read_bytes()).hexdigest() == a["sha256"]
    assert manifest["spec_sha256"] and manifest["magfab_version"]
    assert sorted(p.name for p in (tmp_path / "build").iterdir()) == ["magone"]  # no temp folders left
    summary = json.loads(proc.stdout)
    assert summary["figures"]["d_rest_mm"] == pytest.approx(6.0)
    assert set(summary["artifacts"]) == listed | {"manifest.json"}  # the manifest lists all but itself
    assert isinstance(summary["findings"], list)
    assert "wait-physics" not in summary["timings_s"]
    assert ("wait-physics" in default_build.timings_s) == parallel_available()
    written = {p: (out / p).read_bytes() for p in listed | {"manifest.json"}}
    assert {a.path: a.data for a in default_build.artifacts} == written


def _previous_build(default_build, tmp_path):
    """A copy of the session's MagOne build, standing in for the output a user already has."""
    out = tmp_path / "out"
    shutil.copytree(default_build.out_dir, out)
    return out


@pytest.mark.parametrize(
    "text, key",
    [
        ("[magnet]\ndiameter_mm = -2", "magnet.diameter_mm"),
        ("[magnet]\ndiameter_mm = 11.5", "magnet.diameter_mm"),
        ("[sensor]\nd_max_mm = 1.2", "sensor.d_max_mm"),
        ('[mould]\nprinter = "fdm"\nwall_mm = 0.5', "mould.wall_mm"),
        ("[elastomr]\n", "elastomr"),
    ],
)
def test_bad_spec_exits_2_names_the_key_and_keeps_the_previous_output(default_build, tmp_path, text, key):
    out = _previous_build(default_build, tmp_path)
    before = _snapshot(out)
    spec = tmp_path / "bad.toml"
    spec.write_text(text)
    proc = run("build", str(spec), "--out", str(out))
    assert proc.returncode == 2
    assert key in proc.stderr and "Traceback" not in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert _snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml", "out"]


def test_interrupt_mid_build_leaves_the_previous_output(default_build, tmp_path, monkeypatch):
    import magfab.export.cad

    out = _previous_build(default_build, tmp_path)
    before = _snapshot(out)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(magfab.export.cad, "stl_bytes", interrupted)
    result = CliRunner().invoke(main, ["build", "--out", str(out)])
    assert result.exit_code == 130
    assert _snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def _fake_build(tag: str):
    """Artifacts standing in for a build: a part and a manifest listing it, as a real build writes."""
    from magfab.output import Artifact

    part = Artifact(f"parts/{tag}.stl", tag.encode() * 100, "")
    manifest = json.dumps({"magfab_version": "test", "artifacts": [{"path": part.path}]}).encode()
    return [Artifact("manifest.json", manifest, ""), part]


def test_interrupt_while_writing_restores_the_previous_output(tmp_path, monkeypatch):
    from magfab import output as build_mod  # the only writer of the output folder
    out = tmp_path / "out"
    build_mod.write(out, _fake_build("old"))
    before = _snapshot(out)
    real_rename = os.rename
    calls = []

    def rename(src, dst):
        calls.append(src)
        if len(calls) == 2:  # the old output has been moved aside; now the new one fails to land
            raise KeyboardInterrupt
        return real_rename(src, dst)

    monkeypatch.setattr(build_mod.os, "rename", rename)
    monkeypatch.setattr(build_mod, "exchange", lambda a, b: False)  # the two renames, where Ctrl-C can fall between
    with pytest.raises(KeyboardInterrupt):
        build_mod.write(out, _fake_build("new"))
    monkeypatch.setattr(build_mod.os, "rename", real_rename)
    assert _snapshot(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # no temporaries left
    build_mod.write(out, _fake_build("new"))
    assert sorted(str(p) for p in _snapshot(out)) == ["manifest.json", "parts/new.stl"]


def test_refuses_to_replace_a_directory_that_is_not_a_build(tmp_path):
    precious = tmp_path / "thesis"
    precious.mkdir()
    (precious / "chapter1.tex").write_text("do not delete")
    proc = run("build", "--out", str(precious))
    assert proc.returncode == 2 and "not an earlier magfab build" in proc.stderr
    assert (precious / "chapter1.tex").read_text() == "do not delete"


def test_init_then_check(tmp_path, monkeypatch):
    """init writes once, check writes nothing; the build of the same spec that follows them in the README is run,
    as pasted, by the README's walk (tests/docs/test_pages.py)."""
    runner = CliRunner()
    monkeypatch.chdir(tmp_path)
    assert runner.invoke(main, ["init", "finger.toml"]).exit_code == 0
    again = runner.invoke(main, ["init", "finger.toml"])
    assert again.exit_code == 2 and "exists" in again.output
    checked = runner.invoke(main, ["check", "finger.toml"])
    assert checked.exit_code == 0 and "finger: ok" in checked.output
    assert sorted(os.listdir(".")) == ["finger.toml"]  # check writes nothing


def test_internal_error_is_one_line_exit_1(tmp_path, monkeypatch):
    build_mod = importlib.import_module("magfab.pipeline")

    def broken(*args, **kwargs):
        raise ZeroDivisionError("boom")

    monkeypatch.setattr(build_mod, "derive", broken)
    result = CliRunner().invoke(main, ["build", "--out", str(tmp_path / "o")])
    assert result.exit_code == 1 and "internal error: ZeroDivisionError: boom" in result.output
    assert not (tmp_path / "o").exists()


def test_help_is_fast_to_import():
    # `magfab --help` must not pull in the CAD kernel.
    code = "import sys, magfab.cli; assert 'cadquery' not in sys.modules and 'OCP' not in sys.modules"
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def test_importing_the_cli_leaves_sigint_alone():
    """The handler that makes Ctrl-C exit 130 is installed when a command runs, not as a side effect of import."""
    code = ("import signal; before = signal.getsignal(signal.SIGINT); import magfab.cli; "
            "assert signal.getsignal(signal.SIGINT) is before")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


@pytest.mark.parametrize("delay_s", [0.3, 1.0, 2.5])
def test_ctrl_c_at_any_moment_is_exit_130_in_one_line(tmp_path, delay_s):
    """Ctrl-C while the libraries load, while the branches run or while files are written: exit 130 and one
    line (after the lines of the stages done, the output not being a terminal), never a traceback, 'Aborted!'
    (click's exit 1) or an ImportError from a cut-short import; the folder holds nothing half-written. (The
    interpreter's own start-up, before magfab runs, is Python's.)"""
    import signal
    import time

    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "magfab.cli", "build", "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    time.sleep(delay_s)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    if "init_import_site" in err:  # a very busy machine was still starting the interpreter: not ours to handle
        return
    # 130, or killed by SIGINT after our line: CPython ends itself with SIGINT when a KeyboardInterrupt ended code an
    # extension ran through PyRun_* during an import, even once we caught it; a shell reads both as status 130
    assert proc.returncode in (0, 130, -signal.SIGINT), err
    assert "Traceback" not in err and "Aborted" not in err
    if proc.returncode != 0:  # one line for the interrupt, the last; before it only the stages done (stderr is a pipe)
        *done, last = err.strip().splitlines()
        assert all(PROGRESS_LINE.fullmatch(line) for line in done), err
        assert "interrupted" in last
        assert not out.exists() or (out / "manifest.json").is_file()


def test_init_copies_an_array_example(tmp_path, monkeypatch):
    from magfab.spec import load_spec

    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, ["init", "--example", "strip_1x5", "row.toml"])
    assert result.exit_code == 0, result.output
    spec = load_spec("row.toml")
    assert spec.name == "row" and spec.array.taxels == 5 and spec.array.pitch_mm == 14.0
    bad = CliRunner().invoke(main, ["init", "--example", "nope", "x.toml"])
    assert bad.exit_code == 2 and "fingertip_2x2" in bad.output


def _commands(group, path=()):
    """(words, command) of every magfab command, the sensor group's too."""
    import click

    for name, command in sorted(group.commands.items()):
        if isinstance(command, click.Group):
            yield from _commands(command, (*path, name))
        else:
            yield (*path, name), command


def _usage_mistakes():
    """For every command: an unknown option, and each required argument left out, and each typed option given a word
    its type refuses (an int, a float, a choice, an int range)."""
    import click

    for words, command in _commands(main):
        yield words, ["--no-such-option"], "No such option"
        required = [p for p in command.params if isinstance(p, click.Argument) and p.required]
        if required:
            yield words, [], "Missing argument"
        for p in command.params:
            if isinstance(p, click.Option) and not p.is_flag and isinstance(
                    p.type, (click.types.IntParamType, click.types.FloatParamType, click.Choice)):
                yield words, ["x.toml"] * len(required) + [p.opts[0], "not-a-value"], "Invalid value"


@pytest.mark.parametrize(("words", "args", "said"), list(_usage_mistakes()),
                         ids=lambda v: "-".join(v) if isinstance(v, tuple) else None)
def test_a_usage_mistake_is_one_line_and_exit_2(words, args, said, tmp_path):
    """click's own refusals (its three-line usage block before) are one line naming the mistake and the command's
    --help, exit 2, nothing on stdout, nothing written: generated for every command and every typed option."""
    before = sorted(tmp_path.rglob("*"))
    result = CliRunner().invoke(main, [*words, *args], prog_name="magfab", catch_exceptions=False)
    assert result.exit_code == 2, result.output
    err = result.stderr
    assert err.count("\n") == 1 and err.startswith("magfab: error: ") and said in err, err
    assert f"`magfab {' '.join(words)} --help` lists what is allowed" in err and result.stdout == ""
    assert sorted(tmp_path.rglob("*")) == before
