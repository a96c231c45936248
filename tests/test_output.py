"""The output folder (magfab/output.py): user files are never lost, nor folders beside the build that only look
like magfab's temporaries; the swap leaves a build at the path at every step (an exchange; the two renames where
the file system refuses it) and survives a kill at every step, errors and interrupts at every step, concurrent
writers, a full disk and a read-only folder.

Fake artifacts stand in for a build (the writer does not care what is in them, only that a manifest lists
them); one test goes through ``magfab calibrate`` on the session's real default build."""

from __future__ import annotations

import dataclasses
import errno
import fcntl
import importlib
import json
import os
import random
import shutil
import signal
import time
import traceback

import pytest
from adversarial_support import LOOK_ALIKES, make_look_alike
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from magfab import output
from magfab.errors import OutputError
from magfab.output import Artifact, check_target, write


def _fake(tag: str, *extra: str) -> list[Artifact]:
    """A build: files under a tag, and a manifest listing them as build.py's does."""
    files = [Artifact(f"parts/{tag}.stl", tag.encode() * 100, ""), Artifact("report.html", f"<p>{tag}".encode(), "")]
    files += [Artifact(p, f"{tag} {p}".encode(), "") for p in extra]
    listing = [{"path": a.path, "sha256": "", "bytes": len(a.data), "description": ""} for a in files]
    manifest = json.dumps({"magfab_version": "test", "tag": tag, "artifacts": listing}).encode()
    return [*files, Artifact("manifest.json", manifest, "")]


def _tree(folder) -> dict[str, bytes | str | None]:
    """Everything under a folder: files by bytes, links by target, empty folders as None."""
    found: dict[str, bytes | str | None] = {}
    for root, dirs, files in os.walk(folder):
        rel = os.path.relpath(root, folder)
        for name in dirs + files:
            path, key = os.path.join(root, name), os.path.normpath(os.path.join(rel, name))
            if os.path.islink(path):
                found[key] = "-> " + os.readlink(path)
            elif os.path.isfile(path):
                with open(path, "rb") as fh:
                    found[key] = fh.read()
            elif not os.listdir(path):
                found[key] = None
    return found


def _expected(tag: str, user: dict, *extra: str) -> dict:
    return {**{a.path: a.data for a in _fake(tag, *extra)}, **user}


def _add_user_files(out) -> dict:
    """What a user leaves in a build: a scan, a note inside a magfab folder, a folder of their own, a link."""
    (out / "scan.csv").write_bytes(b"x_mm,y_mm,z_mm,Bx_G\n0,0,1,2\n")
    (out / "parts" / "mine.txt").write_bytes(b"\x00\xffmy notes")
    (out / "bench" / "day1").mkdir(parents=True)
    (out / "bench" / "day1" / "log.txt").write_bytes(b"log")
    (out / "empty").mkdir()
    os.symlink("scan.csv", out / "latest.csv")
    return {"scan.csv": b"x_mm,y_mm,z_mm,Bx_G\n0,0,1,2\n", "parts/mine.txt": b"\x00\xffmy notes",
            "bench/day1/log.txt": b"log", "empty": None, "latest.csv": "-> scan.csv"}


def _beside(out) -> list[str]:
    return sorted(os.listdir(out.parent))


@pytest.fixture
def built(tmp_path):
    """An earlier build with the user's files in it; returns (out, the user's files)."""
    out = tmp_path / "out"
    write(out, _fake("old"))
    return out, _add_user_files(out)


# ---- 1. user files are never lost ----

def test_user_files_survive_build_and_rebuild(built):
    out, user = built
    inode = os.stat(out / "scan.csv").st_ino
    write(out, _fake("new"))
    assert _tree(out) == _expected("new", user)  # parts/old.stl (magfab's) went, the user's stayed
    assert os.stat(out / "scan.csv").st_ino == inode  # the same file, not a copy
    write(out, _fake("newer", "bench/summary.md"))  # into the user's folder: allowed
    assert _tree(out) == _expected("newer", user, "bench/summary.md")
    assert _beside(out) == ["out"]


def test_a_user_file_where_the_build_writes_stops_it_before_anything_changes(built):
    out, _user = built
    before = _tree(out)
    for clash in (_fake("new", "scan.csv"), _fake("new", "empty"), _fake("new", "scan.csv/inner"),
                  _fake("new", "latest.csv")):
        with pytest.raises(OutputError, match=r"(scan\.csv|empty|latest\.csv).* is not magfab's"):
            write(out, clash)
        assert _tree(out) == before and _beside(out) == ["out"]


def test_a_folder_that_is_not_a_build_is_refused(tmp_path):
    precious = tmp_path / "thesis"
    precious.mkdir()
    (precious / "chapter1.tex").write_text("do not delete")
    for call in (lambda: check_target(precious), lambda: write(precious, _fake("new"))):
        with pytest.raises(OutputError, match="not an earlier magfab build"):
            call()
    assert _tree(precious) == {"chapter1.tex": b"do not delete"} and _beside(precious) == ["thesis"]


def test_files_in_an_empty_target_are_the_users(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    write(out, _fake("new"))
    (out / "scan.csv").write_text("1")
    write(out, _fake("newer"))
    assert _tree(out) == _expected("newer", {"scan.csv": b"1"})


def test_a_file_the_user_adds_while_the_build_swaps_is_kept(built, monkeypatch):
    out, user = built

    def hook(what):
        if what == "journal written":  # after the user's files were linked into the new build
            (out / "late.csv").write_bytes(b"late")

    monkeypatch.setattr(output, "_step_hook", hook)
    write(out, _fake("new"))
    assert _tree(out) == _expected("new", {**user, "late.csv": b"late"})


def test_a_manifest_without_a_list_marks_every_file_as_magfabs(tmp_path):
    """No magfab wrote one (its manifests always list the artifacts); test doubles such as test_cli's do."""
    out = tmp_path / "out"
    write(out, [Artifact("manifest.json", b'{"magfab_version": "test"}', ""), Artifact("a.txt", b"a", "")])
    write(out, _fake("new"))
    assert _tree(out) == _expected("new", {})


def test_an_output_folder_under_a_file_is_refused(tmp_path):
    (tmp_path / "file").write_text("x")
    for call in (lambda: check_target(tmp_path / "file" / "out"), lambda: write(tmp_path / "file" / "out", _fake("a"))):
        with pytest.raises(OutputError, match=r"cannot write .*file"):
            call()
    assert _beside(tmp_path / "file") == ["file"]


def _calibrating(default_build, tmp_path, monkeypatch):
    """A copy of the session's default build with a scan.csv in it, and ``magfab calibrate`` whose plan is that
    build (a rebuild of the same spec): the CLI, build() and write() run. Returns (folder, scan bytes, the
    (spec, scan) pairs plan was called with, the CLI runner)."""
    from click.testing import CliRunner

    from magfab.cli import main

    out = tmp_path / "magone"
    shutil.copytree(default_build.out_dir, out)
    scan = (out / "calibration" / "scan_simulated.csv").read_bytes()
    (out / "scan.csv").write_bytes(scan)
    calls = []

    def plan(spec, progress=None, scan=None):
        calls.append((spec, scan))
        return dataclasses.replace(default_build, out_dir=None, timings_s=dict(default_build.timings_s))

    monkeypatch.setattr(importlib.import_module("magfab.pipeline"), "plan", plan)
    return out, scan, calls, lambda *args: CliRunner().invoke(main, ["calibrate", *args])


def test_a_scan_in_the_real_build_folder_survives_calibrate(default_build, tmp_path, monkeypatch):
    """``magfab calibrate build/x/scan.csv`` (the README's bench steps) rebuilds the folder the scan is in."""
    out, scan, calls, calibrate = _calibrating(default_build, tmp_path, monkeypatch)
    result = calibrate(str(out / "scan.csv"), "--out", str(out))
    assert result.exit_code == 0, result.output
    assert calls and calls[0][1] is not None  # the scan was read from the folder before it was rebuilt
    assert (out / "scan.csv").read_bytes() == scan
    assert _tree(out) == {**_tree(default_build.out_dir), "scan.csv": scan}
    assert _beside(out) == ["magone"]


def test_calibrate_inside_the_build_folder_updates_it_in_place(default_build, tmp_path, monkeypatch):
    """``cd build/magone && magfab calibrate scan.csv``: no --spec, no nested build/, the same folder (a shell
    standing in it stays in the build), the spec read back from the folder's spec.json."""
    out, scan, calls, calibrate = _calibrating(default_build, tmp_path, monkeypatch)
    monkeypatch.chdir(out)
    inode = os.stat(out).st_ino
    result = calibrate("scan.csv")
    assert result.exit_code == 0, result.output
    assert [spec for spec, _ in calls] == [default_build.spec]
    assert os.stat(out).st_ino == inode and not (out / "build").exists()
    assert _tree(out) == {**_tree(default_build.out_dir), "scan.csv": scan}
    assert "next: pip install ./readout && magfab-readout upload" in result.output
    other = tmp_path / "other.toml"
    other.write_text('name = "other"\n')
    result = calibrate("scan.csv", "--spec", str(other))
    assert result.exit_code == 2 and "holds 'magone'" in result.output and len(calls) == 1


# ---- 2. the swap: kills, errors and interrupts at every step ----

def _steps(out, tags=("new",), in_place=None) -> list[str]:
    """The steps of one uninterrupted write over ``out`` (on a copy, so ``out`` is untouched)."""
    copy = out.parent / "count" / out.name
    shutil.copytree(out, copy, symlinks=True)
    seen: list[str] = []
    output._step_hook = seen.append
    try:
        write(copy, _fake(*tags), in_place=in_place)
    finally:
        output._step_hook = None
    shutil.rmtree(copy.parent)
    return seen


def _killed_at(k: int, call) -> int:
    """Run ``call`` in a child that SIGKILLs itself at its k-th step; the child's wait status."""
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        count = iter(range(k + 1))

        def hook(what):
            if next(count) == k:
                os.kill(os.getpid(), signal.SIGKILL)

        output._step_hook = hook
        try:
            call()
        finally:
            os._exit(0)
    return os.waitpid(pid, 0)[1]


@pytest.fixture(params=["exchange", "two renames"])
def swap(request, monkeypatch):
    """How the folders are swapped: in one step, or (where the file system refuses the exchange) by two renames."""
    if request.param == "two renames":
        monkeypatch.setattr(output, "exchange", lambda a, b: False)
    return request.param


def test_a_kill_at_every_step_leaves_the_old_or_the_new_build(built, swap):
    """At the path, before any recovery: the old build or the new one at every step (the two renames' only
    window, the documented one, is after the first), and after the next run's recovery with nothing beside it."""
    out, user = built
    old, new = _tree(out), _expected("new", user)
    steps = _steps(out)
    assert len(steps) >= 10 and (swap == "exchange" or "previous moved aside" in steps)
    for k, step in enumerate(steps):
        status = _killed_at(k, lambda: write(out, _fake("new")))
        assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, step
        if swap == "exchange" or step != "previous moved aside":
            assert _tree(out) in (old, new), f"killed after {step!r}: no complete build at the path"
        check_target(out)  # the recovery call
        assert _tree(out) in (old, new), f"killed after {step!r}"
        assert _beside(out) == ["out"], f"killed after {step!r}"
        write(out, _fake("old"))  # back to the old build for the next step
        assert _tree(out) == old


def test_in_place_a_kill_at_every_step_leaves_the_old_or_the_new_build(built):
    """The update for a shell standing in the folder (magfab calibrate inside it): file by file, journalled."""
    out, user = built
    old, new = _tree(out), _expected("new", user)
    steps = _steps(out, in_place=True)
    assert "in-place update committed" in steps and "previous moved aside" not in steps
    for k, step in enumerate(steps):
        status = _killed_at(k, lambda: write(out, _fake("new"), in_place=True))
        assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, step
        check_target(out)
        assert _tree(out) in (old, new), f"killed after {step!r}"
        assert _beside(out) == ["out"], f"killed after {step!r}"
        write(out, _fake("old"), in_place=True)
        assert _tree(out) == old


def test_a_build_into_the_working_folder_keeps_the_folder(built, monkeypatch):
    """A shell standing in the build folder stays in the build: the folder is updated, not swapped."""
    out, user = built
    inode = os.stat(out).st_ino
    monkeypatch.chdir(out / "parts")
    write(out, _fake("new"))
    assert os.stat(out).st_ino == inode and os.path.samefile(".", out / "parts")
    assert _tree(out) == _expected("new", user) and _beside(out) == ["out"]
    monkeypatch.chdir(out.parent)
    write(out, _fake("old"))
    assert os.stat(out).st_ino != inode  # elsewhere, the folder is swapped as before


@pytest.mark.slow
def test_a_kill_at_every_step_of_the_write_then_of_its_recovery(built):
    out, user = built
    old, new = _tree(out), _expected("new", user)
    for k, step in enumerate(_steps(out)):
        for j in range(20):
            _killed_at(k, lambda: write(out, _fake("new")))
            status = _killed_at(j, lambda: check_target(out))
            check_target(out)
            assert _tree(out) in (old, new), f"killed after {step!r}, then at step {j} of the recovery"
            assert _beside(out) == ["out"]
            write(out, _fake("old"))
            if not os.WIFSIGNALED(status):
                break


def test_a_build_is_at_the_path_at_every_instant_of_a_rebuild(built):
    """A second process stats the build's manifest as fast as it can while builds replace it: never missing."""
    out, _user = built
    ready, stop = os.pipe(), os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child: the watcher
        looks = misses = 0
        os.write(ready[1], b"1")
        os.set_blocking(stop[0], False)
        while True:
            try:
                if os.read(stop[0], 1):
                    break
            except BlockingIOError:
                pass
            looks += 1
            misses += not os.path.isfile(out / "manifest.json")
        os.write(ready[1], f"{looks} {misses}".encode())
        os._exit(0)
    os.read(ready[0], 1)
    for k in range(30):
        write(out, _fake(f"w{k % 2}"))
    os.write(stop[1], b"x")
    os.waitpid(pid, 0)
    looks, misses = map(int, os.read(ready[0], 100).split())
    assert looks > 30 and misses == 0


def test_a_kill_between_the_two_renames_is_undone_by_the_next_run(built, monkeypatch):
    """Killed after the previous build was moved aside, before the new one landed (the two renames, where the
    file system refuses the exchange: the documented window)."""
    monkeypatch.setattr(output, "exchange", lambda a, b: False)
    out, _user = built
    old = _tree(out)
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        real, calls = os.rename, []

        def rename(src, dst):
            calls.append(src)
            if len(calls) == 2:
                os.kill(os.getpid(), signal.SIGKILL)
            real(src, dst)

        os.rename = rename
        try:
            write(out, _fake("new"))
        finally:
            os._exit(0)
    assert os.WIFSIGNALED(os.waitpid(pid, 0)[1])
    check_target(out)
    assert _tree(out) == old and _beside(out) == ["out"]


def test_in_place_a_kill_in_the_write_then_in_its_rollback_loses_nothing(tmp_path):
    """Killed at any step of an in-place update that empties a folder and makes one, then at any step of the
    rollback the next run does: the run after that finds the previous build or the new one, byte for byte."""
    out = tmp_path / "out"
    write(out, _fake("old", "gone/old.txt"), in_place=False)
    (out / "scan.csv").write_bytes(b"mine")
    old = _tree(out)
    new = {**_expected("new", {"scan.csv": b"mine"}, "fresh/deep/new.txt")}
    steps = _steps(out, ("new", "fresh/deep/new.txt"), in_place=True)
    assert "removed gone/old.txt" in steps
    for k, step in enumerate(steps):
        for j in range(40):
            _killed_at(k, lambda: write(out, _fake("new", "fresh/deep/new.txt"), in_place=True))
            status = _killed_at(j, lambda: check_target(out))
            check_target(out)
            assert _tree(out) in (old, new), f"killed after {step!r}, then at step {j} of the recovery"
            assert _beside(out) == ["out"]
            write(out, _fake("old", "gone/old.txt"), in_place=True)
            assert _tree(out) == old
            if not os.WIFSIGNALED(status):
                break


@pytest.mark.parametrize("error", [OSError(errno.ENOSPC, "No space left on device"), KeyboardInterrupt()],
                         ids=["ENOSPC", "interrupt"])
@pytest.mark.parametrize("in_place", [False, True], ids=["swap", "in-place"])
def test_an_error_at_every_step_leaves_a_complete_build_and_no_temporaries(built, error, in_place):
    """A swap leaves the old or the new build; an in-place update the old one until its commit."""
    out, user = built
    old, new = _tree(out), _expected("new", user)
    steps = _steps(out, in_place=in_place)
    commit = steps.index("in-place update committed" if in_place else "new in place")
    for k, step in enumerate(steps):
        count = iter(range(len(steps) * 3))

        def hook(what, k=k, count=count):
            if next(count) == k:
                raise error

        output._step_hook = hook
        try:
            with pytest.raises(KeyboardInterrupt if isinstance(error, KeyboardInterrupt) else OutputError) as raised:
                write(out, _fake("new"), in_place=in_place)
        finally:
            output._step_hook = None
        if raised.type is OutputError:
            assert str(raised.value) == f"cannot write {out}: No space left on device"
        assert _tree(out) == (old if k < commit else new) or (not in_place and _tree(out) == old), f"after {step!r}"
        assert _beside(out) == ["out"], f"failed after {step!r}"
        write(out, _fake("old"), in_place=in_place)


def test_stale_temporaries_on_record_are_removed_and_others_kept(built, tmp_path):
    """What a killed run's lock log lists goes; a name that merely looks like a temporary stays."""
    out, _user = built
    old = _tree(out)
    stale = (".out.tmp-0123456789abcdef", ".out.old-fedcba9876543210", ".out.tmp-00000000000000aa")
    for name in (*stale, ".out.tmp-abcd_123", ".out.old-1111111111111111"):
        (tmp_path / name / "parts").mkdir(parents=True)
        (tmp_path / name / "parts" / "x.stl").write_text("partial")
    (tmp_path / ".out.swap").write_text('{"old": ".out.old-')  # cut short by a kill
    # its holder was killed: it had made three (one was gone), and named one outside the pattern
    (tmp_path / ".out.lock").write_text("99999999\n+" + "\n+".join(stale) + "\n+.out.old-1111\n+../x\n-.out.tmp-"
                                        "00000000000000aa\n+.out.tmp-00000000000000aa\n+.out.tmp-")
    keep = [".out.tmp-mine", ".outer.tmp-0123456789abcdef", ".out.tmp-0123456789abcdef.bak", ".out.tmp-abcd_123",
            ".out.old-1111111111111111"]
    for name in keep[:3]:
        (tmp_path / name).write_text("not magfab's")
    check_target(out)
    assert _beside(out) == sorted(["out", *keep]) and _tree(out) == old


def test_a_folder_like_a_temporary_of_an_older_magfab_is_left_alone(tmp_path):
    """No record names them, so nothing removes or moves them: not even a stranded-looking previous build."""
    out = tmp_path / "out"
    write(out, _fake("old"))
    (tmp_path / ".out.old-k2j_9x0a").mkdir()
    os.rename(out, tmp_path / ".out.old-k2j_9x0a" / "previous")
    (tmp_path / ".out.tmp-q8w7e6r5").mkdir()
    assert check_target(out) == out
    write(out, _fake("new"))
    assert _beside(out) == [".out.old-k2j_9x0a", ".out.tmp-q8w7e6r5", "out"]
    assert _tree(tmp_path / ".out.old-k2j_9x0a") == {f"previous/{k}": v for k, v in _expected("old", {}).items()}


def test_a_users_folder_named_like_a_temporary_survives_a_build(tmp_path):
    """The reported case: ``build/.magone.old-20241128`` beside ``build/magone``, through a build, a rebuild, a
    kill's recovery and a journal that names it."""
    out = tmp_path / "magone"
    mine = tmp_path / ".magone.old-20241128"
    (mine / "parts").mkdir(parents=True)
    (mine / "parts" / "tip.stl").write_bytes(b"my backup")
    write(out, _fake("old"))
    write(out, _fake("new"))
    _killed_at(4, lambda: write(out, _fake("newer")))
    (tmp_path / ".magone.swap").write_text('{"old": ".magone.old-20241128"}')
    check_target(out)
    write(out, _fake("old"))
    assert _tree(mine) == {"parts/tip.stl": b"my backup"}
    assert _beside(out) == [".magone.old-20241128", "magone"] and _tree(out) == _expected("old", {})


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(["magone", "out", "my.finger-2"]), look_alikes=LOOK_ALIKES, killed=st.booleans())
def test_no_folder_named_like_a_temporary_is_removed(tmp_path_factory, name, look_alikes, killed):
    """Generated: names built from magfab's temporary patterns with random suffixes and dates, as folders (full
    and empty), files and links beside the build; a build, a rebuild (after a run killed mid-build when
    ``killed``, whose own temporary must go) and the recovery leave every one byte for byte."""
    root = tmp_path_factory.mktemp("beside")
    out = root / name
    write(out, _fake("old"))
    made = {}
    for kind, suffix, shape in look_alikes:
        path = make_look_alike(root, name, kind, suffix, shape)
        made[path.name] = _tree(path) if path.is_dir() and not path.is_symlink() else os.readlink(path) \
            if path.is_symlink() else path.read_bytes()
    if killed:
        status = _killed_at(3, lambda: write(out, _fake("half")))  # after the temporary was made
        assert os.WIFSIGNALED(status)
    check_target(out)
    write(out, _fake("new"))
    for n, content in made.items():
        path = root / n
        assert (_tree(path) if path.is_dir() and not path.is_symlink() else os.readlink(path)
                if path.is_symlink() else path.read_bytes()) == content, n
    assert _beside(out) == sorted([name, *made]) and _tree(out) == _expected("new", {})
    shutil.rmtree(root)


# ---- concurrent writers ----

def _writer(out, tag: str, times: int) -> int:
    """Child: ``times`` writes with random pauses between steps; 0 done, 3 refused (OutputError), 1 a traceback."""
    rng = random.Random(tag)
    output._step_hook = lambda what: rng.random() < 0.3 and time.sleep(rng.random() * 0.003)
    try:
        for _ in range(times):
            write(out, _fake(tag))
        return 0
    except OutputError:
        return 3
    except BaseException:
        traceback.print_exc()
        return 1


def test_concurrent_writers_to_one_folder_all_finish_with_a_complete_build(built):
    out, user = built
    tags = [f"w{i}" for i in range(4)]
    pids = []
    for tag in tags:
        pid = os.fork()
        if pid == 0:  # pragma: no cover - the child
            os._exit(_writer(out, tag, 6))
        pids.append(pid)
    codes = [os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]) for pid in pids]
    assert codes == [0] * len(tags)
    assert _tree(out) in [_expected(tag, user) for tag in tags]
    assert _beside(out) == ["out"]


def test_a_second_writer_that_cannot_wait_is_refused_naming_the_first(built):
    out, _user = built
    before = _tree(out)
    fd = os.open(out.parent / ".out.lock", os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        os.write(fd, b"4242\n")
        with pytest.raises(OutputError, match=r"another magfab build \(process 4242\) is writing .*out"):
            write(out, _fake("new"), lock_timeout_s=0.2)
        assert check_target(out) == out  # does not wait, and leaves the holder's files alone
    finally:
        os.close(fd)
    assert _tree(out) == before


# ---- a full disk, a read-only folder ----

def test_a_full_disk_is_one_line_naming_the_file_and_nothing_is_lost(built, monkeypatch):
    out, _user = built
    before = _tree(out)
    real_open = open

    class Full:
        def __init__(self, f):
            self.f = f

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

        def write(self, data):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def full_open(path, mode="r", *args, **kwargs):
        f = real_open(path, mode, *args, **kwargs)
        return Full(f) if str(path).endswith(".stl") else f

    monkeypatch.setattr(output, "open", full_open, raising=False)
    with pytest.raises(OutputError) as raised:
        write(out, _fake("new"))
    assert str(raised.value) == f"cannot write {out / 'parts' / 'new.stl'}: No space left on device"
    assert _tree(out) == before and _beside(out) == ["out"]


@pytest.mark.parametrize("fail", ["lock", "mkdir", "rename", "exchange"])
def test_a_read_only_folder_is_one_line_naming_it_and_nothing_is_lost(built, monkeypatch, fail):
    """Simulated (root ignores permissions): the first call that needs the parent writable fails with EACCES
    (the rename: on the two renames' path, where the file system refuses the exchange)."""
    out, _user = built
    before = _tree(out)
    if fail == "exchange":
        def refused(a, b):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(a))

        monkeypatch.setattr(output, "exchange", refused)
        fail = "rename"
    elif fail == "rename":
        monkeypatch.setattr(output, "exchange", lambda a, b: False)
    real = {"lock": os.open, "mkdir": os.mkdir, "rename": os.rename}[fail]

    def denied(path, *args, **kwargs):
        if os.path.dirname(os.path.abspath(path)) == str(out.parent) and \
                (fail != "lock" or str(path).endswith(".lock")):
            raise PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path))
        return real(path, *args, **kwargs)

    monkeypatch.setattr(os, {"lock": "open", "mkdir": "mkdir", "rename": "rename"}[fail], denied)
    with pytest.raises(OutputError) as raised:
        write(out, _fake("new"))
    named = out if fail == "rename" else out.parent  # the folder it could not rename, or create in
    assert str(raised.value) == f"cannot write {named}: Permission denied"
    monkeypatch.undo()
    assert _tree(out) == before and _beside(out) == ["out"]


@pytest.mark.parametrize("which", ["parent", "out"])
def test_a_read_only_folder_is_refused_before_any_work(built, monkeypatch, which):
    out, _user = built
    folder = out.parent if which == "parent" else out
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda p, mode, **kw: str(p) != str(folder) and real_access(p, mode, **kw))
    with pytest.raises(OutputError, match=f"^cannot write {folder}: Permission denied$"):
        check_target(out)


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores folder permissions (the simulated tests cover it)")
@pytest.mark.parametrize("which", ["parent", "out"])
def test_a_really_read_only_folder(built, which):
    out, _user = built
    before = _tree(out)
    folder = out.parent if which == "parent" else out
    folder.chmod(0o555)
    try:
        with pytest.raises(OutputError, match=f"cannot write {folder}: Permission denied"):
            write(out, _fake("new"))
    finally:
        folder.chmod(0o755)
    assert _tree(out) == before and _beside(out) == ["out"]


@pytest.mark.parametrize("kind", ["fifo", "deep", "dev zero"])
def test_a_manifest_that_is_no_file_of_magfabs_is_not_a_build(tmp_path, kind):
    """manifest.json as a FIFO (a plain read waits forever), a link to /dev/zero (it reads until memory runs out) or
    nested past Python's recursion limit: read within bounds, the folder is not a magfab build, at once."""
    from magfab.output import is_build

    manifest = tmp_path / "manifest.json"
    if kind == "fifo":
        os.mkfifo(manifest)
    elif kind == "deep":
        manifest.write_text('{"magfab_version": ' + "[" * 5000 + "]" * 5000 + "}")
    else:
        manifest.symlink_to("/dev/zero")
    assert is_build(tmp_path) is False
