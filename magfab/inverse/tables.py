"""Tables of evaluated designs: CSV always, Parquet beside it (pyarrow), the same columns in both."""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .files import write_bytes
from .space import CATEGORICAL, NUMERIC
from .study import Record
from .targets import Objective

# Imported lazily, inside the functions that use it, for speed: pyarrow takes a
# noticeable time to import, and importing this module should not.

__all__ = ["COLUMNS", "rows", "write_table"]

FIGURES = (*(o.value for o in Objective), "normal_sensitivity_at_rest_G_per_N", "Bz_rest_G", "range_limit")
COLUMNS = ("design", "state", "model", *CATEGORICAL, *NUMERIC, *FIGURES, "reason")


def _cell(v: Any) -> Any:
    if isinstance(v, float):
        return float(f"{v:.6g}")
    return v


def rows(records: Sequence[Record], names: Sequence[str] | None = None,
         extra: Sequence[dict[str, Any]] | None = None) -> list[dict[str, Any]]:
    """One dict per record with :data:`COLUMNS` (plus ``extra``'s keys), numbers to 6 significant digits."""
    out = []
    for i, r in enumerate(records):
        row = {"design": names[i] if names else r.number, "state": r.state, "model": r.model}
        row.update({k: _cell(r.point.get(k)) for k in CATEGORICAL + NUMERIC})
        row.update({k: _cell(r.metrics.get(k)) for k in FIGURES})
        row["reason"] = r.reason
        if extra:
            row.update({k: _cell(v) for k, v in extra[i].items()})
        out.append(row)
    return out


def csv_bytes(table: list[dict[str, Any]]) -> bytes:
    buf = io.StringIO()
    columns = list(table[0]) if table else list(COLUMNS)
    w = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    w.writeheader()
    for row in table:
        w.writerow({k: "" if v is None else v for k, v in row.items()})
    return buf.getvalue().encode("utf-8")


def parquet_bytes(table: list[dict[str, Any]]) -> bytes:
    import pyarrow as pa
    import pyarrow.parquet as pq

    columns = list(table[0]) if table else list(COLUMNS)
    data = {c: [row.get(c) for row in table] for c in columns}
    arrays = {}
    for c, values in data.items():
        kinds = {type(v) for v in values if v is not None}
        if kinds <= {int, float} and kinds:
            arrays[c] = pa.array([None if v is None else float(v) for v in values], type=pa.float64())
        else:
            arrays[c] = pa.array([None if v is None else str(v) for v in values], type=pa.string())
    buf = pa.BufferOutputStream()
    pq.write_table(pa.table(arrays), buf, compression="zstd")
    return buf.getvalue().to_pybytes()


def write_table(folder: Path, stem: str, table: list[dict[str, Any]]) -> list[Path]:
    """``stem``.csv and ``stem``.parquet in ``folder`` (each written to a temporary name and renamed)."""
    return [write_bytes(folder / f"{stem}.csv", csv_bytes(table)),
            write_bytes(folder / f"{stem}.parquet", parquet_bytes(table))]
