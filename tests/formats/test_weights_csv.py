"""The weighings CSV (magfab.formats.weights_csv): what is written reads back the same; every kind of malformed file,
generated at random over its rows and columns, is refused in one ScanError line naming the file and the line."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab.errors import ScanError
from magfab.formats.weights_csv import (
    BANDS,
    MAX_WEIGHINGS,
    MIN_WEIGHINGS,
    WEIGHT_COLUMNS,
    Weighing,
    read_weights_csv,
    weights_csv,
)

FIELD = st.floats(-5e4, 5e4, allow_nan=False)
SD = st.floats(0.0, 100.0, allow_nan=False)
WEIGHING = st.builds(lambda m, a, b, s, n: Weighing(m, a, b, s, n), st.floats(0.0, 5000.0), st.floats(0.0, 80.0),
                     st.tuples(FIELD, FIELD, FIELD), st.tuples(SD, SD, SD), st.integers(1, 100_000))


@settings(max_examples=60, deadline=None)
@given(st.lists(WEIGHING, min_size=MIN_WEIGHINGS, max_size=20))
def test_written_weighings_read_back(weighings):
    back = read_weights_csv(weights_csv(weighings, ["a comment"]).encode())
    assert len(back) == len(weighings)
    for a, b in zip(weighings, back):
        assert b.samples == a.samples
        np.testing.assert_allclose([b.mass_g, b.angle_deg, *b.field_uT, *b.sd_uT],
                                   [a.mass_g, a.angle_deg, *a.field_uT, *a.sd_uT], rtol=1e-7, atol=1e-9)


def _good(rows: int = 12) -> list[list[str]]:
    return [[str(5 + 50 * k), str(20 * (k // 4)), "10", "-5", str(18000 + 100 * k), "11", "11", "12", "250"]
            for k in range(rows)]


def _text(header: list[str], rows: list[list[str]]) -> bytes:
    return ("\n".join([",".join(header), *(",".join(r) for r in rows)]) + "\n").encode()


#: Each kind of mistake, made at a drawn row and column (or count), and what the one line must name.
MISTAKES = ("drop column", "short row", "not a number", "outside band", "fraction of a sample", "too few", "too many",
            "duplicate column")


@settings(max_examples=120, deadline=None)
@given(kind=st.sampled_from(MISTAKES), row=st.integers(0, 11), column=st.integers(0, len(WEIGHT_COLUMNS) - 1),
       junk=st.sampled_from(["nan", "inf", "", "1,5", "0x10", "1e999", "abc", "\u0661"]), scale=st.floats(1.5, 1e6))
def test_every_kind_of_malformed_file_is_refused_in_one_line(kind, row, column, junk, scale):
    header, rows = list(WEIGHT_COLUMNS), _good()
    name = WEIGHT_COLUMNS[column]
    if kind == "drop column":
        header.pop(column)
        rows = [r[:column] + r[column + 1:] for r in rows]
    elif kind == "short row":
        rows[row] = rows[row][:-1]
    elif kind == "not a number":
        rows[row][column] = junk
    elif kind == "outside band":
        lo, hi, _ = BANDS[name]
        rows[row][column] = repr(hi * scale + 1.0 if hi > 0 else lo - scale)
    elif kind == "fraction of a sample":
        rows[row][-1] = "250.5"
    elif kind == "too few":
        rows = rows[:MIN_WEIGHINGS - 1]
    elif kind == "too many":
        rows = (rows * (MAX_WEIGHINGS // len(rows) + 1))[:MAX_WEIGHINGS + 1]
    else:
        header[column] = header[(column + 1) % len(header)]
    with pytest.raises(ScanError) as err:
        read_weights_csv(_text(header, rows))
    text = str(err.value)
    assert "\n" not in text and len(text) < 400 and text.startswith("weighings")
    if kind in ("short row", "not a number", "outside band", "fraction of a sample"):
        assert f"line {row + 2}" in text
    if kind in ("drop column",):
        assert name in text


def test_a_missing_file_is_one_line(tmp_path):
    with pytest.raises(ScanError, match="cannot read"):
        read_weights_csv(tmp_path / "nope.csv")
