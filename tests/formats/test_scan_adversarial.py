"""Adversarial scans: hypothesis mutates a good calibration scan CSV -- hostile number
spellings, huge and tiny magnitudes, stray bytes, short rows, collapsed axes -- and the reader either returns a
scan every value of which is a finite number inside its column's band and whose (Bz, Br) span an area, or
refuses it with one ScanError line of bounded length. Never another exception, never a warning.

Sized for CI (a few hundred examples); ``-m slow`` runs the exhaustive variant."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from magfab.errors import ScanError
from magfab.formats.scan_csv import BANDS, FORCE_COLUMNS, SCAN_COLUMNS, read_scan_csv

HEADER = list(SCAN_COLUMNS + FORCE_COLUMNS)
ROWS = 64
#: The longest error line the reader may give (the file name, line, column, a value cut to 24 characters).
MAX_MESSAGE = 400


def good_rows() -> list[list[str]]:
    """A 2-D scan: 8 indentation steps x 8 lateral steps."""
    rows = []
    for i in range(ROWS):
        z, y = i // 8, i % 8
        rows.append([repr(0.01 * i), repr(4.0 * y), repr(-1.5 * y), repr(20000.0 + 25.0 * z), "0.0",
                     repr(0.01 * y), repr(0.05 * z)])
    return rows


HOSTILE = st.one_of(
    st.sampled_from(["1_000", "\u0661\u0662", "\u0967", "\uff11", "inf", "-inf", "Infinity", "nan", "NaN",
                     "1e999", "-1e999", "1e300", "-3e300", "4.9e-324", "0x10", "1,5", "", " ", "\u00a01", "1.2.3",
                     "--1", "1e", ".", "+", "١", "\x00", "1e+308", "1E400", "0" * 400, "9" * 400,
                     "12\u200b", "True", "١٠٠"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(max_size=12),
    st.integers(min_value=-10**30, max_value=10**30).map(str),
)


@st.composite
def mutated_scans(draw) -> tuple[bytes, str]:
    rows = good_rows()
    kind = draw(st.sampled_from(["field", "field", "scale", "collapse", "row", "header", "bytes"]))
    if kind == "field":
        for _ in range(draw(st.integers(1, 3))):
            rows[draw(st.integers(0, ROWS - 1))][draw(st.integers(0, 6))] = draw(HOSTILE)
    elif kind == "scale":  # a whole column off by a factor: a unit mistake
        col = draw(st.integers(1, 6))
        factor = draw(st.sampled_from([1e-300, 1e-6, 1e3, 1e6, 1e12, 1e300, -1e300]))
        for r in rows:
            r[col] = repr(float(r[col]) * factor)
    elif kind == "collapse":  # one field axis constant, or Br a linear function of Bz
        how = draw(st.sampled_from(["Bz", "Br", "line"]))
        for i, r in enumerate(rows):
            if how == "Bz":
                r[3] = "20000.0"
            elif how == "Br":
                r[1] = r[2] = "0.0"
            else:
                r[1], r[2] = repr(2.0 * i), "0.0"
                r[3] = repr(20000.0 + 10.0 * i)
    elif kind == "row":
        k = draw(st.integers(0, ROWS - 1))
        rows[k] = rows[k][:draw(st.integers(0, 6))] + draw(st.lists(HOSTILE, max_size=2))
    lines = [",".join(HEADER)] + [",".join(r) for r in rows]
    if kind == "header":
        names = draw(st.permutations(HEADER))
        if draw(st.booleans()):
            names[draw(st.integers(0, 6))] = draw(st.text(max_size=2000))
        order = [HEADER.index(n) if n in HEADER else 0 for n in names]
        lines = [",".join(names)] + [",".join(r[j] for j in order) for r in rows]
    data = ("\n".join(lines) + "\n").encode("utf-8", "surrogatepass")
    if kind == "bytes":
        pos = draw(st.integers(0, len(data) - 1))
        data = data[:pos] + draw(st.binary(min_size=1, max_size=4)) + data[pos + 1:]
    return data, kind


def check(data: bytes) -> str:
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning is a failure, not a line on stderr
        try:
            scan = read_scan_csv(data)
        except ScanError as exc:
            message = str(exc)
            assert "\n" not in message and len(message) <= MAX_MESSAGE, message[:500]
            return "rejected"
    columns = dict(zip(HEADER, [scan.time_s, *scan.B_uT.T, *scan.F_N.T]))
    for name, x in columns.items():
        lo, hi, _ = BANDS[name]
        assert np.all(np.isfinite(x)) and np.all((x >= lo) & (x <= hi)), name
    assert np.ptp(scan.B_uT[:, 2]) >= 1.0 and np.ptp(scan.Br_uT) >= 1.0
    assert all(math.isfinite(float(v)) for v in scan.B_uT.ravel())
    return "accepted"


SETTINGS = {"deadline": None, "derandomize": True, "suppress_health_check": [HealthCheck.too_slow]}


@settings(max_examples=300, **SETTINGS)
@given(mutated_scans())
def test_mutated_scans_are_read_or_refused_in_one_line(case):
    data, kind = case
    event(f"{kind}: {check(data)}")


@pytest.mark.slow
@settings(max_examples=20000, **SETTINGS)
@given(mutated_scans())
def test_mutated_scans_exhaustive(case):
    data, kind = case
    event(f"{kind}: {check(data)}")


@pytest.mark.parametrize("text", ["1_000", "\u0661\u0660\u0660\u0660", "Infinity", "1e999", "inf", "0x3e8"])
def test_each_hostile_spelling_is_refused(text):
    rows = good_rows()
    rows[10][3] = text
    data = ("\n".join([",".join(HEADER)] + [",".join(r) for r in rows]) + "\n").encode()
    assert check(data) == "rejected"
