"""``magfab sensor ...``: the physical sensors' records (docs/sensors.md), beside their engine :mod:`magfab.sensors`.

Registered into ``magfab`` by :func:`register`, which hands over the CLI's error handling (one line and exit 2 for
the user's input, 130 for Ctrl-C), so this module never imports :mod:`magfab.cli`."""

from __future__ import annotations

import contextlib
import json
import os
from collections.abc import Callable
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import click

# magfab's own modules are imported lazily, inside the commands, as in magfab.cli: `magfab --help` loads none of them.

Handler = Callable[[], AbstractContextManager[None]]
_handled: Handler = contextlib.nullcontext


def register(group: click.Group, handled: Handler) -> None:
    """Add the ``sensor`` commands to ``group``, their errors handled by ``handled``."""
    global _handled
    _handled = handled
    group.add_command(sensor)


_ROOT_HELP = "The sensor records' root folder (default: $MAGFAB_SENSORS, else the nearest sensors/ here or above)."


def _root(explicit: Path | None, must_exist: bool = True) -> Path:
    from .formats import sensor_records as rec
    from .sensors import records_checked

    with records_checked():
        return rec.find_root(explicit, must_exist=must_exist)


def _open(root: Path | None, sensor_id: str):
    from .formats import sensor_records as rec
    from .sensors import records_checked

    with records_checked():
        return rec.open_sensor(_root(root), sensor_id)


@click.group()
def sensor() -> None:
    """Records of physical sensors: what each was made from and every measurement made on it (docs/sensors.md)."""


@sensor.command()
@click.argument("sensor_id", metavar="ID")
@click.option("--build", "build_dir", type=click.Path(file_okay=False, path_type=Path),
              help="The build folder the sensor was made from (default: the one you stand in, else build/<name> of "
                   "the default spec).")
@click.option("--sensors", "root", type=click.Path(file_okay=False, path_type=Path), help=_ROOT_HELP)
@click.option("--date", help="When it was made, ISO 8601 (default: now; UTC unless it names a zone).")
def add(sensor_id: str, build_dir: Path | None, root: Path | None, date: str | None) -> None:
    """Start the record of the sensor ID from a build folder: its spec, design and acceptance bands, and any
    calibration measured into that folder (so a rebuild can no longer lose it)."""
    with _handled():
        from .pipeline import default_out_dir
        from .sensors import add_from_build, build_folder
        from .spec import load_spec

        folder = build_folder(build_dir, default_out_dir(load_spec(None)) if build_dir is None else Path())
        made, adopted = add_from_build(_root(root, must_exist=False), sensor_id, folder, date)
        click.echo(f"added sensor {made.id} ({made.info.get('spec_name')}, from {folder}) in {made.root}")
        if adopted:
            click.echo(f"  kept the {adopted} calibration(s) measured into {folder} as its first")


@sensor.command("list")
@click.option("--sensors", "root", type=click.Path(file_okay=False, path_type=Path), help=_ROOT_HELP)
@click.option("--json", "as_json", is_flag=True, help="Print the sensors as JSON on stdout.")
def list_(root: Path | None, as_json: bool) -> None:
    """One line per sensor: design, skin, calibrations and checks, the last calibration and check."""
    with _handled():
        from .formats import sensor_records as rec
        from .sensors import records_checked, summary

        with records_checked():
            rows = [summary(s) for s in rec.list_sensors(_root(root))]
        if as_json:
            click.echo(json.dumps(rows, indent=2, sort_keys=True))
            return
        click.echo(f"{'ID':<14} {'design':<14} {'skin':>4} {'cal':>4} {'checks':>6}  last calibration (Fz held out)"
                   "   last check")
        for r in rows:
            last = "-" if r["last_calibration"] is None else f"{_day(r['last_calibration'])} ({_mN(r)})"
            click.echo(f"{r['id']:<14} {r['design']!s:<14} {r['epoch']:>4} {r['calibrations']:>4} "
                       f"{r['checks']:>6}  {last:<32} {r['last_check'] or '-'}")


def _day(date: str) -> str:
    return date[:16].replace("T", " ")


def _mN(row: dict[str, Any]) -> str:
    x = row["last_rms_holdout_Fz_mN"]
    return "-" if x is None else f"{x:.3g} mN"


@sensor.command()
@click.argument("sensor_id", metavar="ID")
@click.option("--sensors", "root", type=click.Path(file_okay=False, path_type=Path), help=_ROOT_HELP)
@click.option("--plot", type=click.Path(dir_okay=False, path_type=Path),
              help="Also draw the history (sensitivity, rest field, errors, checks against the date) into this PNG.")
@click.option("--json", "as_json", is_flag=True, help="Print the history and the re-skin comparison as JSON.")
def show(sensor_id: str, root: Path | None, plot: Path | None, as_json: bool) -> None:
    """The history of sensor ID: every event, and a new skin's calibration against the previous skin's."""
    with _handled():
        from dataclasses import asdict

        from .sensors import comparisons, history, summary

        found = _open(root, sensor_id)
        rows, compared, head = history(found), comparisons(found), summary(found)
        if plot is not None:
            _plot(found, plot)
        if as_json:
            click.echo(json.dumps({"sensor": head, "events": [asdict(r) for r in rows],
                                   "reskin": [dict(asdict(c), line=c.line) for c in compared]}, indent=2))
            return
        click.echo(f"sensor {found.id}: design {head['design']}, skin {head['epoch']}, {head['calibrations']} "
                   f"calibration(s), {head['checks']} check(s)")
        click.echo(f"{'#':>3}  {'date (UTC)':<16}  {'event':<11} {'skin':>4} {'taxel':>5}  figures")
        for r in rows:
            click.echo(f"{r.number:>3}  {_day(r.date):<16}  {r.kind:<11} {r.epoch:>4} "
                       f"{'-' if r.taxel is None else r.taxel:>5}  {r.figures}")
        if compared:
            click.echo("new skin against the previous one (newest calibration of each):")
            for c in compared:
                click.echo(f"  {c.line}")
        if plot is not None:
            click.echo(f"history chart: {plot}")


def _plot(found, path: Path) -> None:
    """The history chart into ``path`` (written whole, then renamed), never inside the record itself."""
    from .errors import InputError
    from .export.sensor_history import chart
    from .sensors import bands, records_checked

    target = path.resolve()
    if target == found.root.resolve() or found.root.resolve() in target.parents:
        raise InputError(f"--plot = {path}: is inside the sensor records ({found.root}), which only appends "
                         "events: draw the chart elsewhere")
    with records_checked():
        png = chart(found.id, found.events(), bands(found))
    tmp = target.with_name(f".{target.name}.tmp-{os.getpid()}")
    tmp.write_bytes(png)
    os.replace(tmp, target)


@sensor.command()
@click.argument("sensor_id", metavar="ID")
@click.option("--note", default="", help="What was replaced and why (kept in the record).")
@click.option("--sensors", "root", type=click.Path(file_okay=False, path_type=Path), help=_ROOT_HELP)
@click.option("--date", help="When the new skin went on, ISO 8601 (default: now).")
def reskin(sensor_id: str, note: str, root: Path | None, date: str | None) -> None:
    """Record a new skin on sensor ID: a new calibration epoch begins, and `magfab sensor show` compares its first
    calibration with the old skin's."""
    with _handled():
        from .formats import sensor_records as rec
        from .sensors import records_checked

        found = _open(root, sensor_id)
        with records_checked():
            event = found.append("reskin", {"note": note}, date=rec.parse_date(date) if date else None)
        click.echo(f"sensor {found.id}: new skin (skin {found.epoch()}) on {_day(event['date'])}; calibrate it "
                   f"before use: magfab calibrate SCAN --reference REF --sensor {found.id}")
