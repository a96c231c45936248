"""``record --format``: a recording as robot stacks read it (docs/bundle.md section 1, "The recording").

``record`` always streams its rows to a CSV first (each row flushed as it comes, so Ctrl-C or a lost board keeps
what was read). For ``parquet`` and ``mcap`` that CSV is ``OUT.partial.csv``, converted into OUT when the recording
ends and then removed; OUT is written whole or not at all.

- ``parquet`` (pyarrow): one row a sample, the CSV's columns plus ``stamp_s``, the sample's time on this computer's
  clock mapped from the device's (:mod:`.clock`); each column's unit in its field metadata; the file's metadata has
  the recording's header (``magfab``: JSON) and the calibration the forces were made with (``magfab.calibration``:
  calibration.json's text).
- ``mcap`` (mcap, mcap-ros2-support): ROS 2 messages, CDR-encoded, their definitions embedded (profile ``ros2``):
  ``geometry_msgs/msg/WrenchStamped`` per taxel on ``/magfab/wrench`` (an array's taxel k on
  ``/magfab/taxel_k/wrench``), ``sensor_msgs/msg/MagneticField`` (tesla) on ``/magfab/magnetic_field`` (per taxel
  likewise) and ``sensor_msgs/msg/Temperature`` on ``/magfab/temperature`` where the chip's temperature is read;
  each stamped, and logged, at ``stamp_s``. The MCAP metadata record ``magfab`` holds the header (``recording``)
  and the calibration (``calibration.json``).

The libraries are optional extras of the readout package (``parquet``, ``mcap``; or ``pip install pyarrow``, ``pip
install mcap mcap-ros2-support``): the base install stays pyserial-only, and a format whose library is missing is
refused before the board is opened.
"""

from __future__ import annotations

import csv
import importlib
import json
import os
import re
import sys
from array import array
from typing import Any, Callable, Dict, Iterator, List, Optional, Tuple

from .clock import clock_map
from .usage import UsageError

__all__ = ["FORMATS", "UNITS", "format_of", "require", "convert", "partial_path", "prepare", "finish"]

FORMATS = ("csv", "parquet", "mcap")
#: Each recorded column's unit (stamp_s is added by the conversion).
UNITS = {"time_s": "s (device clock)", "host_time_s": "s (Unix time, when read)", "stamp_s": "s (Unix time, mapped "
         "from the device clock)", "taxel": "index", "Bx_uT": "uT", "By_uT": "uT", "Bz_uT": "uT",
         "temperature_C": "degC", "Fx_sensor_N": "N", "Fy_sensor_N": "N", "Fz_sensor_N": "N", "status": "bits",
         "seq": "count"}
_INTEGER = ("taxel", "status", "seq")
#: What each format imports, and the packages (the readout package's extra of the format's name) that give it.
_MODULES = {"parquet": ("pyarrow", "pyarrow.parquet"), "mcap": ("mcap", "mcap_ros2.writer")}
_PACKAGES = {"parquet": ("pyarrow",), "mcap": ("mcap", "mcap-ros2-support")}

# The ROS 2 message definitions the MCAP file embeds (ros2msg, dependencies after a line of '=' and 'MSG: type'), as
# in ROS 2's common_interfaces (geometry_msgs, sensor_msgs, std_msgs) and rcl_interfaces (builtin_interfaces).
_SEPARATOR = "=" * 80 + "\n"
_HEADER = "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n"
_TIME = "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"
_VECTOR3 = "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n"
_WRENCH = "MSG: geometry_msgs/Wrench\nVector3 force\nVector3 torque\n"
MSGDEFS = {
    "geometry_msgs/msg/WrenchStamped": "std_msgs/Header header\nWrench wrench\n" + _SEPARATOR + _HEADER + _SEPARATOR
    + _TIME + _SEPARATOR + _WRENCH + _SEPARATOR + _VECTOR3,
    "sensor_msgs/msg/MagneticField": "std_msgs/Header header\ngeometry_msgs/Vector3 magnetic_field\n"
    "float64[9] magnetic_field_covariance\n" + _SEPARATOR + _HEADER + _SEPARATOR + _TIME + _SEPARATOR + _VECTOR3,
    "sensor_msgs/msg/Temperature": "std_msgs/Header header\nfloat64 temperature\nfloat64 variance\n" + _SEPARATOR
    + _HEADER + _SEPARATOR + _TIME,
}


def format_of(requested: Optional[str], out: str) -> str:
    """The format asked for, else the one OUT's suffix names (``.parquet``, ``.mcap``; anything else CSV)."""
    if requested is not None:
        return requested
    suffix = os.path.splitext(out)[1].lower()
    return {".parquet": "parquet", ".mcap": "mcap"}.get(suffix, "csv")


def require(fmt: str) -> None:
    """UsageError (one line) when the format's library is not installed."""
    try:
        for module in _MODULES.get(fmt, ()):
            importlib.import_module(module)
    except ImportError:
        raise UsageError(f"--format {fmt} needs {' and '.join(_PACKAGES[fmt])}: pip install "
                         f"{' '.join(_PACKAGES[fmt])} (the readout package's extra '{fmt}')") from None


def partial_path(out: str) -> str:
    """Where ``record`` streams its rows before converting them into OUT."""
    return out + ".partial.csv"


def prepare(requested: Optional[str], out: str) -> Tuple[str, str]:
    """(format, the file ``record`` streams its rows to), refused (UsageError, one line) before the board is opened:
    a format whose library is missing, and a partial file an earlier recording left (its rows, which a new
    recording would overwrite)."""
    fmt = format_of(requested, out)
    if fmt == "csv":
        return fmt, out
    require(fmt)
    partial = partial_path(out)
    if os.path.exists(partial):
        raise UsageError(f"{partial} exists: the rows of an earlier recording that was not converted (it is a CSV "
                         "recording); move it away first")
    return fmt, partial


def finish(partial: str, out: str, fmt: str, calibration: Callable[[], Dict[str, Any]], rows: int) -> None:
    """After the board is closed: the recording's rows converted into OUT (:func:`convert`; ``calibration()`` the
    calibration.json the forces were made with, read only then), saying so on stderr (an hour's MCAP takes minutes);
    a CSV recording is already in place."""
    if fmt == "csv":
        return
    print(f"magfab-readout: converting {rows} rows from {partial} to {out} ({fmt})", file=sys.stderr, flush=True)
    convert(partial, out, fmt, calibration())
    print(f"magfab-readout: wrote {out}", file=sys.stderr)


def convert(partial: str, out: str, fmt: str, calibration: Dict[str, Any]) -> int:
    """The recording's CSV ``partial`` (``record``'s header and rows) written to ``out`` in ``fmt``, whole or not at
    all; ``calibration``: the calibration.json the forces were made with (an array: {taxel: document}). Returns the
    rows written. ``partial`` is removed once ``out`` is in place. Two passes over the file, so an hour's rows are
    never held in memory: the device and host times first, as arrays of doubles (for the clock map), then the rows."""
    header, columns = _head(partial)
    t, h = columns.index("time_s"), columns.index("host_time_s")
    times, hosts = array("d"), array("d")
    for row in _rows(partial, columns):
        times.append(row[t])
        hosts.append(row[h])
    if any(b < a for a, b in zip(times, times[1:])):  # an array's taxels of one cycle may interleave
        order = sorted(range(len(times)), key=times.__getitem__)
        times, hosts = array("d", (times[k] for k in order)), array("d", (hosts[k] for k in order))
    t0, h0, slope = clock_map(times, hosts)
    stamped = ((row, h0 + slope * (row[t] - t0)) for row in _rows(partial, columns))
    tmp = out + ".tmp"
    try:
        (_parquet if fmt == "parquet" else _mcap)(tmp, header, columns, stamped, calibration)
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    os.remove(partial)
    return len(times)


def _head(path: str) -> Tuple[List[str], List[str]]:
    """(header lines without their '# ', column names) of a recording CSV."""
    header: List[str] = []
    with open(path, encoding="utf-8", newline="") as f:
        for line in f:
            if not line.startswith("#"):
                return header, line.strip().split(",")
            header.append(line[1:].strip())
    raise ValueError(f"{path}: no column header")


def _rows(path: str, columns: List[str]) -> Iterator[List[Any]]:
    """The recording's rows as numbers (the index columns as integers)."""
    integer = [c in _INTEGER for c in columns]
    with open(path, encoding="utf-8", newline="") as f:
        lines = (line for line in f if not line.startswith("#"))
        next(lines)  # the column header
        for row in csv.reader(lines):
            yield [int(v) if i else float(v) for i, v in zip(integer, row)]


def _meta(header: List[str]) -> str:
    return json.dumps({"format": "magfab-recording/1", "header": header, "units": UNITS}, sort_keys=True)


#: Rows a Parquet row group is written in.
BATCH = 65536


def _parquet(path, header, columns, stamped, calibration) -> None:
    # imported lazily: an optional extra of the readout, and slow to import
    import pyarrow as pa
    import pyarrow.parquet as pq

    names = [*columns, "stamp_s"]
    fields = [pa.field(c, pa.int64() if c in _INTEGER else pa.float64(), nullable=False,
                       metadata={"unit": UNITS[c]}) for c in names]
    schema = pa.schema(fields, metadata={"magfab": _meta(header),
                                         "magfab.calibration": json.dumps(calibration, sort_keys=True)})
    with pq.ParquetWriter(path, schema) as writer:
        batch: List[List[Any]] = []

        def flush() -> None:
            data = [[row[i] for row in batch] for i in range(len(names))]
            writer.write_table(pa.Table.from_arrays([pa.array(d, type=f.type) for d, f in zip(data, fields)],
                                                    schema=schema))
            batch.clear()

        for row, stamp in stamped:
            batch.append([*row, stamp])
            if len(batch) == BATCH:
                flush()
        if batch:
            flush()


def _mcap(path, header, columns, stamped, calibration) -> None:
    # imported lazily: an optional extra of the readout
    from mcap_ros2.writer import Writer

    col = {c: i for i, c in enumerate(columns)}
    spec = next((json.loads(h[len("spec: "):]) for h in header if h.startswith("spec: ")), "sensor")
    frame = "magfab_" + re.sub(r"[^A-Za-z0-9_]", "_", str(spec))  # a ROS frame id: letters, digits, underscores
    with open(path, "wb") as f:
        writer = Writer(f)
        schemas = {name: writer.register_msgdef(name, text) for name, text in MSGDEFS.items()}
        for row, stamp in stamped:
            taxel = f"taxel_{row[col['taxel']]}" if "taxel" in col else ""
            topic = f"/magfab/{taxel}/" if taxel else "/magfab/"
            ns = round(stamp * 1e9)
            head = {"stamp": {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000},
                    "frame_id": f"{frame}_{taxel}" if taxel else frame}
            seq = row[col["seq"]]
            force = {"x": row[col["Fx_sensor_N"]], "y": row[col["Fy_sensor_N"]], "z": row[col["Fz_sensor_N"]]}
            writer.write_message(topic + "wrench", schemas["geometry_msgs/msg/WrenchStamped"],
                                 {"header": head, "wrench": {"force": force, "torque": {"x": 0.0, "y": 0.0, "z": 0.0}}},
                                 log_time=ns, publish_time=ns, sequence=seq)
            field = {k: 1e-6 * row[col[f"B{k}_uT"]] for k in "xyz"}  # the message's unit is the tesla
            writer.write_message(topic + "magnetic_field", schemas["sensor_msgs/msg/MagneticField"],
                                 {"header": head, "magnetic_field": field, "magnetic_field_covariance": [0.0] * 9},
                                 log_time=ns, publish_time=ns, sequence=seq)
            if "temperature_C" in col:
                writer.write_message(topic + "temperature", schemas["sensor_msgs/msg/Temperature"],
                                     {"header": head, "temperature": row[col["temperature_C"]], "variance": 0.0},
                                     log_time=ns, publish_time=ns, sequence=seq)
        writer.add_metadata("magfab", {"recording": _meta(header),
                                       "calibration.json": json.dumps(calibration, sort_keys=True)})
        writer.finish()
