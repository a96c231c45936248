"""Every write of a sensor record survives a kill (SIGKILL) at every write system call: the record is left as it was
or with the whole new event, it reads, and running the command again completes it. As tests/test_output.py does for
the build folder's swap, the writer runs in a forked child that kills itself at its k-th step, here every call that
changes the file system (open for writing, write, fsync, link, unlink, mkdir, rename)."""

from __future__ import annotations

import json
import os
import shutil
import signal
from collections.abc import Callable
from pathlib import Path

import pytest
from click.testing import CliRunner
from sensor_support import calibration, check

from magfab.cli import main
from magfab.formats import sensor_records as rec
from magfab.sensors import SensorError, add_from_build

#: The os functions a record's writer changes the file system with.
WRITES = ("open", "write", "fsync", "link", "unlink", "mkdir", "rename", "replace")


def _counting(kill_at: int | None, seen: list[str]) -> None:
    """Wrap :data:`WRITES` so each call is counted (``seen``), and the process killed at call ``kill_at``."""
    for name in WRITES:
        real = getattr(os, name)

        def wrapped(*args, _real=real, _name=name, **kwargs):
            flags = args[1] if len(args) > 1 else kwargs.get("flags", 0)
            if _name == "open" and not flags & (os.O_WRONLY | os.O_RDWR):
                return _real(*args, **kwargs)  # a read
            if kill_at is not None and len(seen) == kill_at:
                os.kill(os.getpid(), signal.SIGKILL)
            seen.append(_name)
            return _real(*args, **kwargs)

        setattr(os, name, wrapped)


def _steps(call: Callable[[], object]) -> int:
    """How many write calls ``call`` makes, counted in a child (the parent's os is left alone)."""
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        os.close(r)
        seen: list[str] = []
        write = os.write
        _counting(None, seen)
        try:
            call()
            write(w, str(len(seen)).encode())
        finally:
            os._exit(0)
    os.close(w)
    with os.fdopen(r) as pipe:
        count = pipe.read()
    os.waitpid(pid, 0)
    return int(count)


def _killed_at(k: int, call: Callable[[], object]) -> int:
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        try:
            _counting(k, [])
            call()
        finally:
            os._exit(0)
    return os.waitpid(pid, 0)[1]


def _events(root: Path, sensor_id: str) -> list[dict]:
    """The record's events as a reader sees them (every kept file checked against its hash), or [] without one."""
    s = rec.Sensor(root, sensor_id)
    if not (s.path / "sensor.json").is_file():
        return []
    s.info  # noqa: B018 - it reads
    events = s.events()
    for e in events:
        for sha in e.get("files", {}).values():
            s.file(sha)
    return [{k: v for k, v in e.items() if k != "date"} for e in events]


def _every_kill(root: Path, sensor_id: str, call: Callable[[], object], rerun: Callable[[], object]) -> int:
    """Kill ``call`` at each of its write calls, on a fresh copy of ``root`` each time; check the record is the old
    one or the old one with the whole new event(s), then that ``rerun`` completes it. Returns the number of steps."""
    pristine = root.parent / "pristine"
    shutil.copytree(root, pristine)
    old = _events(root, sensor_id)
    steps = _steps(call)
    new = _events(root, sensor_id)
    assert len(new) > len(old) and new[:len(old)] == old
    assert steps >= 5
    outcomes = set()
    for k in range(steps):
        shutil.rmtree(root)
        shutil.copytree(pristine, root)
        status = _killed_at(k, call)
        assert os.WIFSIGNALED(status) and os.WTERMSIG(status) == signal.SIGKILL, k
        seen = _events(root, sensor_id)
        assert seen in (old, new), f"killed at write call {k} of {steps}"
        outcomes.add(seen == new)
        rerun()
        after = _events(root, sensor_id)
        added = len(new) - len(old)
        if seen == old:  # nothing had landed: the rerun writes the whole of it
            assert after == new, k
        else:  # the event had landed before the kill; running the command again appends it again (or, for add,
            # finds the record complete and refuses)
            assert after[:len(new)] == new and len(after) in (len(new), len(new) + added), k
    assert outcomes == {False, True}  # killed before the event landed, and after it (cleaning up)
    shutil.rmtree(pristine)
    return steps


def _fake_build(folder: Path, measured: bool = True) -> Path:
    """A build folder as far as ``sensor add`` reads one: manifest, spec, design, acceptance bands, and a calibration
    measured from a merged scan kept beside its recording and reference log."""
    (folder / "calibration").mkdir(parents=True)
    (folder / "manifest.json").write_text(json.dumps({"magfab_version": "0.1.0", "spec_sha256": "a" * 64}))
    (folder / "spec.json").write_text(json.dumps({"name": "magone"}))
    (folder / "design.json").write_text("{}")
    (folder / "calibration" / "acceptance.json").write_text(json.dumps({"rest": {"Bz_uT": {"min": 1, "max": 2}}}))
    source = "rec.csv + ref.csv" if measured else "simulated"
    (folder / "calibration" / "calibration.json").write_text(json.dumps(
        {"scan": {"source": source, "sha256": "b" * 64, "rows": 3},
         "errors": {"Fz_N": {"rms_holdout": 0.003}, "Fr_N": {"rms_holdout": 0.002}}, "method": "poly", "order": 4}))
    rows = "\n".join(f"{0.01 * i},0,{10 * i},{18000 + 50 * i},0,{0.01 * i},{0.02 * i}" for i in range(60))
    (folder / "calibration" / "scan_merged.csv").write_text("time_s,Bx_uT,By_uT,Bz_uT,Fx_N,Fy_N,Fz_N\n" + rows + "\n")
    (folder / "rec.csv").write_text("recording\n")
    (folder / "ref.csv").write_text("reference\n")
    return folder


def test_a_kill_in_add_leaves_no_record_or_the_whole_one(tmp_path: Path) -> None:
    build = _fake_build(tmp_path / "build")
    root = tmp_path / "lab" / "sensors"
    root.mkdir(parents=True)

    def add() -> None:
        add_from_build(root, "A", build, "2026-11-01")

    def rerun() -> None:
        if (root / "A" / "sensor.json").is_file():  # the record was whole before the kill: add refuses it
            with pytest.raises(SensorError, match="already has a record"):
                add()
        else:
            add()

    steps = _every_kill(root, "A", add, rerun)
    assert steps >= 20  # marker, three kept files per event, two events, sensor.json
    events = _events(root, "A")
    assert [e["kind"] for e in events] == ["added", "calibration"]
    assert set(events[1]["files"]) == {"calibration.json", "scan_merged.csv", "scan.csv", "reference.csv"}


@pytest.fixture
def sensor(tmp_path: Path) -> rec.Sensor:
    root = tmp_path / "lab" / "sensors"
    s = rec.create(root, "A", {"spec_name": "magone"}, {"spec.json": b"{}"}, date="2026-10-01T00:00:00Z")
    data, files = calibration(n=1)
    s.append("calibration", data, files, date="2026-10-02T00:00:00Z")
    return s


APPENDS = {
    "calibration": lambda: ("calibration", *calibration(n=7)),
    "check": lambda: ("check", check("pass"), {}),
    "drift": lambda: ("drift", check("fail"), {}),
    "upload": lambda: ("upload", {"calibration_sha256": "c" * 64, "taxel": None}, {}),
    "note": lambda: ("note", {"text": "moved to the left hand"}, {"photo.jpg": b"\xff\xd8 a photo"}),
    "reskin": lambda: ("reskin", {"note": "torn"}, {}),
}


@pytest.mark.parametrize("kind", sorted(APPENDS))
def test_a_kill_in_an_append_leaves_the_old_record_or_the_whole_event(sensor: rec.Sensor, kind: str) -> None:
    what, data, files = APPENDS[kind]()

    def append() -> None:
        sensor.append(what, data, files, date="2026-11-01T00:00:00Z")

    _every_kill(sensor.root, "A", append, append)


def test_a_kill_in_the_reskin_command(sensor: rec.Sensor, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(rec.ROOT_ENV, str(sensor.root))

    def reskin() -> None:
        result = CliRunner().invoke(main, ["sensor", "reskin", "A", "--note", "new", "--date", "2026-11-01"])
        assert result.exit_code == 0, result.output

    _every_kill(sensor.root, "A", reskin, reskin)
    assert rec.Sensor(sensor.root, "A").epoch() >= 1
