"""The sensor records' core (magfab.formats.sensor_records, shared with the readout package): append-only events,
content-addressed files, epochs, and what it refuses."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab.formats import sensor_records as rec


def _snapshot(root: Path) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}


def test_events_append_in_order_and_nothing_is_replaced(tmp_path: Path) -> None:
    root = tmp_path / "sensors"
    s = rec.create(root, "finger-01", {"spec_name": "magone"}, {"spec.json": b"{}"}, date="2026-11-01T00:00:00Z")
    before = _snapshot(root)
    s.append("calibration", {"taxel": None}, {"calibration.json": b'{"a": 1}', "scan.csv": b"x\n"})
    after = _snapshot(root)
    assert all(after[k] == v for k, v in before.items()), "an append changed a file already there"
    assert [e["kind"] for e in s.events()] == ["added", "calibration"]
    assert s.info["added"] == "2026-11-01T00:00:00Z"


def test_the_newest_calibration_of_the_skin_in_use(tmp_path: Path) -> None:
    s = rec.create(tmp_path / "sensors", "f1", {}, {})
    s.append("calibration", {"taxel": None}, {"calibration.json": b'{"n": 1}'})
    s.append("calibration", {"taxel": None}, {"calibration.json": b'{"n": 2}'})
    assert s.current_calibration()[1] == {"n": 2}
    s.append("reskin", {"note": "torn"})
    with pytest.raises(rec.RecordError, match="since its new skin"):
        s.current_calibration()
    s.append("calibration", {"taxel": None}, {"calibration.json": b'{"n": 3}'})
    event, cal = s.current_calibration()
    assert event["epoch"] == 1
    assert cal == {"n": 3}
    assert [c["epoch"] for c in s.calibrations()] == [0, 0, 1]


def test_a_file_belongs_to_the_sensor_it_calibrated(tmp_path: Path) -> None:
    root = tmp_path / "sensors"
    a = rec.create(root, "A", {}, {})
    rec.create(root, "B", {}, {})
    a.append("calibration", {"taxel": None}, {"scan.csv": b"scan of A\n"})
    assert rec.owner_of(root, rec.sha256_hex(b"scan of A\n")) == ["A"]
    assert rec.owner_of(root, rec.sha256_hex(b"other\n")) == []


@pytest.mark.parametrize("bad", ["", "-x", "a/b", "..", "a" * 33, "tab\there", "é"])
def test_ids_that_cannot_name_a_folder_or_a_label_are_refused(tmp_path: Path, bad: str) -> None:
    with pytest.raises(rec.RecordError, match="must be 1 to 32"):
        rec.create(tmp_path / "sensors", bad, {}, {})
    assert not (tmp_path / "sensors" / bad).exists() or bad in ("", "..")


def test_an_id_is_added_once(tmp_path: Path) -> None:
    rec.create(tmp_path / "sensors", "A", {}, {})
    with pytest.raises(rec.RecordError, match="already has a record"):
        rec.create(tmp_path / "sensors", "A", {}, {})


def test_no_root_inside_a_build_folder(tmp_path: Path) -> None:
    build = tmp_path / "build"
    build.mkdir()
    (build / "manifest.json").write_text("{}")
    (build / "design.json").write_text("{}")
    with pytest.raises(rec.RecordError, match="rebuild replaces"):
        rec.init_root(build / "sensors")
    assert not (build / "sensors").exists()


def test_the_root_is_found_from_a_folder_below_it(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(rec.ROOT_ENV, raising=False)
    rec.init_root(tmp_path / "sensors")
    deep = tmp_path / "build" / "magone"
    deep.mkdir(parents=True)
    assert rec.find_root(start=deep) == (tmp_path / "sensors").resolve()
    with pytest.raises(rec.RecordError, match="holds no sensor records"):
        rec.find_root(start=Path(tmp_path.anchor))  # no root above the filesystem's top
    monkeypatch.setenv(rec.ROOT_ENV, str(tmp_path / "elsewhere"))
    with pytest.raises(rec.RecordError, match="elsewhere"):
        rec.find_root(start=deep)


def test_a_kept_file_edited_by_hand_is_named(tmp_path: Path) -> None:
    s = rec.create(tmp_path / "sensors", "A", {}, {})
    ev = s.append("calibration", {"taxel": None}, {"calibration.json": b"{}"})
    sha = ev["files"]["calibration.json"]
    (s.path / "files" / f"{sha}.json").write_bytes(b"[]")
    with pytest.raises(rec.RecordError, match="edited by hand"):
        s.file(sha)


def test_leftover_temporary_files_are_ignored(tmp_path: Path) -> None:
    s = rec.create(tmp_path / "sensors", "A", {}, {})
    (s.path / "events" / ".tmp-1-abc").write_bytes(b'{"half')
    assert [e["kind"] for e in s.events()] == ["added"]
    s.append("check", {"verdict": "pass"})
    assert [e["number"] for e in s.events()] == [1, 2]


@settings(max_examples=25, deadline=None)
@given(dates=st.lists(st.datetimes(timezones=st.just(__import__("datetime").timezone.utc)), min_size=1, max_size=4))
def test_dates_round_trip_through_parse(dates: list) -> None:
    for when in dates:
        text = when.replace(microsecond=0, tzinfo=None).isoformat() + "Z"
        assert rec.parse_date(text) == text
        assert rec.parse_date(when.isoformat()) == text


def test_event_files_are_plain_json(tmp_path: Path) -> None:
    s = rec.create(tmp_path / "sensors", "A", {"spec_name": "magone"}, {"spec.json": b"{}"})
    for path in (s.path / "events").iterdir():
        data = json.loads(path.read_text())
        assert data["sensor"] == "A"
        assert "date" in data
