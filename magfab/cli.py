"""Command line: the only module that parses arguments and prints.

Exit codes: 0 success; 2 invalid or infeasible spec, scan or output directory (any
:class:`magfab.errors.InputError`: one message on stderr, nothing written); 1 internal error; 130 interrupted.
"""

from __future__ import annotations

import signal
import sys


def _on_interrupt(signum: int, frame: object) -> None:
    """Remember the interrupt, then raise it: a library that turns it into another error on the way (an
    ImportError from an import it cut short) still ends as an interrupt, exit 130."""
    global _interrupted
    _interrupted = True
    raise KeyboardInterrupt


_interrupted = False
try:  # Ctrl-C while these load is Python's KeyboardInterrupt, ended here as exit 130 (no handler needed yet)
    import json
    import os
    import warnings
    from collections.abc import Iterator, Mapping
    from contextlib import contextmanager
    from pathlib import Path
    from typing import Any, cast

    import click

    from . import __version__
    from .calibration_input import kept_from_record, read_scan
    from .cli_progress import QUIET, phases, stages, way
    from .cli_usage import EXIT_INTERRUPTED, OneLineErrors
    from .cli_usage import fail as _fail
    from .errors import InputError, SpecError, shown
    from .out_path import check_out
except KeyboardInterrupt:
    sys.stderr.write("magfab: error: interrupted; nothing was written\n")
    raise SystemExit(130) from None

# Imported lazily, inside the commands that use them, for speed: ``magfab --help`` and every command load only what
# they run. magfab's own modules (the pipeline, the checks, the design search) pull in numpy, pydantic and the
# models, magfab.output and importlib.resources the archive, hashing and temporary-file modules; rich draws the progress
# bars. Only magfab.errors (dataclasses and enum) is imported above.

EXIT_BAD_INPUT = 2
EXIT_INTERNAL = 1
#: The command ran and wrote its results, and they fail what was asked: `magfab design` when no design meets the
#: targets with margin (as magfab-readout exits when the sensor fails a check step).
EXIT_UNMET = 3




@contextmanager
def _handled() -> Iterator[None]:
    """Turn errors into one line and an exit code by their type in :mod:`magfab.errors`: the user's input or
    environment (InputError, a missing or unreadable file) exits 2; anything else is our bug and exits 1;
    an interrupt exits 130. Never a traceback, unless MAGFAB_DEBUG is set."""
    try:
        yield
    except InputError as exc:
        _fail(str(exc), EXIT_BAD_INPUT)
    except KeyboardInterrupt:
        _fail("interrupted; nothing was written and any previous output is untouched", EXIT_INTERRUPTED)
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError) as exc:
        if exc.filename is None or os.environ.get("MAGFAB_DEBUG"):
            raise
        _fail(f"{exc.filename}: {exc.strerror}", EXIT_BAD_INPUT)
    except Exception as exc:
        if _interrupted:
            _fail("interrupted; nothing was written and any previous output is untouched", EXIT_INTERRUPTED)
        if os.environ.get("MAGFAB_DEBUG"):
            raise
        _fail(f"internal error: {type(exc).__name__}: {exc} (set MAGFAB_DEBUG=1 for a traceback)", EXIT_INTERNAL)


def _catch_interrupts(ctx: click.Context) -> None:
    """Ctrl-C is exit 130 and one line for the command's run, never a traceback: installed when a command runs
    (importing this module leaves the process's handlers alone), the previous handler back when it ends."""
    try:
        previous = signal.signal(signal.SIGINT, _on_interrupt)
    except ValueError:  # not the main thread (a test's runner): Ctrl-C stays Python's KeyboardInterrupt
        return
    ctx.call_on_close(lambda: signal.signal(signal.SIGINT, previous))


@click.group(cls=OneLineErrors, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="magfab")
@click.pass_context
def main(ctx: click.Context) -> None:
    """Turn one design spec into the files to make a magnetic soft tactile sensor."""
    _catch_interrupts(ctx)
    warnings.showwarning = _one_line_warning


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """A library's warning as one line on stderr (what and which library), never its source line."""
    origin = Path(filename).parent.name if filename else "?"
    click.echo(f"magfab: warning: {category.__name__}: {message} ({origin})", err=True)


@main.command()
@click.argument("spec", required=False, type=click.Path(dir_okay=False, path_type=Path))
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              help="Output directory (default: ./build/<spec name>).")
@click.option("--json", "as_json", is_flag=True, help="Print a machine-readable summary on stdout.")
@click.option("--discard-calibration", is_flag=True,
              help="Replace a measured calibration the build folder holds though no sensor record keeps it (by "
                   "default the build refuses: keep it first with `magfab sensor add ID --build DIR`).")
@QUIET
def build(spec: Path | None, out_dir: Path | None, as_json: bool, discard_calibration: bool, quiet: bool) -> None:
    """Build SPEC (default: the embedded MagOne reference design). Its stages go to stderr as it runs (--quiet: not)."""
    with _handled():
        check_out(out_dir)
    _run_build(spec, out_dir, as_json, None, discard=discard_calibration, quiet=quiet)


@main.command()
@click.argument("scan", required=False, type=click.Path(dir_okay=False, path_type=Path))
@click.option("--weights", type=click.Path(dir_okay=False, path_type=Path),
              help="Instead of SCAN: the weighings, the chip's mean field under known weights (docs/bundle.md section "
                   "1b); the sensor's model is fitted to them and the calibration built from the model (no force "
                   "sensor needed).")
@click.option("--reference", type=click.Path(dir_okay=False, path_type=Path),
              help="The reference force sensor's log (time_s on this computer's clock, Fx_N, Fy_N, Fz_N), merged "
                   "into SCAN (a magfab-readout recording) by time.")
@click.option("--spec", "spec", type=click.Path(dir_okay=False, path_type=Path),
              help="The spec the sensor was built from (default: the build folder's own spec.json).")
@click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
              help="Build folder to update (default: the build folder SCAN is in, or the one you are in).")
@click.option("--taxel", type=click.IntRange(min=0), default=None,
              help="For an array: the taxel SCAN pressed (its rows of the recording's taxel column are fitted).")
@click.option("--sensor", "sensor_id", metavar="ID",
              help="The sensor SCAN was recorded on: append the calibration to its record (`magfab sensor add`) and "
                   "leave the build folder as it is; `magfab-readout upload --sensor ID` then puts it on the board.")
@click.option("--sensors", "sensors_root", type=click.Path(file_okay=False, path_type=Path),
              help="The folder of sensor records (default: $MAGFAB_SENSORS, else the nearest sensors/ folder).")
@click.option("--date", help="With --sensor: when the scan was taken (ISO 8601, UTC unless it names a zone; default: "
                             "now).")
@click.option("--json", "as_json", is_flag=True, help="Print a machine-readable summary on stdout.")
@QUIET
def calibrate(scan: Path | None, weights: Path | None, reference: Path | None, spec: Path | None, out_dir: Path | None,
              taxel: int | None, sensor_id: str | None, sensors_root: Path | None, date: str | None,
              as_json: bool, quiet: bool) -> None:
    """Fit the force calibration to SCAN (a CSV, see docs/bundle.md). With --sensor ID, append it to that
    sensor's record, which no build touches; without, update the build with it: calibration.json, the firmware's
    EEPROM record and the readout package carry the new coefficients.

    Inside a build folder no option is needed: `magfab calibrate scan.csv --reference reference.csv` updates
    that build from its own spec.json, file by file (your shell stays where it is). An array is calibrated one
    taxel at a time (`--taxel K`); the other taxels keep the scans they were fitted to. A scan whose field at rest
    is outside the design's acceptance band is refused (the wrong sensor or build, or a misassembled sensor).

    Without a force sensor: `magfab calibrate --weights weights.csv` fits the sensor's model to known weights on the
    build's weight jig and builds the calibration from the model (docs/bundle.md section 1b); a sensor on a new skin
    (`magfab sensor reskin`) keeps its magnet's and silicone's fitted parameters, so three weighings do."""
    with _handled():
        check_out(out_dir)
    if (scan is None) == (weights is None) or (weights is not None and (reference or taxel is not None)):
        _fail("give a SCAN, or --weights FILE without --reference and --taxel (a weight calibration is of a single "
              "taxel's sensor, and its loads are the weights')", EXIT_BAD_INPUT)
    path = cast(Path, scan or weights)
    if sensor_id is None:
        if date is not None:
            _fail("--date dates a sensor's calibration: give it with --sensor ID", EXIT_BAD_INPUT)
        _run_build(spec, out_dir, as_json, path, reference, taxel, weights=weights is not None, quiet=quiet)
        return
    _calibrate_sensor(path, reference, spec, out_dir, taxel, sensor_id, sensors_root, date, as_json,
                      weights is not None)


def _build_folder(*candidates: Path | None) -> Path | None:
    """The first of ``candidates`` that is a magfab build folder (it has a manifest.json magfab wrote)."""
    from .output import is_build

    return next((folder for folder in candidates if folder is not None and is_build(folder)), None)


def _calibration_target(spec_path: Path | None, out_dir: Path | None, scan_path: Path):
    """(spec, build folder) for ``magfab calibrate``: the folder is --out, else the build folder the scan is
    in, else the one we stand in (so a scan recorded into build/x/ never makes build/x/build/x/); the spec
    is --spec, else that folder's spec.json (or, for --out a new folder, the spec of the build the scan is in or
    we stand in), else the embedded MagOne design."""
    from .pipeline import default_out_dir
    from .spec import load_build_spec, load_spec

    here = _build_folder(scan_path.parent, Path.cwd())
    found = _build_folder(out_dir) if out_dir is not None else here
    if spec_path is None:
        source = found or here  # --out a new folder: the spec of the build the scan is in
        loaded = load_build_spec(source) if source is not None else load_spec(None)
        return loaded, (found or out_dir or default_out_dir(loaded))
    loaded = load_spec(spec_path)
    if found is not None and out_dir is None:
        built = load_build_spec(found).name
        if built != loaded.name:
            raise SpecError("spec", shown(str(spec_path)), f"names the design {loaded.name!r} but the build folder "
                            f"{found} holds {built!r}", "drop --spec to use the folder's own, or pass --out")
    return loaded, (found or out_dir or default_out_dir(loaded))


def _run_build(spec: Path | None, out_dir: Path | None, as_json: bool, scan_path: Path | None = None,
               reference: Path | None = None, taxel: int | None = None, discard: bool = False,
               weights: bool = False, quiet: bool = False) -> None:
    with _handled():  # every import inside: Ctrl-C while a heavy library loads is still exit 130
        from .output import is_build
        from .pipeline import build as run_build
        from .pipeline import default_out_dir
        from .spec import load_spec

        scan = None
        if scan_path is None:
            loaded = load_spec(spec)
            target = out_dir if out_dir is not None else default_out_dir(loaded)
            if not discard and is_build(target):
                from .sensor_calibration import refuse_discarding

                refuse_discarding(target, [Path.cwd(), Path(target)] + ([spec.parent] if spec is not None else []))
        else:
            loaded, out_dir = _calibration_target(spec, out_dir, scan_path)
            scan = read_scan(scan_path, reference, out_dir, loaded, taxel, weights)
            _check_rest(scan, loaded, out_dir if out_dir is not None and is_build(out_dir) else None, taxel)
        with stages("off" if as_json else way(quiet)) as progress:
            result = run_build(loaded, out_dir, progress, scan)
        summary: Mapping[str, Any] = result.summary()  # JSON values, read by key below
        if as_json:
            click.echo(json.dumps(summary, indent=2, sort_keys=True))
            return
        _print_findings(result.findings)
        fig = summary["figures"]
        click.echo(f"built {loaded.name} into {result.out_dir} ({len(result.artifacts)} files, "
                   f"{result.timings_s['total']:.2f} s)")
        click.echo(f"  rest distance {fig['d_rest_mm']} mm, cover {fig['cover_mm']} mm, "
                   f"silicone {fig['cavity_volume_mL']} mL ({fig['silicone_per_part_g']} g) per part")
        if "taxels" in fig:
            click.echo(f"  array: {fig['taxels']} taxels, pitch {fig['pitch_mm']} mm, {fig['skin']} skin, "
                       f"{fig['polarity']} polarity; chips at {', '.join(fig['addresses'])} (order codes "
                       f"{', '.join(fig['option_codes'])}: the address plan in checklist.md)")
        pred = summary.get("predictions")
        if pred:
            n0, n1 = pred["normal_sensitivity_G_per_N"]
            s0, s1 = pred["shear_sensitivity_G_per_N"]
            click.echo(f"  field at rest {pred['Bz_rest_G']} G, gradient {pred['dBz_dz_rest_G_per_mm']} G/mm; "
                       f"noise {pred['noise_G']} G RMS")
            click.echo(f"  normal: {n0:g}-{n1:g} G/N, resolution {pred['normal_resolution_mN']:g} mN, range "
                       f"{pred['normal_range_text']}")
            click.echo(f"  shear:  {s0:g}-{s1:g} G/N, resolution {pred['shear_resolution_mN']:g} mN, range "
                       f"{pred['shear_range_N']:g} N  (worst case over material and magnet bands; models: "
                       + ", ".join(f"{k} {v}" for k, v in sorted(pred["models"].items())) + ")")
        cal = summary.get("calibration")
        if cal:
            source = "provisional, simulated scan" if cal["source"] == "simulated" else cal["source"]
            click.echo(f"  calibration ({source}): {cal['method']} order {cal['order']}, held-out RMS "
                       f"Fz {cal['rms_holdout_Fz_mN']:g} mN, Fr {cal['rms_holdout_Fr_mN']:g} mN; firmware image: "
                       f"{cal['image'] or 'not built (no avr-gcc)'}")
            if "predicted_error_Fz_mN" in cal:
                click.echo(f"  weight calibration's predicted error over the region (9 in 10): Fz RMS "
                           f"{cal['predicted_error_Fz_mN']:g} mN, shear RMS {cal['predicted_error_shear_mN']:g} mN")
        if scan_path is not None and result.out_dir is not None:  # a command line build is always written out
            readout = os.path.relpath(result.out_dir / "readout")
            click.echo(f"next: pip install {readout if readout.startswith('.') else './' + readout} && "
                       "magfab-readout upload   (the new calibration into the reader and the board's EEPROM)")


def _check_rest(scan, spec, folder: Path | None, taxel: int | None, sensor=None):
    """The new scan's rest field (a scan dict of an array: taxel ``taxel``'s), refused outside the design's
    acceptance band (magfab.sensor_calibration.check_rest); the bands of the record, the build folder or the
    design."""
    from .design import derive
    from .models.rest_guard import rest_field
    from .sensor_calibration import acceptance_bands, check_rest

    new = scan[taxel] if isinstance(scan, dict) else scan
    design = derive(spec)
    bands, where = acceptance_bands(spec, design, folder, sensor)
    return rest_field(new) if bands is None else check_rest(new, design, bands, where, taxel)


def _calibrate_sensor(scan_path: Path, reference: Path | None, spec_path: Path | None, out_dir: Path | None,
                      taxel: int | None, sensor_id: str, root: Path | None, date: str | None, as_json: bool,
                      weights: bool = False) -> None:
    """``magfab calibrate SCAN --sensor ID``: every guard, then the fit appended to the sensor's record; the build
    folder is left as it is (its calibration stays the provisional one, fitted to the simulated scan)."""
    with _handled():
        from .check import preflight
        from .design import derive
        from .formats import bounded
        from .formats import sensor_records as records
        from .models.scan_guards import MERGED, merged_csv
        from .output import is_build
        from .sensor_calibration import (
            calibrate_record,
            check_owner,
            check_spec,
            open_record,
            record_errors,
            spec_of_record,
        )
        from .spec import load_spec

        sensor = open_record(root, sensor_id)
        with record_errors():
            when = None if date is None else records.parse_date(date)
        found = _build_folder(out_dir) if out_dir is not None else _build_folder(scan_path.parent, Path.cwd())
        if spec_path is None and found is None:  # no build at hand: the spec the sensor was made from
            loaded = spec_of_record(sensor) or load_spec(None)
        else:
            loaded, _ = _calibration_target(spec_path, out_dir, scan_path)
        folder = found if found is not None and is_build(found) else None
        design = preflight(derive(loaded))  # the spec as built: a board it does not size is sized as the build sizes it
        loaded = design.spec
        check_spec(sensor, loaded)
        scans = read_scan(scan_path, reference, folder, loaded, taxel, weights, kept_from_record(sensor) if weights
                          else None)
        scan = scans[taxel] if isinstance(scans, dict) else scans
        rest = _check_rest(scan, loaded, folder, taxel, sensor)
        files = {"weights.csv": bounded.read_bytes(scan_path, "weighings CSV")} if weights else {
            "scan.csv": bounded.read_bytes(scan_path, "scan CSV")}
        if reference is not None:
            files["reference.csv"] = bounded.read_bytes(reference, "reference log")
        if MERGED in scan.source:
            files["scan_merged.csv"] = merged_csv(scan)
        check_owner(sensor, files)
        if not weights:  # a weight calibration's forces are the weights', never the sensor's own
            _reject_own_forces(sensor, scan, loaded, taxel)
        for line in _depth_warnings(scan, loaded, folder, design, taxel):
            click.echo(f"warning: {line} [calibration.scan_z_mm]", err=True)
        done = calibrate_record(sensor, loaded, design, scan, rest, files, taxel, when)
        event = done.event
        if as_json:
            click.echo(json.dumps(event, indent=2, sort_keys=True))
            return
        if not done.fit.meets_tolerance:
            click.echo(f"warning: {done.fit.message} [calibration.tolerance_mN]", err=True)
        which = "" if taxel is None else f" (taxel {taxel})"
        click.echo(f"calibrated sensor {sensor_id}{which} from {event['source']}: {event['method']} order "
                   f"{event['order']}, held-out RMS Fz {event['rms_holdout_Fz_mN']:g} mN, Fr "
                   f"{event['rms_holdout_Fr_mN']:g} mN")
        if "predicted_error_Fz_mN" in event:
            click.echo(f"  predicted error over the region (9 in 10): Fz RMS {event['predicted_error_Fz_mN']:g} mN, "
                       f"shear RMS {event['predicted_error_shear_mN']:g} mN")
        click.echo(f"  at rest Bz {event['rest_field_uT'][2]:.0f} uT; sensitivity "
                   f"{event['sensitivity_normal_uT_per_N']} uT/N normal, "
                   f"{event['sensitivity_shear_uT_per_N']} uT/N shear; calibrated to "
                   f"{event['range_normal_N']:g} N normal, {event['range_shear_N']:g} N shear")
        path = sensor.path / "events" / f"{event['number']:06d}-calibration.json"
        click.echo(f"  kept in {os.path.relpath(path)} (no build folder was changed)")
        click.echo(f"next: magfab-readout upload --sensor {sensor_id}   (this calibration into the sensor's board)")


def _reject_own_forces(sensor, scan, spec, taxel: int | None) -> None:
    """Guard B against the sensor's current calibration (the one its board may have run while recording)."""
    from .formats import sensor_records as records
    from .models.calibration import Calibration
    from .models.scan_guards import reject_self_calibrated

    try:
        _, doc = sensor.current_calibration(taxel)
    except records.RecordError:
        return  # none yet
    if spec.array is not None and taxel is not None:
        from .design import derive
        from .models.taxels import array_field, compensated

        scan = compensated(scan, array_field(derive(spec)), taxel)
    reject_self_calibrated(scan, Calibration.from_json(doc), spec.calibration.reference_resolution_mN)


def _depth_warnings(scan, spec, folder: Path | None, design, taxel: int | None) -> list[str]:
    """Guard C's lines, against the build folder's predictions.json when it is a build of this spec (none without:
    the prediction would cost more than the fit)."""
    from .formats import bounded
    from .models.scan_guards import scan_depth_warnings
    from .sensor_calibration import build_of

    if folder is None or not build_of(folder, spec) or not (folder / "predictions.json").is_file():
        return []
    if design.array is not None and taxel is not None:
        from .models.taxels import array_field, compensated

        scan = compensated(scan, array_field(design), taxel)
    predictions = folder / "predictions.json"
    return scan_depth_warnings(scan, bounded.loads_json(bounded.read_bytes(predictions, "JSON"), "JSON", predictions))


def _print_findings(findings: list) -> None:
    for f in findings:
        if f.severity.value != "info":
            where = f" [{f.key}]" if f.key else ""
            click.echo(f"{f.severity.value}: {f.message}{where}", err=True)


@main.command()
@click.argument("spec", required=False, type=click.Path(dir_okay=False, path_type=Path))
@click.option("--json", "as_json", is_flag=True, help="Print the findings as JSON on stdout.")
def check(spec: Path | None, as_json: bool) -> None:
    """Validate SPEC and run the design checks, predictions included; writes nothing."""
    with _handled():
        from .spec import load_spec
        from .verdict import verdict

        loaded = load_spec(spec)
        # the reference chip's site, the build's cost and the board's size refused (or the board sized) as the build
        # does, then its stages' findings, and the refusal the build would stop with
        _design, findings, stop = verdict(loaded)
        if as_json:
            click.echo(json.dumps([f.as_dict() for f in findings], indent=2))
        else:
            for f in findings:
                where = f" [{f.key}]" if f.key else ""
                click.echo(f"{f.severity.value}: {f.message}{where}")
        if stop:
            raise stop
        if not as_json:
            click.echo(f"{loaded.name}: ok")


#: The example specs ``magfab init --example`` copies (magfab/examples/NAME.toml).
EXAMPLES = ("magone", "fingertip_2x2", "strip_1x5")


@main.command()
@click.argument("path", required=False, type=click.Path(dir_okay=False, path_type=Path))
@click.option("--force", is_flag=True, help="Overwrite PATH if it exists.")
@click.option("--targets", "targets", is_flag=True,
              help="Write a commented design-targets file for `magfab design` instead (default PATH: targets.toml).")
@click.option("--example", type=click.Choice(list(EXAMPLES)), default="magone", show_default=True,
              help="Which example spec to copy: the MagOne taxel, a 2x2 fingertip in one skin, a 1x5 strip.")
def init(path: Path | None, force: bool, targets: bool, example: str) -> None:
    """Write a commented copy of an example spec (default: MagOne) to PATH (default: spec.toml)."""
    with _handled():
        from importlib import resources

        from .spec import NAME_PATTERN, default_spec_text, is_valid_name

        path = path or Path("targets.toml" if targets else "spec.toml")
        if not is_valid_name(path.stem):  # the design is named after its file, in a TOML string and a folder
            raise SpecError("name", shown(path.stem), "the file's name (without .toml) names the design and must "
                            "match " + NAME_PATTERN, "choose a file name of letters, digits, '.', '_' and '-'")
        if path.exists() and not force:
            _fail(f"{path} exists; use --force to overwrite it", EXIT_BAD_INPUT)
        if targets:
            text = resources.files("magfab.examples").joinpath("targets.toml").read_text(encoding="utf-8")
            path.write_text(text.replace('name = "fingertip"', f'name = "{path.stem}"', 1), encoding="utf-8")
            click.echo(f"wrote {path}; edit it, then: magfab design {path}")
            return
        text = (default_spec_text() if example == "magone" else
                resources.files("magfab.examples").joinpath(f"{example}.toml").read_text(encoding="utf-8"))
        text = text.replace(f'name = "{example}"', f'name = "{path.stem}"', 1)
        path.write_text(text, encoding="utf-8")
        click.echo(f"wrote {path}; edit it, then: magfab build {path}")


_STUDY_OPTIONS = [
    click.option("--out", "out_dir", type=click.Path(file_okay=False, path_type=Path),
                 help="Study folder (default: ./design/<targets name>); running again resumes its study."),
    click.option("--scheduler", help="Address of an existing Dask scheduler (default: a local cluster)."),
    click.option("--workers", type=click.IntRange(1, 256),
                 help="Local cluster's worker processes (default: the cores)."),
    QUIET,
]


def _say_estimate(cost) -> None:
    """A study's estimated time, before its work (magfab.inverse.budget.study_cost)."""
    click.echo(cost.line())


def _study_options(f):
    for option in reversed(_STUDY_OPTIONS):
        f = option(f)
    return f


@main.command()
@click.argument("targets", type=click.Path(dir_okay=False, path_type=Path))
@_study_options
def design(targets: Path, out_dir: Path | None, scheduler: str | None, workers: int | None, quiet: bool) -> None:
    """Search for designs that meet TARGETS (a TOML file: requirements, variables, objectives) and write the Pareto
    front, its page and plot, and each verified design as a spec `magfab build` accepts. Every requirement is met by
    a margin (the models' own error, or [require] margin); exits 3 when no design meets them so."""
    with _handled(), phases(way(quiet)) as bar:
        check_out(out_dir)
        from .inverse.run import design as run_design

        try:
            r = run_design(targets, out_dir, scheduler, workers, bar, _say_estimate)
        except KeyboardInterrupt:
            _fail("interrupted; the designs evaluated so far are kept in the study folder's study.log: run the same "
                  "command again to resume", EXIT_INTERRUPTED)
        from .inverse.study import tally
        from .inverse.verify import PREFIX

        states = tally(r.trials)
        refused = sum(v.reason.startswith(PREFIX) for v in r.verified)
        click.echo(f"searched {len(r.trials)} designs ({states['ok']} feasible, {states['infeasible']} infeasible, "
                   f"{states['failed']} failed); verified {len(r.verified)} by the full chain"
                   + (f" ({refused} refused by the build: pareto.csv says why)" if refused else "")
                   + f"; front of {len(r.front)} in {r.folder}")
        if r.chosen is None:  # a result, not an input error: the study and its tables are written and resumable
            _fail(f"no design meets the targets with margin; {r.closest()}; see README.md there: relax a "
                  "requirement, widen the variables or raise study.trials and run again", EXIT_UNMET)
        from .inverse.result import margins

        chosen = r.verified[r.chosen]
        for m in margins(r.targets, chosen):
            click.echo(f"  {m.name}: {m.shown} met with margin {100 * m.margin:.1f} % (by {100 * m.slack:+.1f} %)")
        click.echo(f"chosen: {r.names[r.chosen]}; build it: magfab build "
                   f"{r.folder / 'designs' / r.names[r.chosen]}.toml")


@main.command()
@click.argument("targets", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--grid", "levels", type=click.IntRange(2, 50), help="A full grid, LEVELS even steps over each range.")
@click.option("--lhs", "samples", type=click.IntRange(1, 1_000_000), help="A Latin hypercube of SAMPLES designs.")
@click.option("--models", "fidelity", default="surrogate", show_default=True,
              help="'surrogate' (the cheap models: the elastomer surrogate) or 'fe' (the full chain).")
@_study_options
def sweep(targets: Path, levels: int | None, samples: int | None, fidelity: str, out_dir: Path | None,
          scheduler: str | None, workers: int | None, quiet: bool) -> None:
    """Evaluate every design of a grid or Latin hypercube of TARGETS' variables; write sweep.csv (and .parquet)."""
    with _handled(), phases(way(quiet)) as bar:
        check_out(out_dir)
        from .inverse.run import sweep as run_sweep

        if (levels is None) == (samples is None):
            _fail("give one of --grid LEVELS or --lhs SAMPLES", EXIT_BAD_INPUT)
        folder, recs = run_sweep(targets, out_dir, scheduler, workers, levels, samples, fidelity, bar, _say_estimate)
        from .inverse.study import tally

        states = tally(recs)
        click.echo(f"evaluated {len(recs)} designs ({states['ok']} feasible, {states['infeasible']} infeasible, "
                   f"{states['failed']} failed): {folder / 'sweep.csv'}")


@main.command()
def schema() -> None:
    """Print the spec's JSON Schema (the shipped magfab/spec.schema.json)."""
    from .spec import spec_schema

    click.echo(json.dumps(spec_schema(), indent=2, sort_keys=True))


from .sensor_cli import register as _register_sensor  # noqa: E402  (the commands beside their engine, magfab.sensors)
from .weigh_cli import register as _register_weigh  # noqa: E402  (as the sensor commands)

_register_sensor(main, _handled)
_register_weigh(main, _handled, _calibration_target)

if __name__ == "__main__":  # pragma: no cover
    main()
