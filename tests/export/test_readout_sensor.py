"""``magfab-readout`` with sensor records: ``upload --sensor ID`` writes the sensor's current calibration
and its identity, ``info`` names the sensor, ``check --sensor ID`` appends its verdict, and the guards refuse with
exit status 2, one line, and nothing written to the board or the record. Run as ``python -m magfab_readout`` on the
default build's package against the simulated board, whose EEPROM a file keeps between commands
(``--simulate-eeprom``); the real image's side: tests/export/test_simbus.py::test_the_sensor_identity_*."""

from __future__ import annotations

import json

import pytest
from readout_support import assert_refused
from readout_support import board_bytes as _board
from readout_support import readout_command as readout
from readout_support import snapshot as _snapshot

from magfab.formats import sensor_records as rec
from magfab.formats.calibration_json import calibration_sha256

FAST = ("--samples", "150", "--settle", "0.1", "--yes")
DATE = "2026-11-28T20:15:00Z"


def _build_data(build) -> dict:
    return json.loads((build.out_dir / "readout" / "src" / "magfab_readout" / "build.json").read_text())


def _calibration(build) -> dict:
    return json.loads((build.out_dir / "readout" / "src" / "magfab_readout" / "calibration.json").read_text())


@pytest.fixture
def bench(default_build, tmp_path):
    """A sensor root with finger-01 (calibrated, this design) and its own calibration: the package's with another
    tare, so its hash differs from the package's."""
    spec = _build_data(default_build)["spec_sha256"]
    cal = _calibration(default_build)
    cal["tare_N"]["Fz_N"] += 0.01
    root = tmp_path / "lab" / "sensors"  # not above the working folder
    sensor = rec.create(root, "finger-01", {"spec_sha256": spec}, {})
    sensor.append("calibration", {"taxel": None, "spec_sha256": spec},
                  {"calibration.json": json.dumps(cal).encode()}, date=DATE)
    bench = tmp_path / "bench"  # the working folder: no sensors/ in it or above
    bench.mkdir()
    return {"build": default_build, "root": root, "sensor": sensor, "cal": cal, "spec": spec,
            "eeprom": tmp_path / "board.eeprom", "cwd": bench}


def test_upload_info_check_round_trip(bench):
    """An erased board names no sensor; ``upload --sensor`` writes the record's calibration (not the package's) and
    the ID; ``info`` then names the sensor and its calibration's date and accepts the board's calibration as the
    sensor's current one; ``check --sensor`` appends its verdict, figures and steps to the record."""
    root, sensor = bench["root"], bench["sensor"]
    sha = calibration_sha256(bench["cal"])
    proc = readout(bench, "info", "--sensors", root)
    assert proc.returncode == 0, proc.stderr
    assert "sensor:  no sensor ID on this board (upload --sensor ID)" in proc.stdout

    proc = readout(bench, "upload", "--sensor", "finger-01", "--sensors", root)
    assert proc.returncode == 0, proc.stderr
    assert f"the board runs calibration {sha[:16]}" in proc.stdout and "carries sensor finger-01's ID" in proc.stdout
    upload = sensor.events()[-1]
    assert upload["kind"] == "upload" and upload["calibration_sha256"] == sha and upload["taxel"] is None

    proc = readout(bench, "info", "--sensors", root)
    assert proc.returncode == 0, proc.stderr
    assert f"sensor:  finger-01, calibration of {DATE} ({sha[:16]})" in proc.stdout
    assert "calibration: match (sensor finger-01's current calibration" in proc.stdout

    proc = readout(bench, "check", "--sensor", "finger-01", "--sensors", root, *FAST)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert f"calibration {sha[:16]}" in proc.stdout.splitlines()[0]
    check = sensor.events()[-1]
    assert check["kind"] == "check" and check["verdict"] == "pass" and check["calibration_sha256"] == sha
    assert check["taxel"] is None and check["simulated"] is True
    assert [s["name"] for s in check["steps"]] == ["polarity (sign of Bz)", "Bz at rest", "|Bxy| at rest",
                                                   "rise of Bz under 50 g"]
    assert all(s["verdict"] == "pass" for s in check["steps"])
    stated = float(check["steps"][1]["text"].split("measured ")[1].split(" uT")[0])
    assert check["figures"]["Bz_rest_uT"] == pytest.approx(stated, abs=0.5)
    assert check["figures"]["weight_g"] == 50.0 and check["figures"]["Bz_rise_uT"] > 0
    assert f"record: check {check['number']} of sensor finger-01" in proc.stdout


def test_without_the_record_the_board_of_a_sensor_is_a_mismatch(bench):
    """The board runs the sensor's calibration; without its record (no --sensors, none found from the working
    folder) the host has only the package's calibration, and ``info`` keeps refusing the mismatch."""
    assert readout(bench, "upload", "--sensor", "finger-01", "--sensors", bench["root"]).returncode == 0
    proc = readout(bench, "info")
    assert proc.returncode == 2 and "calibration mismatch" in proc.stderr
    assert "sensor:  finger-01" in proc.stdout
    (bench["cwd"] / "sensors").symlink_to(bench["root"])  # found from the working folder
    assert "calibration: match (sensor finger-01's" in readout(bench, "info").stdout
    proc = readout(bench, "record", bench["cwd"] / "scan.csv", "--seconds", "0.1", "--sensors", bench["root"])
    assert proc.returncode == 0, proc.stderr
    header = (bench["cwd"] / "scan.csv").read_text()
    assert "# sensor: finger-01" in header and calibration_sha256(bench["cal"]) in header


def test_a_new_skin_s_board_reads_with_the_old_calibration_named_as_superseded(bench):
    """After a re-skin the board still runs the old skin's calibration, which is no longer the sensor's current one:
    ``info`` and ``record`` read it with that calibration and name it superseded (its skin and date); ``check``, an
    acceptance test that would judge the old skin's fit on the new skin, refuses in one line and keeps nothing."""
    root, sensor = bench["root"], bench["sensor"]
    assert readout(bench, "upload", "--sensor", "finger-01", "--sensors", root).returncode == 0
    sensor.append("reskin", {"note": "torn tip"}, {}, date="2026-11-29T09:00:00Z")
    note = f"sensor finger-01's calibration of {DATE} (skin 0), not one of the skin in use (skin 1)"
    proc = readout(bench, "info", "--sensors", root)
    assert proc.returncode == 0, proc.stderr
    assert "calibration: match, superseded (the board runs " + note in proc.stdout
    proc = readout(bench, "record", bench["cwd"] / "scan.csv", "--seconds", "0.1", "--sensors", root)
    assert proc.returncode == 0 and note in proc.stderr, proc.stderr
    assert calibration_sha256(bench["cal"]) in (bench["cwd"] / "scan.csv").read_text()
    assert_refused(bench, note, "check", "--sensors", root, *FAST)


def test_a_calibration_file_forced_onto_a_named_board_is_named_when_recording(bench):
    """``upload FILE --force`` onto finger-01's board keeps its ID but runs the file's calibration (here the
    package's), which no record keeps: ``record`` reads with it and says the board runs another calibration than the
    one it names, and how to write the sensor's own; ``info`` says the same on its sensor line."""
    root = bench["root"]
    assert readout(bench, "upload", "--sensor", "finger-01", "--sensors", root).returncode == 0
    package = _build_data(bench["build"])["calibration_sha256"][:16]
    cal = bench["build"].out_dir / "readout" / "src" / "magfab_readout" / "calibration.json"
    assert readout(bench, "upload", cal, "--force", "--sensors", root).returncode == 0
    proc = readout(bench, "record", bench["cwd"] / "scan.csv", "--seconds", "0.1", "--sensors", root)
    named = calibration_sha256(bench["cal"])[:16]
    said = f"the board names sensor finger-01 and its calibration of {DATE} ({named}) but runs calibration "
    assert proc.returncode == 0 and said in proc.stderr, proc.stderr
    assert proc.stderr.split(said)[1][:16].lower() == package
    assert "upload --sensor finger-01" in proc.stderr and "superseded" not in proc.stderr
    assert f"the board runs calibration {package} since" in readout(bench, "info", "--sensors", root).stdout.lower()


def _other_design(bench):
    sensor = rec.open_sensor(bench["root"], "finger-01")
    sensor.append("calibration", {"taxel": None, "spec_sha256": "ab" * 32},
                  {"calibration.json": json.dumps(_calibration(bench["build"])).encode()})


def _another_sensor_on_the_board(bench):
    other = rec.create(bench["root"], "finger-02", {"spec_sha256": bench["spec"]}, {})
    other.append("calibration", {"taxel": None, "spec_sha256": bench["spec"]},
                 {"calibration.json": json.dumps(_calibration(bench["build"])).encode()})
    assert readout(bench, "upload", "--sensor", "finger-02", "--sensors", bench["root"]).returncode == 0


def _not_calibrated(bench):
    rec.create(bench["root"], "finger-03", {"spec_sha256": bench["spec"]}, {})


GUARDS = {
    "another design": (_other_design, "finger-01", "was fitted to another design"),
    "the board names another sensor": (_another_sensor_on_the_board, "finger-01",
                                       "reports sensor finger-02, not finger-01"),
    "an unknown sensor": (None, "finger-09", "has no record in"),
    "no calibration yet": (_not_calibrated, "finger-03", "has no calibration yet"),
}


@pytest.mark.parametrize("case", list(GUARDS))
def test_upload_guards_exit_2_with_one_line_and_write_nothing(bench, case):
    prepare, sid, message = GUARDS[case]
    if prepare is not None:
        prepare(bench)
    assert_refused(bench, message, "upload", "--sensor", sid, "--sensors", bench["root"])


def test_force_writes_over_another_sensors_board_and_says_so(bench):
    _another_sensor_on_the_board(bench)
    proc = readout(bench, "upload", "--sensor", "finger-01", "--sensors", bench["root"], "--force")
    assert proc.returncode == 0, proc.stderr
    event = bench["sensor"].events()[-1]
    assert event["kind"] == "upload" and event["replaced_sensor"] == "finger-02"
    assert "sensor:  finger-01" in readout(bench, "info", "--sensors", bench["root"]).stdout


def test_check_of_another_sensors_board_or_calibration_writes_nothing(bench):
    """``check --sensor ID`` on a board naming another sensor: exit 2; on an erased board running the package's
    calibration while the sensor has its own: the mismatch (exit 1) naming the upload; the record unchanged."""
    record = _snapshot(bench["root"])
    proc = readout(bench, "check", "--sensor", "finger-01", "--sensors", bench["root"], *FAST)
    assert proc.returncode == 2 and "upload --sensor finger-01" in proc.stderr, proc.stderr
    assert _snapshot(bench["root"]) == record
    _another_sensor_on_the_board(bench)
    record, board = _snapshot(bench["root"]), _board(bench)
    proc = readout(bench, "check", "--sensor", "finger-01", "--sensors", bench["root"], *FAST)
    assert proc.returncode == 2 and "reports sensor finger-02, not finger-01" in proc.stderr
    assert len(proc.stderr.splitlines()) == 1
    assert _snapshot(bench["root"]) == record and _board(bench) == board


def test_upload_takes_a_file_or_a_sensor(bench, tmp_path):
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(bench["cal"]))
    proc = readout(bench, "upload", path, "--sensor", "finger-01", "--sensors", bench["root"])
    assert proc.returncode == 2 and "not both" in proc.stderr
    assert _board(bench) == b""


def test_a_plain_upload_onto_a_sensors_board_is_refused_without_force(bench, tmp_path):
    """The board names finger-01: the package's provisional calibration (or any file) would replace the sensor's;
    refused (exit 2, one line, nothing written) until --force, which writes it and leaves the identity, so info
    says the board runs another calibration than the sensor's."""
    assert readout(bench, "upload", "--sensor", "finger-01", "--sensors", bench["root"]).returncode == 0
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(_calibration(bench["build"])))
    for args in ((), (path,)):
        board, record = _board(bench), _snapshot(bench["root"])
        proc = readout(bench, "upload", *args)
        assert proc.returncode == 2, proc.stdout + proc.stderr
        assert proc.stderr == ("magfab-readout: error: this board is sensor finger-01: upload --sensor finger-01, or "
                               "--force\n")
        assert _board(bench) == board and _snapshot(bench["root"]) == record
    proc = readout(bench, "upload", "--force")
    assert proc.returncode == 0, proc.stderr
    package = calibration_sha256(_calibration(bench["build"]))[:16]
    assert f"the board runs calibration {package}" in proc.stdout
    assert "the board runs calibration" in readout(bench, "info").stdout.split("sensor:  finger-01")[1]
