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
    "nan": (_edit(9, 3, "nan"), ["line 9", "'Bz_uT'", "nan is not a finite number"]),
    "infinity": (_edit(10, 4, "-inf"), ["line 10", "'Fx_N'", "-inf"]),
    "decreasing time": (_edit(12, 0, "0.05"), ["line 12", "'time_s'", "non-decreasing", "line 11"]),
    "short row": ("\n".join(_good()[:20] + ["0.5,1,2"] + _good()[20:]), ["line 21", "3 values", "7 columns"]),
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
