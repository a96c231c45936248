"""The second adversarial pass's refusals for a study and the CLI: a sweep or search that asks more than
the machine holds is refused before any work (no grid listed, no cluster started, no folder made); a malformed
--scheduler, an --out too long for the file system and a refused storage URL are each one line, exit 2, with nothing
left behind; Dask workers take Ctrl-C by default. Each test failed on the code before (a grid listed, a traceback,
ENAMETOOLONG, an empty folder left, KeyboardInterrupt in the workers)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from magfab.cli import main
from magfab.inverse import run


def _no_work(monkeypatch) -> None:
    """Listing a grid or starting a cluster fails the test: a refusal must come before either."""
    def listed(*_a, **_k):
        raise AssertionError("the grid was listed before the refusal")

    def started(*_a, **_k):
        raise AssertionError("a cluster was started before the refusal")

    monkeypatch.setattr(run, "grid", listed)
    monkeypatch.setattr(run, "client", started)


def _one_line(result, *words: str) -> None:
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("magfab: error: ") and "Traceback" not in result.output, lines
    assert all(w in lines[0] for w in words), lines[0]


@pytest.mark.parametrize("args, words", [
    (["--grid", "50"], ["--grid 50", "study.trials = 300"]),  # the default variables: billions of designs, counted
    (["--lhs", "1000000"], ["--lhs 1000000", "study.trials = 300"]),
    (["--lhs", "10", "--workers", "256"], ["--workers 256", "at most", "os.cpu_count()"]),
])
def test_a_sweep_past_the_machine_is_refused_before_any_work(tmp_path, monkeypatch, args, words):
    _no_work(monkeypatch)
    (tmp_path / "t.toml").write_text("")
    result = CliRunner().invoke(main, ["sweep", str(tmp_path / "t.toml"), "--out", str(tmp_path / "s"), *args])
    _one_line(result, *words)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.toml"]


def test_a_search_with_more_workers_than_cores_is_refused_before_any_work(tmp_path, monkeypatch):
    _no_work(monkeypatch)
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    (tmp_path / "t.toml").write_text("")
    result = CliRunner().invoke(main, ["design", str(tmp_path / "t.toml"), "--out", str(tmp_path / "d"),
                                       "--workers", "3"])
    _one_line(result, "--workers 3", "at most 2", "os.cpu_count() = 2")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.toml"]


# ---- the CLI's one-line refusals ----------------------------------------------------------------------------------


def _magfab(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "magfab.cli", *args], cwd=cwd, capture_output=True, text=True,
                          timeout=300)


@pytest.mark.parametrize("address", ["garbage", "tcp://localhost:notaport", "tcp://localhost:99999", "tcp://:",
                                     "tcp://127.0.0.1:8786\nsecond line", "tcp://127.0.0.1:87\r86"])
def test_a_malformed_scheduler_address_is_one_line(tmp_path, address):
    (tmp_path / "t.toml").write_text("[study]\ntrials = 2")
    run_ = _magfab("design", "t.toml", "--scheduler", address, cwd=tmp_path)
    assert run_.returncode == 2 and "--scheduler" in run_.stderr and "Traceback" not in run_.stderr, run_.stderr
    assert len(run_.stderr.strip().splitlines()) == 1 and sorted(p.name for p in tmp_path.iterdir()) == ["t.toml"]


@pytest.mark.parametrize("command", ["build", "design", "sweep", "calibrate"])
@pytest.mark.parametrize("where", ["name", "beside", "path"])
def test_an_out_path_too_long_for_the_file_system_is_one_line(tmp_path, monkeypatch, command, where):
    """A name over the file system's 255 bytes, one that leaves no room for magfab's temporaries beside it, or a
    path over PATH_MAX: refused before any work (ENAMETOOLONG halfway, exit 1, before)."""
    _no_work(monkeypatch)
    out = {"name": tmp_path / ("x" * 300), "beside": tmp_path / ("x" * 250),
           "path": tmp_path.joinpath(*["y" * 200] * 21)}[where]
    (tmp_path / "t.toml").write_text("")
    args = [command, str(tmp_path / "t.toml"), "--out", str(out)] + (["--lhs", "2"] if command == "sweep" else [])
    result = CliRunner().invoke(main, args)
    _one_line(result, "--out", "at most")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.toml"]


def test_a_refused_storage_leaves_no_folder(tmp_path):
    (tmp_path / "t.toml").write_text('[study]\ntrials = 2\nstorage = "nosuchdb://nowhere/x"\n')
    run_ = _magfab("design", "t.toml", "--workers", "1", "--out", "a/b/study", cwd=tmp_path)
    assert run_.returncode == 2 and "study.storage" in run_.stderr, run_.stderr
    assert len(run_.stderr.strip().splitlines()) == 1 and sorted(p.name for p in tmp_path.iterdir()) == ["t.toml"]


def _sigint() -> str:
    blocked = signal.SIGINT in signal.pthread_sigmask(signal.SIG_BLOCK, [])
    return f"{signal.getsignal(signal.SIGINT)!r} blocked={blocked}"


def test_dask_workers_take_ctrl_c_by_default(monkeypatch):
    """A local cluster's workers end on Ctrl-C as any process does by default (no KeyboardInterrupt, no traceback),
    whatever handler magfab runs under, and the caller's own handling is back once the cluster is up."""
    from magfab.inverse.study import client

    def mine(*_a):
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGINT, mine)
    try:
        with client(None, 1) as c:
            states = set(c.run(_sigint).values())
            assert signal.getsignal(signal.SIGINT) is mine
            assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, [])
    finally:
        signal.signal(signal.SIGINT, previous)
    assert states == {f"{signal.SIG_DFL!r} blocked=False"}
