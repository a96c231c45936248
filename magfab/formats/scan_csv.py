"""The calibration scan CSV (docs/bundle.md section 1): the :class:`Scan` value, reading and writing it.

One row per sample: ``time_s`` and the field ``Bx_uT, By_uT, Bz_uT`` (chip axes), optionally
``temperature_C``, and for a calibration the reference force ``Fx_N, Fy_N, Fz_N`` (sensor frame); columns in
any order, others ignored, ``#`` lines are comments. :func:`read_scan_csv` is the one reader of a scan: every
malformed file gives one :class:`~magfab.errors.ScanError` line naming the file, the line number and the column.

Two related files share its parsing: a recording of ``magfab-readout record`` (:func:`read_recording`: the
host's clock ``host_time_s`` beside ``time_s``, and the sensor's own forces ``Fx_sensor_N, Fy_sensor_N,
Fz_sensor_N``, which a calibration refuses) and a reference force sensor's log (:func:`read_reference`:
``time_s`` on the same host clock, ``Fx_N, Fy_N, Fz_N``); :func:`magfab.models.scan_guards.merge_reference`
makes a scan of the two.
"""

from __future__ import annotations

import hashlib
import io
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ScanError, shown
from . import bounded

__all__ = ["SCAN_COLUMNS", "FORCE_COLUMNS", "SENSOR_FORCE_COLUMNS", "HOST_TIME_COLUMN", "TAXEL_COLUMN",
           "REFERENCE_COLUMNS", "TEMPERATURE_COLUMN", "MIN_ROWS", "BANDS", "HOST_TIME_BAND", "MIN_SPAN_UT",
           "MIN_THICKNESS", "ScanError",
           "Scan", "Recording", "Reference", "scan_csv", "read_scan_csv", "read_recording", "read_reference",
           "check_calibration_scan"]

#: Required scan columns; the force columns are required for a calibration (not for a recording).
SCAN_COLUMNS = ("time_s", "Bx_uT", "By_uT", "Bz_uT")
FORCE_COLUMNS = ("Fx_N", "Fy_N", "Fz_N")
#: The sensor's own calibrated force, as ``magfab-readout record`` writes it: never a calibration's reference.
SENSOR_FORCE_COLUMNS = ("Fx_sensor_N", "Fy_sensor_N", "Fz_sensor_N")
#: A recording's host clock (``time.time()`` when the sample was read: Unix time, s), beside the device's time_s.
#: An array's recording: which taxel each row is (docs/bundle.md section 1).
TAXEL_COLUMN = "taxel"
HOST_TIME_COLUMN = "host_time_s"
#: A reference force sensor's log: ``time_s`` on the host clock of the recording's ``host_time_s``, and its force.
REFERENCE_COLUMNS = ("time_s", *FORCE_COLUMNS)
TEMPERATURE_COLUMN = "temperature_C"
#: Smallest scan a calibration accepts: the order-6 fit has 28 coefficients and is cross-validated.
MIN_ROWS = 50
#: The largest polynomial order every fit tries (``magfab.models.calibration.ORDERS[-1]``; a test keeps them
#: equal), named in the too-few-rows message.
LARGEST_ORDER = 6
#: A value: ASCII decimal digits, an optional sign, point and exponent (what every CSV writer emits). Python's
#: float() also takes '1_000', 'inf', 'nan', ' 1e3 ' with other Unicode spaces and other scripts' digits.
NUMBER = re.compile(r"[+-]?(?:[0-9]+(?:\.[0-9]*)?|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
#: Plausible band of each column, (low, high, unit): beyond it a value is a unit or scaling mistake, not a
#: reading. Field: 1 T is past any magnetometer chip's full scale (the MLX90393's is below 0.1 T); force:
#: 1 kN (100 kgf) is far past what a tactile tip's elastomer survives; time: about 30 years; temperature:
#: beyond any chip's rating (the MLX90393's is -40 to 125 degC).
BANDS = {
    "time_s": (-1e9, 1e9, "s"),
    "Bx_uT": (-1e6, 1e6, "uT"), "By_uT": (-1e6, 1e6, "uT"), "Bz_uT": (-1e6, 1e6, "uT"),
    "temperature_C": (-100.0, 250.0, "degC"),
    "Fx_N": (-1e3, 1e3, "N"), "Fy_N": (-1e3, 1e3, "N"), "Fz_N": (-1e3, 1e3, "N"),
    "Fx_sensor_N": (-1e3, 1e3, "N"), "Fy_sensor_N": (-1e3, 1e3, "N"), "Fz_sensor_N": (-1e3, 1e3, "N"),
}
#: Most data rows a scan, recording or reference log may hold, checked before a value is parsed (parsing is about
#: 15 us a row, so the largest file is read in seconds): a recording at the chip's fastest 543 Hz for 15 minutes, a
#: 1 kHz reference log for 8; a calibration then fits at most magfab.limits.MAX_SCAN_ROWS of them. Lines of any
#: kind (blank and comment lines too) at most twice as many, counted before the text is split.
MAX_ROWS = 500_000
#: What str.splitlines splits at, in UTF-8 (each counted before the text is split into that many lines).
_BREAKS = (b"\n", b"\r", b"\x0b", b"\x0c", b"\x1c", b"\x1d", b"\x1e", "\x85".encode(), "\u2028".encode(),
           "\u2029".encode())
#: The host clock's band (Unix time in s, 1970 to about the year 5000): a recording's ``host_time_s`` and a
#: reference log's ``time_s``.
HOST_TIME_BAND = (0.0, 1e11, "s")
BANDS[HOST_TIME_COLUMN] = HOST_TIME_BAND
#: Least range of Bz and of Br a calibration scan must span, uT: a few LSB of the chip's finest setting.
MIN_SPAN_UT = 1.0
#: Least RMS distance of the scan's (Bz, Br) points from their best straight line, in the scaled variables
#: (each axis mapped onto -1..1 by its range): below it the points lie on a line and span no area.
MIN_THICKNESS = 1e-3
#: Largest difference, N, between Fx_N.. and Fx_sensor_N.. on every row that still counts as a copy: a twentieth
#: of the recorder's last decimal (1e-6 N) would be too tight for a spreadsheet's re-rounding, a micronewton is
#: far below any reference's resolution (an ATI Nano17's is 6.25 mN).
COPY_TOLERANCE_N = 1e-6


@dataclass(frozen=True)
class Scan:
    """A calibration scan, one row per sample.

    ``time_s`` (N,) s, non-decreasing; ``B_uT`` (N, 3) field at the sensor in the chip's axes, uT;
    ``F_N`` (N, 3) reference force on the tip in the sensor frame (+z presses the tip towards the chip), N,
    or None for a recording without a reference; ``temperature_C`` (N,) degC or None; ``source`` the file
    name or "simulated"; ``sha256`` of the CSV bytes as read (simulated: of :func:`scan_csv` of the scan).
    ``model``: for the scan of a sensor's fitted model (a weight calibration, :mod:`magfab.models.weighing`), what
    it was fitted from and to (JSON values, kept in calibration.json's ``scan``); None for a measured scan.
    """

    time_s: np.ndarray
    B_uT: np.ndarray
    F_N: np.ndarray | None
    temperature_C: np.ndarray | None = None
    source: str = "simulated"
    sha256: str = ""
    model: Mapping[str, Any] | None = None

    @property
    def rows(self) -> int:
        return int(self.time_s.shape[0])

    @property
    def Br_uT(self) -> np.ndarray:
        """Lateral field magnitude sqrt(Bx^2 + By^2), uT, (N,)."""
        return np.hypot(self.B_uT[:, 0], self.B_uT[:, 1])

    @property
    def Fr_N(self) -> np.ndarray:
        """Lateral force magnitude sqrt(Fx^2 + Fy^2), N, (N,)."""
        if self.F_N is None:
            raise ScanError(f"scan {self.source}: no force columns ({', '.join(FORCE_COLUMNS)})")
        return np.hypot(self.F_N[:, 0], self.F_N[:, 1])


def scan_csv(scan: Scan, comments: Sequence[str] = ()) -> str:
    """The scan as CSV text (docs/bundle.md section 1), every value in Python's round-trip repr, so
    :func:`read_scan_csv` gives back the same numbers. ``comments`` become leading ``# `` lines."""
    cols = [scan.time_s, *scan.B_uT.T]
    names = list(SCAN_COLUMNS)
    if scan.temperature_C is not None:
        cols.append(scan.temperature_C)
        names.append(TEMPERATURE_COLUMN)
    if scan.F_N is not None:
        cols.extend(scan.F_N.T)
        names.extend(FORCE_COLUMNS)
    out = io.StringIO()
    for c in comments:
        out.write("# " + " ".join(str(c).splitlines()) + "\n")
    out.write(",".join(names) + "\n")
    for row in zip(*(np.asarray(c, dtype=float).tolist() for c in cols)):
        out.write(",".join(map(repr, row)) + "\n")
    return out.getvalue()


def _load(source: str | os.PathLike[str] | bytes, what: str = "scan CSV") -> tuple[bytes, str]:
    """(bytes, name) of a scan: a path (a regular file within ``what``'s limit, :mod:`.bounded`), CSV text (a str
    holding a newline, or a comma and naming no file) or CSV bytes."""
    given = "weighings" if what == "weighings CSV" else "scan"  # the name of a file given as its text
    if isinstance(source, bytes):
        return source, given
    if isinstance(source, str) and ("\n" in source or ("," in source and not os.path.exists(source))):
        return source.encode("utf-8"), given
    path = Path(source)
    try:
        return bounded.read_bytes(path, what), path.name
    except OSError as exc:
        kind = "the scan file" if what == "scan CSV" else f"the {what}"
        raise ScanError(f"{path}: cannot read {kind} ({exc.strerror or exc})") from None


def _number(text: str, name: str, line: int, column: str, row: int, band: tuple[float, float, str]) -> float:
    stripped = text.strip(" \t")
    if not NUMBER.fullmatch(stripped):
        what = shown(stripped) if stripped else "an empty field"
        finite = stripped.lower().lstrip("+-") in ("nan", "inf", "infinity")
        raise ScanError(f"{name}: line {line} (row {row}), column {column!r}: {what} is not "
                        f"{'a finite' if finite else 'a decimal'} number; every value must be a finite decimal "
                        "number in ASCII digits (e.g. 12.5 or -3e-2)")
    x = float(stripped)
    lo, hi, unit = band
    if not lo <= x <= hi:  # also an overflow to inf, e.g. 1e999
        raise ScanError(f"{name}: line {line} (row {row}), column {column!r}: {shown(stripped)} is outside the "
                        f"plausible band {lo:g} to {hi:g} {unit}; check the column's unit and scaling")
    return x


def _lines(source: str | os.PathLike[str] | bytes, what: str = "scan CSV") -> tuple[list[tuple[int, str]], str, bytes]:
    """(numbered lines that are neither blank nor comments, the file's name, its bytes)."""
    raw, name = _load(source, what)
    limit = f"a {what} may hold at most {MAX_ROWS:,} data rows (15 minutes at 543 Hz): split it or record less"
    if sum(raw.count(b) for b in _BREAKS) > 4 * MAX_ROWS:  # CRLF counts twice
        raise ScanError(f"{name}: over {4 * MAX_ROWS:,} line breaks; {limit}")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise ScanError(f"{name}: byte {exc.start} is not UTF-8; the scan must be UTF-8 text") from None
    lines = [(i, s) for i, s in enumerate(text.splitlines(), 1) if s.strip() and not s.lstrip().startswith("#")]
    if len(lines) - 1 > MAX_ROWS:
        raise ScanError(f"{name}: {len(lines) - 1:,} data rows; {limit}")
    return lines, name, raw


def _header(lines: list[tuple[int, str]], name: str) -> tuple[int, list[str]]:
    if not lines:
        raise ScanError(f"{name}: line 1: no header row (the file is empty or holds only comments); expected "
                        f"a header naming {', '.join(SCAN_COLUMNS + FORCE_COLUMNS)}")
    number, text = lines[0]
    names = [c.strip() for c in text.split(",")]
    seen: set[str] = set()
    for c in names:
        if c in seen:
            raise ScanError(f"{name}: line {number} (header): column {shown(c)} appears twice; each column once")
        seen.add(c)
    return number, names


def _require(names: list[str], needed: tuple[str, ...], name: str, number: int, note: str) -> None:
    """ScanError naming the first of ``needed`` the header lacks; for missing reference force columns beside the
    sensor's own (a recording), the line says why those cannot stand in (guard A, docs/bundle.md section 1)."""
    missing = [c for c in needed if c not in names]
    if not missing:
        return
    if missing[0] in FORCE_COLUMNS and any(c in names for c in SENSOR_FORCE_COLUMNS):
        raise ScanError(f"{name}: line {number} (header): no reference force ({', '.join(FORCE_COLUMNS)}): "
                        f"{', '.join(SENSOR_FORCE_COLUMNS)} are this sensor's own calibrated forces (a magfab-readout "
                        "recording), and a fit to them only gives back the calibration that made them; log a "
                        "reference force sensor during the scan and merge its log with --reference "
                        "(docs/bundle.md section 1)")
    raise ScanError(f"{name}: line {number} (header): missing column {missing[0]!r}; required columns are "
                    f"{', '.join(needed)} ({note})")


def _values(lines: list[tuple[int, str]], names: list[str], wanted: Sequence[str], name: str,
            bands: dict[str, tuple[float, float, str]]) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The ``wanted`` columns as arrays (rows,) and each row's line number (rows,); ``time_s`` non-decreasing."""
    hline = lines[0][0]
    index = {c: names.index(c) for c in wanted}
    values: dict[str, list[float]] = {c: [] for c in wanted}
    numbers = []
    last_t, last_line = -math.inf, hline
    for row, (number, s) in enumerate(lines[1:], 1):
        fields = s.split(",")
        if len(fields) != len(names):
            raise ScanError(f"{name}: line {number}: {len(fields)} values, but the header (line {hline}) names "
                            f"{len(names)} columns; every row needs one value per column")
        for c in wanted:
            values[c].append(_number(fields[index[c]], name, number, c, row, bands[c]))
        numbers.append(number)
        t = values["time_s"][-1]
        if t < last_t:
            raise ScanError(f"{name}: line {number}, column 'time_s': {t!r} is less than {last_t!r} on line "
                            f"{last_line}; time_s must be non-decreasing")
        last_t, last_line = t, number
    return {c: np.asarray(v, dtype=float) for c, v in values.items()}, np.asarray(numbers, dtype=int)


def _taxel_rows(lines: list[tuple[int, str]], names: list[str], taxel: int | None,
                name: str) -> list[tuple[int, str]]:
    """The header and the rows of one taxel of an array's recording (its ``taxel`` column, docs/bundle.md section 1);
    all lines when ``taxel`` is None. ScanError without the column or without a row of that taxel."""
    if taxel is None:
        return lines
    if TAXEL_COLUMN not in names:
        raise ScanError(f"{name}: line {lines[0][0]} (header): no {TAXEL_COLUMN!r} column, so no rows can be told to "
                        f"be taxel {taxel}'s; record an array with a current readout package")
    at = names.index(TAXEL_COLUMN)
    rows = [(n, s) for n, s in lines[1:] if len(s.split(",")) == len(names) and s.split(",")[at].strip() == str(taxel)]
    if not rows:
        seen = sorted({s.split(",")[at].strip() for _, s in lines[1:] if len(s.split(",")) == len(names)})
        raise ScanError(f"{name}: no rows of taxel {taxel}; the file holds taxel(s) {', '.join(seen) or 'none'}")
    return [lines[0], *rows]


def _enough(lines: list[tuple[int, str]], name: str, what: str) -> None:
    """ScanError unless the file holds two data rows (what interpolation in time needs)."""
    if len(lines) - 1 < 2:
        raise ScanError(f"{name}: line {lines[-1][0]}: the {what} ends after {len(lines) - 1} data rows; at least 2 "
                        "are needed")


def read_scan_csv(source: str | os.PathLike[str] | bytes, *, require_force: bool = True,
                  min_rows: int = MIN_ROWS, taxel: int | None = None) -> Scan:
    """A scan from a CSV file (path), CSV text (a str with a newline) or CSV bytes; docs/bundle.md section 1.

    Raises :class:`ScanError` (one line: file, line number, column, what is allowed) for a missing file or
    column, a value that is not an ASCII decimal number or lies outside its column's :data:`BANDS`, a row of
    the wrong length, decreasing time or fewer than ``min_rows`` rows; with ``require_force`` (a calibration
    scan) also for (Bz, Br) points that span no area (:func:`check_calibration_scan`), so a scan the fit
    would refuse is refused before any build work. ``require_force=False`` accepts a recording without the
    force columns (``F_N`` None). A recording's sensor forces (:data:`SENSOR_FORCE_COLUMNS`) never stand in
    for the reference force: without ``Fx_N, Fy_N, Fz_N`` beside them, or with copies of them there, the scan
    is refused with a line saying so (guard A). ``taxel``: only the rows of that taxel of an array (its ``taxel``
    column).
    """
    lines, name, raw = _lines(source)
    hline, names = _header(lines, name)
    lines = _taxel_rows(lines, names, taxel, name)
    with_force = require_force or any(c in names for c in FORCE_COLUMNS)
    _require(names, SCAN_COLUMNS + (FORCE_COLUMNS if with_force else ()), name, hline,
             f"any order; {TEMPERATURE_COLUMN} optional, others ignored")
    sensor = with_force and all(c in names for c in SENSOR_FORCE_COLUMNS)
    wanted = [c for c in (*SCAN_COLUMNS, TEMPERATURE_COLUMN, *FORCE_COLUMNS) if c in names]
    arr, _ = _values(lines, names, wanted + list(SENSOR_FORCE_COLUMNS if sensor else ()), name, BANDS)
    rows = len(lines) - 1
    if rows < min_rows:
        end = lines[-1][0]
        raise ScanError(f"{name}: line {end}: the scan ends after {rows} data rows; a calibration needs at "
                        f"least {min_rows} (the order-{LARGEST_ORDER} fit has "
                        f"{(LARGEST_ORDER + 1) * (LARGEST_ORDER + 2) // 2} coefficients and is cross-validated)")
    forces = np.column_stack([arr[c] for c in FORCE_COLUMNS]) if FORCE_COLUMNS[0] in arr else None
    if sensor and forces is not None:
        own = np.column_stack([arr[c] for c in SENSOR_FORCE_COLUMNS])
        if np.max(np.abs(forces - own)) <= COPY_TOLERANCE_N:
            raise ScanError(f"{name}: columns {', '.join(FORCE_COLUMNS)} repeat {', '.join(SENSOR_FORCE_COLUMNS)} "
                            "(this sensor's own forces) on every row; the reference force must come from a "
                            "reference sensor: merge its log with --reference (docs/bundle.md section 1)")
    scan = Scan(arr["time_s"], np.column_stack([arr[c] for c in SCAN_COLUMNS[1:]]), forces,
                arr.get(TEMPERATURE_COLUMN), name, hashlib.sha256(raw).hexdigest())
    if require_force:
        check_calibration_scan(scan)
    return scan


@dataclass(frozen=True)
class Recording:
    """A recording of ``magfab-readout record`` (docs/bundle.md section 1): ``scan`` (device ``time_s``, field,
    temperature, and in ``F_N`` the sensor's own forces, or None when the file has no Fx_sensor_N... columns),
    ``host_time_s`` (N,) the host's clock when each sample was read (Unix time, s) and ``lines`` (N,) each row's
    line number in the file."""

    scan: Scan
    host_time_s: np.ndarray
    lines: np.ndarray


@dataclass(frozen=True)
class Reference:
    """A reference force sensor's log: ``time_s`` (M,) on the host clock of the recording's ``host_time_s``
    (Unix time, s), non-decreasing; ``F_N`` (M, 3) its force in the sensor frame, N; ``lines`` (M,) each row's
    line number; ``source`` the file name; ``sha256`` of its bytes."""

    time_s: np.ndarray
    F_N: np.ndarray
    lines: np.ndarray
    source: str
    sha256: str


def read_recording(source: str | os.PathLike[str] | bytes, taxel: int | None = None) -> Recording:
    """A recording (:class:`Recording`) from a file, CSV text or bytes; ScanError (one line) as
    :func:`read_scan_csv`, and for a missing ``host_time_s``. ``taxel``: only that taxel's rows of an array's."""
    lines, name, raw = _lines(source)
    hline, names = _header(lines, name)
    lines = _taxel_rows(lines, names, taxel, name)
    _require(names, (*SCAN_COLUMNS, HOST_TIME_COLUMN), name, hline, "any order; a recording of magfab-readout "
             "record has host_time_s, the host's clock, which ties it to the reference's log: record again "
             f"with a current readout package; {TEMPERATURE_COLUMN} and {', '.join(SENSOR_FORCE_COLUMNS)} optional")
    optional = [c for c in (TEMPERATURE_COLUMN, *SENSOR_FORCE_COLUMNS) if c in names]
    arr, numbers = _values(lines, names, [*SCAN_COLUMNS, HOST_TIME_COLUMN, *optional], name, BANDS)
    _enough(lines, name, "recording")
    own = (np.column_stack([arr[c] for c in SENSOR_FORCE_COLUMNS])
           if all(c in arr for c in SENSOR_FORCE_COLUMNS) else None)
    scan = Scan(arr["time_s"], np.column_stack([arr[c] for c in SCAN_COLUMNS[1:]]), own, arr.get(TEMPERATURE_COLUMN),
                name, hashlib.sha256(raw).hexdigest())
    return Recording(scan, arr[HOST_TIME_COLUMN], numbers)


def read_reference(source: str | os.PathLike[str] | bytes) -> Reference:
    """A reference force sensor's log (:class:`Reference`): columns ``time_s`` (host clock, Unix time, s) and
    ``Fx_N, Fy_N, Fz_N`` (others ignored); ScanError (one line) as :func:`read_scan_csv`."""
    lines, name, raw = _lines(source, "reference log")
    hline, names = _header(lines, name)
    _require(names, REFERENCE_COLUMNS, name, hline, "any order, others ignored; time_s is the host's clock, "
             "Unix time in s, the clock of the recording's host_time_s")
    arr, numbers = _values(lines, names, REFERENCE_COLUMNS, name, {**BANDS, "time_s": HOST_TIME_BAND})
    _enough(lines, name, "reference log")
    return Reference(arr["time_s"], np.column_stack([arr[c] for c in FORCE_COLUMNS]), numbers, name,
                     hashlib.sha256(raw).hexdigest())


def check_calibration_scan(scan: Scan) -> None:
    """:class:`ScanError` unless ``scan`` can be calibrated on: force columns, every value finite and within
    :data:`BANDS`, and (Bz, Br) points that span an area (each axis at least :data:`MIN_SPAN_UT`, the points
    at least :data:`MIN_THICKNESS` off a straight line in the scaled variables). Cheap (one 2x2 eigenproblem),
    so run when the scan is read and again at the start of every fit, before any build work."""
    if scan.F_N is None:
        raise ScanError(f"scan {scan.source}: no force columns ({', '.join(FORCE_COLUMNS)}); a calibration "
                        "needs the reference force")
    columns = dict(zip(SCAN_COLUMNS + FORCE_COLUMNS, [scan.time_s, *scan.B_uT.T, *scan.F_N.T]))
    if scan.temperature_C is not None:
        columns[TEMPERATURE_COLUMN] = scan.temperature_C
    for column, x in columns.items():
        lo, hi, unit = BANDS[column]
        bad = np.flatnonzero(~((x >= lo) & (x <= hi)))  # NaN fails both
        if bad.size:
            raise ScanError(f"scan {scan.source}: row {bad[0] + 1}, column {column!r}: {float(x[bad[0]])!r} is "
                            f"outside the plausible band {lo:g} to {hi:g} {unit} (or not finite)")
    bz, br = scan.B_uT[:, 2], scan.Br_uT
    uv = []
    for axis, x in (("Bz", bz), ("Br", br)):
        span = float(x.max() - x.min())
        if not span >= MIN_SPAN_UT:
            raise ScanError(f"scan {scan.source}: the scan's (Bz, Br) points span no area: {axis} spans only "
                            f"{span:.3g} uT (at least {MIN_SPAN_UT:g} uT needed); a calibration needs a 2-D scan "
                            "(normal and lateral load)")
        uv.append((x - (x.max() + x.min()) / 2.0) / (span / 2.0))
    centred = np.column_stack(uv) - np.mean(uv, axis=1)
    thickness = math.sqrt(max(float(np.linalg.eigvalsh(centred.T @ centred / len(bz))[0]), 0.0))
    if not thickness >= MIN_THICKNESS:
        raise ScanError(f"scan {scan.source}: the scan's (Bz, Br) points span no area: they lie on a line (RMS "
                        f"distance {thickness:.2g} of the scaled range, at least {MIN_THICKNESS:g} needed); a "
                        "calibration needs a 2-D scan (normal and lateral load)")
