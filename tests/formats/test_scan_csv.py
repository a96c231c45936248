"""The scan CSV reader (docs/bundle.md section 1): every malformed file gives one line naming the file's
line and column. The round trip with a simulated scan is in tests/models/test_calibrate.py."""

from __future__ import annotations

import pytest

from magfab.errors import InputError
from magfab.formats.scan_csv import MIN_ROWS, ScanError, read_scan_csv


def _good(rows: int = 60) -> list[str]:
    out = ["time_s,Bx_uT,By_uT,Bz_uT,Fx_N,Fy_N,Fz_N"]
    out += [f"{0.01 * i:.2f},{i},{-i},{20000 + 10 * i},0,{0.001 * i:.3f},{0.01 * i:.2f}" for i in range(rows)]
    return out


def _edit(line: int, column: int, value: str) -> str:
    rows = _good()
    fields = rows[line - 1].split(",")
    fields[column] = value
    rows[line - 1] = ",".join(fields)
    return "\n".join(rows) + "\n"


MALFORMED = {
    "missing column": ("\n".join([_good()[0].replace(",Fz_N", "")] + [r.rsplit(",", 1)[0] for r in _good()[1:]]),
                       ["line 1", "'Fz_N'", "required columns"]),
    "not a number": (_edit(5, 2, "abc"), ["line 5", "'By_uT'", "'abc'", "finite"]),
    "empty field": (_edit(7, 6, ""), ["line 7", "'Fz_N'", "empty field"]),
    "nan": (_edit(9, 3, "nan"), ["line 9", "'Bz_uT'", "'nan' is not a finite number"]),
    "infinity": (_edit(10, 4, "-inf"), ["line 10", "'Fx_N'", "-inf"]),
    # float() reads these, a CSV must not
    "underscore": (_edit(11, 3, "20_100"), ["line 11", "'Bz_uT'", "'20_100' is not a decimal number"]),
    "arabic-indic digits": (_edit(13, 1, "\u0661\u0662"), ["line 13", "'Bx_uT'", "not a decimal number", "ASCII"]),
    "Infinity": (_edit(14, 5, "Infinity"), ["line 14", "'Fy_N'", "not a finite number"]),
    "overflow": (_edit(15, 6, "1e999"), ["line 15", "'Fz_N'", "1e999", "outside the plausible band -1000 to 1000 N"]),
    "non-breaking space": (_edit(16, 2, "\u00a05"), ["line 16", "'By_uT'", "not a decimal number"]),
    # forces or fields scaled by 1e300 are refused when read, naming the row and band
    "force 1e300": (_edit(17, 6, "3e300"), ["line 17 (row 16)", "'Fz_N'", "-1000 to 1000 N"]),
    "field 1e300": (_edit(18, 3, "2.01e304"), ["line 18 (row 17)", "'Bz_uT'", "-1e+06 to 1e+06 uT"]),
    "temperature": ("\n".join([_good()[0] + ",temperature_C"] + [r + ",25" for r in _good()[1:5]]
                               + [_good()[5] + ",2500"] + [r + ",25" for r in _good()[6:]]),
                    ["line 6 (row 5)", "'temperature_C'", "-100 to 250 degC"]),
    "decreasing time": (_edit(12, 0, "0.05"), ["line 12", "'time_s'", "non-decreasing", "line 11"]),
    "short row": ("\n".join([*_good()[:20], "0.5,1,2", *_good()[20:]]), ["line 21", "3 values", "7 columns"]),
    "duplicate column": ("\n".join([_good()[0] + ",Bz_uT"] + [r + ",1" for r in _good()[1:]]),
                         ["line 1", "'Bz_uT' appears twice"]),
    "too few rows": ("\n".join(_good(10)), ["line 11", "10 data rows", f"at least {MIN_ROWS}"]),
    "empty": ("", ["line 1", "no header"]),
    "only comments": ("# nothing here\n# still nothing\n", ["no header"]),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_csv_gives_one_line_naming_line_and_column(case):
    text, expected = MALFORMED[case]
    with pytest.raises(ScanError) as info:
        read_scan_csv(text.encode("utf-8"))
    message = str(info.value)
    assert "\n" not in message and "Traceback" not in message
    for part in expected:
        assert part in message, (part, message)
    assert isinstance(info.value, InputError)  # exit 2: the user's file is at fault


def test_unreadable_inputs(tmp_path):
    with pytest.raises(ScanError, match="cannot read"):
        read_scan_csv(tmp_path / "absent.csv")
    with pytest.raises(ScanError, match="not UTF-8"):
        read_scan_csv(b"time_s,Bx_uT\n\xff\xfe\n")


def test_plain_decimal_forms_are_read():
    text = "\n".join([*_good()[:3], "+0.03,1.,-.5,2e4,0,1E-3,0.0", *_good()[4:]]) + "\n"
    scan = read_scan_csv(text.encode("utf-8"))
    assert scan.B_uT[2].tolist() == [1.0, -0.5, 2e4] and scan.F_N[2, 1] == 1e-3


def _scan(bz, br, fz=None):
    """A calibration scan CSV with (Bz, Br) as given (Br all along +x)."""
    rows = ["time_s,Bx_uT,By_uT,Bz_uT,Fx_N,Fy_N,Fz_N"]
    for i, (z, r) in enumerate(zip(bz, br)):
        rows.append(f"{0.01 * i!r},{r!r},0,{z!r},{0.001 * i!r},0,{0.01 * i if fz is None else fz[i]!r}")
    return ("\n".join(rows) + "\n").encode("utf-8")


@pytest.mark.parametrize("case, bz, br, words", [
    ("no lateral field", [20000.0 + 10 * i for i in range(60)], [0.0] * 60, ["Br spans only 0 uT"]),
    ("no normal travel", [20000.0] * 60, [10.0 * i for i in range(60)], ["Bz spans only 0 uT"]),
    ("on a line", [20000.0 + 10 * i for i in range(60)], [3.0 * i for i in range(60)], ["lie on a line"]),
    ("sub-LSB lateral noise", [20000.0 + 10 * i for i in range(60)], [1e-7 * (i % 3) for i in range(60)],
     ["Br spans only 2e-07 uT"]),
])
def test_a_scan_spanning_no_area_is_refused_when_read(case, bz, br, words):
    """The fit once found this only after the whole build (exit 1); the reader finds it."""
    with pytest.raises(ScanError) as info:
        read_scan_csv(_scan(bz, br))
    message = str(info.value)
    assert "span no area" in message and "\n" not in message
    for w in words:
        assert w in message, message
    # a recording (no calibration) may be one-dimensional
    assert read_scan_csv(_scan(bz, br), require_force=False).rows == 60


def test_a_two_dimensional_scan_passes():
    bz = [20000.0 + 10 * (i // 8) for i in range(64)]
    br = [5.0 * (i % 8) for i in range(64)]
    assert read_scan_csv(_scan(bz, br)).rows == 64


def _recording_text(host: bool = True, sensor: bool = True) -> str:
    """A recording as magfab-readout record writes it (docs/bundle.md section 1)."""
    names = ["time_s"] + (["host_time_s"] if host else []) + ["Bx_uT", "By_uT", "Bz_uT"]
    names += ["Fx_sensor_N", "Fy_sensor_N", "Fz_sensor_N"] if sensor else []
    rows = [",".join(names)]
    for i in range(60):
        row = [f"{0.00184 * i:.6f}"] + ([f"{1.7e9 + 0.002 * i:.6f}"] if host else [])
        row += [str(i % 8), str(-i), str(20000 + 10 * i)]
        row += ["0.0", f"{0.001 * i:.3f}", f"{0.01 * i:.2f}"] if sensor else []
        rows.append(",".join(row))
    return "\n".join(rows) + "\n"


def test_guard_a_the_sensors_own_forces_never_stand_in_for_the_reference():
    """A recording calibrated against itself once reported 'held-out RMS Fz 0 mN'; its columns are named
    for what they are, and the reader says why they cannot be the reference, in one line."""
    with pytest.raises(ScanError) as info:
        read_scan_csv(_recording_text().encode())
    message = str(info.value)
    assert "\n" not in message and "line 1 (header)" in message
    for part in ("Fx_sensor_N", "own calibrated forces", "reference force sensor", "--reference"):
        assert part in message, message
    # without them the plain missing-column line
    with pytest.raises(ScanError, match="missing column 'Fx_N'; required columns"):
        read_scan_csv(_recording_text(sensor=False).encode())
    # a recording needs no force columns
    assert read_scan_csv(_recording_text().encode(), require_force=False).F_N is None


def test_recording_and_reference_readers():
    from magfab.formats.scan_csv import read_recording, read_reference

    rec = read_recording(_recording_text().encode())
    assert rec.scan.rows == 60 and rec.host_time_s[1] == 1.7e9 + 0.002 and rec.scan.F_N[2, 2] == 0.02
    assert rec.lines[0] == 2
    with pytest.raises(ScanError, match=r"missing column 'host_time_s'.*record again"):
        read_recording(_recording_text(host=False).encode())
    ref = read_reference(b"# a log\nFz_N,time_s,Fx_N,Fy_N\n0.5,1700000000.25,0,0.1\n0.6,1700000000.5,0,0.2\n")
    assert ref.time_s.tolist() == [1700000000.25, 1700000000.5] and ref.F_N[1].tolist() == [0.0, 0.2, 0.6]
    assert ref.lines.tolist() == [3, 4]
    # a recording passed as the reference is refused by the same guard
    with pytest.raises(ScanError, match="own calibrated forces"):
        read_reference(_recording_text().encode())
    with pytest.raises(ScanError, match=r"line 3.*'time_s'.*non-decreasing"):
        read_reference(b"time_s,Fx_N,Fy_N,Fz_N\n2,0,0,0\n1,0,0,0\n")


@pytest.mark.parametrize("reader", ["scan", "recording", "reference"])
def test_a_file_over_the_row_limit_is_refused_before_its_values_are_read(reader, monkeypatch):
    """Every reader counts rows before parsing a value (a 256 MiB scan once took over a minute to be refused):
    MAX_ROWS data rows are read, one more is refused in one line naming the file and the limit, and so is a text
    of more line breaks (of any kind str.splitlines splits at) than four times the limit, before it is split."""
    from magfab.formats import scan_csv
    from magfab.formats.scan_csv import read_recording, read_reference

    monkeypatch.setattr(scan_csv, "MAX_ROWS", 60)
    log = "time_s,Fx_N,Fy_N,Fz_N\n" + "".join(f"{1.7e9 + k},0,0,{0.01 * k}\n" for k in range(60))
    text = {"scan": "\n".join(_good(60)) + "\n", "recording": _recording_text(), "reference": log}[reader]
    read = {"scan": lambda t: read_scan_csv(t, require_force=False), "recording": read_recording,
            "reference": read_reference}[reader]
    assert read(text.encode()) is not None  # at the limit
    header, first, rest = text.split("\n", 2)
    over = f"{header}\n{first}\n{first}\n{rest}"  # one row more (a repeated time is non-decreasing)
    with pytest.raises(ScanError, match=r"61 data rows; a .* may hold at most 60 data rows") as info:
        read(over.encode())
    assert "\n" not in str(info.value)
    for brk in ("\n", "\r\n", "\x0c", "\u2028"):
        with pytest.raises(ScanError, match="over 240 line breaks") as info:
            read((text + "#" + brk * 241).encode())
        assert "\n" not in str(info.value)
