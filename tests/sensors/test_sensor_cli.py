"""``magfab sensor add | list | show | reskin`` (docs/sensors.md): what they write, what they refuse (exit 2, one
line, nothing written), the measured calibration a record adopts from its build folder, the history's table and
chart, and the re-skin comparison against the design's bands."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from sensor_support import HISTORY, calibration, tree, write_history

from magfab.cli import main
from magfab.formats import sensor_records as rec
from magfab.formats.calibration_json import calibration_sha256
from magfab.formats.scan_csv import read_scan_csv


@pytest.fixture
def here(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A lab folder to stand in, with no sensor root above it or in the environment."""
    monkeypatch.delenv(rec.ROOT_ENV, raising=False)
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _run(*args: str):
    return CliRunner().invoke(main, ["sensor", *args])


def _refused(result, *words: str) -> None:
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("magfab: error: "), result.output
    for w in words:
        assert w in lines[0], (w, lines[0])


def test_add_keeps_the_build_s_spec_design_and_bands(here, default_build):
    folder = default_build.out_dir
    result = _run("add", "finger-01", "--build", str(folder), "--date", "2026-10-01T12:00")
    assert result.exit_code == 0, result.output
    s = rec.open_sensor(here / "sensors", "finger-01")
    (added,) = s.events()
    assert added["kind"] == "added" and added["date"] == "2026-10-01T12:00:00Z" and added["taxels"] is None
    for role, rel in (("spec.json", "spec.json"), ("design.json", "design.json"),
                      ("acceptance.json", "calibration/acceptance.json")):
        assert s.file(added["files"][role]) == (folder / rel).read_bytes(), role
    manifest = json.loads((folder / "manifest.json").read_text())
    assert added["spec_sha256"] == manifest["spec_sha256"] == s.info["spec_sha256"]
    assert added["design_sha256"] == rec.sha256_hex((folder / "design.json").read_bytes())
    assert list(s.calibrations()) == []  # the build's calibration is the simulated one: nothing to adopt


def _no_writes(here: Path, *args: str, words: tuple[str, ...] = ()) -> None:
    before = tree(here)
    _refused(_run(*args), *words)
    assert tree(here) == before


def test_refusals_are_one_line_and_write_nothing(here, default_build):
    folder = str(default_build.out_dir)
    _no_writes(here, "show", "A", words=("sensors", "holds no sensor records"))
    _no_writes(here, "add", "A", "--build", str(here / "missing"), words=("--build", "not a magfab build folder"))
    _no_writes(here, "add", "A", "--build", str(here), words=("not a magfab build folder",))
    _no_writes(here, "add", ".x", "--build", folder, words=("must be 1 to 32",))
    _no_writes(here, "add", "a/b", "--build", folder, words=("must be 1 to 32",))
    _no_writes(here, "add", "A", "--build", folder, "--date", "yesterday", words=("date", "ISO 8601"))
    build_copy = here / "b"
    shutil.copytree(folder, build_copy)
    _no_writes(here, "add", "A", "--build", folder, "--sensors", str(build_copy / "sensors"),
               words=("inside the build folder", "rebuild replaces"))
    assert _run("add", "A", "--build", folder).exit_code == 0
    _no_writes(here, "add", "A", "--build", folder, words=("already has a record",))
    _no_writes(here, "show", "B", words=("has no record", "sensors there: A"))
    _no_writes(here, "reskin", "B", words=("has no record",))
    _no_writes(here, "show", "../A", words=("must be 1 to 32",))
    _no_writes(here, "show", "A", "--plot", str(here / "sensors" / "A" / "h.png"), words=("--plot", "inside"))


def _recording_and_reference(scan_path: Path, folder: Path) -> None:
    """A recording of the scan's field by the reader (host clock, the sensor's own forces zero) and the reference
    sensor's log of its forces on the same clock, into ``folder`` as rec.csv and ref.csv."""
    scan = read_scan_csv(scan_path)
    host = 1.7e9 + scan.time_s
    rows = ["time_s,host_time_s,Bx_uT,By_uT,Bz_uT,Fx_sensor_N,Fy_sensor_N,Fz_sensor_N"]
    rows += [f"{t!r},{h:.6f},{b[0]!r},{b[1]!r},{b[2]!r},0,0,0"
             for t, h, b in zip(scan.time_s.tolist(), host.tolist(), scan.B_uT.tolist())]
    (folder / "rec.csv").write_text("\n".join(rows) + "\n")
    assert scan.F_N is not None
    force = np.round(scan.F_N / 0.002) * 0.002  # the reference's resolution
    ref = ["time_s,Fx_N,Fy_N,Fz_N"] + [f"{h:.6f},{f[0]!r},{f[1]!r},{f[2]!r}" for h, f in zip(host.tolist(),
                                                                                            force.tolist())]
    (folder / "ref.csv").write_text("\n".join(ref) + "\n")


def test_add_adopts_a_calibration_measured_into_the_build(here, default_build):
    folder = here / "build" / "magone"
    shutil.copytree(default_build.out_dir, folder)
    _recording_and_reference(folder / "calibration" / "scan_simulated.csv", folder)
    calibrated = CliRunner().invoke(main, ["calibrate", str(folder / "rec.csv"), "--reference",
                                           str(folder / "ref.csv"), "--out", str(folder)])
    assert calibrated.exit_code == 0, calibrated.output
    result = _run("add", "finger-02", "--build", str(folder))
    assert result.exit_code == 0 and "kept the 1 calibration(s) measured" in result.output, result.output
    s = rec.open_sensor(here / "sensors", "finger-02")
    (cal,) = s.calibrations()
    built = (folder / "calibration" / "calibration.json").read_bytes()
    assert cal["calibration_sha256"] == calibration_sha256(json.loads(built))
    assert not cal["provisional"] and cal["taxel"] is None
    assert s.file(cal["files"]["calibration.json"]) == built
    for role, name in (("scan.csv", "rec.csv"), ("reference.csv", "ref.csv"),
                       ("scan_merged.csv", "calibration/scan_merged.csv")):
        assert s.file(cal["files"][role]) == (folder / name).read_bytes(), role
    doc = json.loads(built)
    assert cal["rms_holdout_Fz_mN"] == pytest.approx(1000 * doc["errors"]["Fz_N"]["rms_holdout"], abs=1e-3)
    bands = json.loads((folder / "calibration" / "acceptance.json").read_text())
    assert bands["rest"]["Bz_uT"]["min"] <= cal["rest_field_uT"][2] <= bands["rest"]["Bz_uT"]["max"]
    weight = bands["weight"]
    lo, hi = (weight["delta_Bz_uT"][k] / weight["force_N"] for k in ("min", "max"))
    assert lo <= cal["sensitivity_normal_uT_per_N"] <= hi  # the simulated sensor is the nominal design
    assert cal["sensitivity_shear_uT_per_N"] > 0 and cal["range_normal_N"] > 0.5
    assert s.current_calibration()[1] == doc


@pytest.fixture
def history(here, default_build) -> rec.Sensor:
    """A sensor with three calibrations and five checks over seven weeks, a new skin in week four."""
    assert _run("add", "finger-01", "--build", str(default_build.out_dir), "--date", "2026-10-01T12:00").exit_code == 0
    s = rec.open_sensor(here / "sensors", "finger-01")
    write_history(s)
    return s


def test_show_lists_every_event_with_its_skin(history):
    result = _run("show", "finger-01")
    assert result.exit_code == 0, result.output
    lines = result.output.splitlines()
    assert lines[0] == "sensor finger-01: design magone, skin 1, 3 calibration(s), 5 check(s)"
    rows = lines[2:2 + 1 + len(HISTORY)]
    assert [r.split()[3] for r in rows] == ["added"] + [h[1] for h in HISTORY]
    assert [int(r.split()[4]) for r in rows] == [0] * 7 + [1] * 4  # the reskin event opens skin 1
    assert "FAIL: Bz rest 18380 uT, rise 2875 uT under 50 g, error 14.5 mN turned over or warmed" in rows[6]
    assert "Bz rest 19420 uT" in rows[8]
    listed = _run("list")
    assert listed.output.splitlines()[1].split() == ["finger-01", "magone", "1", "3", "5", "2026-10-28", "09:00",
                                                    "(2.9", "mN)", "pass"]


def test_a_new_skin_is_compared_with_the_old_against_the_design_s_bands(history):
    """The example's new skin is within the bands; one whose magnet sits lower (rest field past the band's top)
    and whose silicone is far stiffer is flagged, quantity by quantity."""
    shown = json.loads(_run("show", "finger-01", "--json").output)
    assert {c["quantity"]: c["flagged"] for c in shown["reskin"]} == {
        "rest Bz": False, "rest Bxy": False, "normal sensitivity": False, "shear sensitivity": False,
        "normal range": False, "shear range": False}
    bands = json.loads(history.file(history.events()[0]["files"]["acceptance.json"]))
    top = bands["rest"]["Bz_uT"]["max"]
    data, files = calibration(bz=top + 500.0, normal=600.0, n=4)
    history.append("calibration", data, files, date="2026-11-20T09:00:00Z")
    text = _run("show", "finger-01").output
    # the newest calibration of the new skin against the last of the old one
    assert f"rest Bz 18560 -> {top + 500:.5g} uT" in text and "the new value is outside" in text
    assert "normal sensitivity 5620 -> 600 uT/N" in text and text.count("CHANGED beyond the design's bands") == 2


def test_show_draws_the_history_the_same_bytes_every_time(history, here):
    result = _run("show", "finger-01", "--plot", "history.png")
    assert result.exit_code == 0 and "history chart: history.png" in result.output, result.output
    first = (here / "history.png").read_bytes()
    assert first.startswith(b"\x89PNG\r\n\x1a\n") and len(first) > 20_000
    assert _run("show", "finger-01", "--plot", "again.png").exit_code == 0
    assert (here / "again.png").read_bytes() == first
    assert not any(p.name.endswith(".png") for p in history.path.rglob("*"))


def test_reskin_starts_a_new_epoch(history, here):
    result = _run("reskin", "finger-01", "--note", "third skin", "--date", "2026-12-01")
    assert result.exit_code == 0 and "skin 2" in result.output, result.output
    assert history.epoch() == 2 and history.events()[-1]["note"] == "third skin"
    with pytest.raises(rec.RecordError, match="since its new skin"):
        history.current_calibration()
