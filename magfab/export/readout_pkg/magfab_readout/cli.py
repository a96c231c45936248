"""``magfab-readout``: stream calibrated forces, record scans, ask the board what it runs, write a new
calibration into its EEPROM (``upload``), and run the acceptance test (``check``) against the bands magfab
predicted for this build (acceptance.json).

Exit status: 0 done (``check``: passed), 1 a device or calibration problem (one line on stderr) or a failed
check, 2 a usage error, 130 Ctrl-C.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pkgutil
import signal
import sys
import time
from typing import List, Optional, Tuple

from . import __version__, _build, acceptance_json, eeprom
from .calibration import Calibration, CalibrationError
from .device import Device, DeviceError, NoData, calibration_record, cross_check
from .simulate import RestTip, SimulatedDevice
from .taxels import ArrayCalibration

G0 = 9.80665  # m/s^2

#: ``record``'s columns (docs/bundle.md section 1): host_time_s ties the recording to a reference sensor's log.
CSV_COLUMNS = ("time_s", "host_time_s", "Bx_uT", "By_uT", "Bz_uT", "temperature_C", "Fx_sensor_N", "Fy_sensor_N",
               "Fz_sensor_N", "status", "seq")


def _parser() -> argparse.ArgumentParser:
    common = argparse.ArgumentParser(add_help=False)
    link = common.add_argument_group("connection")
    link.add_argument("--port", help="serial port (default: $MAGFAB_READOUT_PORT when set, else the one USB serial "
                      "port present)")
    link.add_argument("--baud", type=int, default=_build.BAUD, help="baud rate (default: %(default)s, the firmware's)")
    link.add_argument("--timeout", type=float, default=3.0, metavar="S",
                      help="seconds to wait for data before giving up (default: %(default)s)")
    sim = common.add_argument_group("simulated device")
    sim.add_argument("--simulate", action="store_true", help="no hardware: a simulated board sends the firmware's frames")
    sim.add_argument("--simulate-seed", type=int, default=0, metavar="N", help="noise seed of the simulated board")
    sim.add_argument("--simulate-corrupt", type=float, default=0.0, metavar="FRACTION",
                     help="fraction of simulated frames with a flipped bit (to see the CRC checks at work)")

    parser = argparse.ArgumentParser(
        prog="magfab-readout",
        description="Host readout for the magfab tactile sensor built from spec {}.".format(json.dumps(_build.SPEC_NAME)),
    )
    parser.add_argument("--version", action="version",
                        version="magfab-readout {} (calibration {})".format(__version__, _build.CALIBRATION_SHA256[:16]))
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    stream = commands.add_parser("stream", parents=[common], help="print calibrated forces as they arrive",
                                 description="Print Fx Fy Fz (N), the field B (uT), the temperature and the status "
                                 "flags (o outside the calibrated region, E chip error, S full scale, R recovered), "
                                 "and on an error row which fault struck where (e.g. nack_at_read).")
    stream.add_argument("--text", action="store_true", help="ask the firmware for text lines instead of binary frames")
    stream.add_argument("--zero", type=int, default=0, metavar="N",
                        help="average N samples at rest first and subtract that force from the rest (tare)")
    stream.add_argument("--raw", action="store_true", help="also print the raw counts and raw temperature (binary only)")
    stream.add_argument("--check", action="store_true",
                        help="also recompute each force from the field on the host and print the difference")
    stream.add_argument("--count", type=int, metavar="N", help="stop after N samples (an array: N cycles)")
    stream.add_argument("--seconds", type=float, metavar="S", help="stop after S seconds of device time")

    record = commands.add_parser("record", parents=[common], help="record the field during a scan, until Ctrl-C",
                                 description="Write the device's and the host's time, the field, the temperature and "
                                 "this sensor's own calibrated force (Fx_sensor_N, Fy_sensor_N, Fz_sensor_N) as CSV "
                                 "with a # comment header (docs/bundle.md section 1), until Ctrl-C or --seconds. "
                                 "Samples with a chip error are left out. To calibrate, log a reference force "
                                 "sensor on this computer's clock during the scan and pass its log to magfab "
                                 "calibrate --reference.")
    record.add_argument("out", metavar="OUT.csv", help="file to write")
    record.add_argument("--seconds", type=float, metavar="S",
                        help="stop after S seconds of device time (default: record until Ctrl-C)")
    record.add_argument("--text", action="store_true", help="ask the firmware for text lines instead of binary frames")

    commands.add_parser("info", parents=[common], help="ask the board which spec and calibration it runs",
                        description="Send 'i', print the board's answer and check its calibration against this package's.")

    upload = commands.add_parser(
        "upload", parents=[common], help="write a calibration into the board's EEPROM (no compiler, no reflash)",
        description="Check a calibration.json, write it into the board's EEPROM over serial (docs/bundle.md section "
        "4), read it back, and check that the board now reports its hash. Without a file: this package's own "
        "calibration (what the build's .eep holds).")
    upload.add_argument("calibration", nargs="?", metavar="CALIBRATION.json",
                        help="the calibration to write (default: the one embedded in this package)")

    check = commands.add_parser(
        "check", parents=[common], help="acceptance test: the field at rest and under a known weight vs the prediction",
        description="The acceptance test at the end of the fabrication checklist. With nothing touching the tip it "
        "averages the field and compares it with the band magfab predicted from the magnet, material and assembly "
        "tolerances (its sign tells an upside-down magnet); then it asks for a known weight on the tip and compares "
        "the rise of Bz with the predicted band. Prints PASS or FAIL per step with the measured and predicted values; "
        "exit status 0 when every step passes, 1 otherwise.")
    check.add_argument("--weight-g", type=float, metavar="W",
                       help="the known weight in grams (default: the one the build chose, in acceptance.json)")
    check.add_argument("--samples", type=int, default=500, metavar="N",
                       help="samples averaged per reading (default: %(default)s)")
    check.add_argument("--settle", type=float, default=1.0, metavar="S",
                       help="seconds of device time to wait after the weight is on before reading (default: %(default)s)")
    check.add_argument("--no-weight", action="store_true", help="skip the known-weight step")
    check.add_argument("--yes", "-y", action="store_true",
                       help="do not wait for Enter (non-interactive): the weight is on the tip when the check asks")
    sensor = check.add_argument_group("simulated sensor (with --simulate)")
    sensor.add_argument("--simulate-grade", metavar="GRADE",
                        help="the simulated magnet's grade (a name from acceptance.json: N35, N42, N45, N52) or "
                        "its remanence in tesla, instead of the spec's")
    sensor.add_argument("--simulate-flipped", action="store_true", help="the simulated magnet is upside down")
    return parser


def _device(args: argparse.Namespace, text: Optional[bool], pattern=None) -> Device:
    calibration = Calibration.embedded()
    transport = None
    if args.simulate:
        transport = SimulatedDevice(calibration, seed=args.simulate_seed, corrupt_fraction=args.simulate_corrupt,
                                    pattern=pattern)
    elif args.simulate_corrupt or args.simulate_seed:
        raise DeviceError("--simulate-corrupt and --simulate-seed need --simulate")
    return Device(args.port, args.baud, text=text, timeout_s=args.timeout, calibration=calibration, transport=transport)


def _number(x: Optional[float], width: int, decimals: int, sign: bool = True) -> str:
    if x is None or math.isnan(x):
        return "nan".rjust(width)
    return "{:{}{}.{}f}".format(x, "+" if sign else "", width, decimals)


def _stream(args: argparse.Namespace, out) -> int:
    if args.zero < 0:
        raise DeviceError("--zero needs a positive number of samples")
    if args.raw and args.text:
        raise DeviceError("--raw needs binary frames: text lines carry microtesla, not raw counts")
    with _device(args, text=bool(args.text)) as device:
        out.write("# magfab-readout {}: spec {}, calibration {}, {}\n".format(
            __version__, json.dumps(_build.SPEC_NAME), device.calibration.short_hash, device.port))
        if args.zero:
            offset = device.zero(args.zero)
            out.write("# zero: offset Fx {:+.4f} N, Fy {:+.4f} N, Fz {:+.4f} N from {} samples\n".format(
                *offset, args.zero))
        columns = ["t_s", "seq", "Fx_N", "Fy_N", "Fz_N", "Bx_uT", "By_uT", "Bz_uT", "T_C", "flags", "fault"]
        if args.raw:
            columns += ["Bx_lsb", "By_lsb", "Bz_lsb", "T_raw"]
        if args.check:
            columns.append("dF_N")
        out.write("# " + " ".join(columns) + "\n")
        worst = 0.0
        n = 0
        for sample in device.samples(count=args.count, seconds=args.seconds):
            row = [_number(sample.time_s, 10, 4, False), "{:3d}".format(sample.seq)]
            row += [_number(f, 8, 4) for f in sample.force_N]
            row += [_number(b, 9, 2) for b in sample.B_uT]
            row += [_number(sample.temperature_C, 6, 2, False), sample.flags,
                    (sample.fault_name or "-").replace(" ", "_")]
            if args.raw:
                counts = sample.counts or (0, 0, 0)
                row += ["{:6d}".format(c) for c in counts] + ["{:5d}".format(sample.temperature_raw or 0)]
            if args.check:
                diff = cross_check(sample, device.calibration)
                worst = max(worst, diff) if not math.isnan(diff) else worst
                row.append("{:.2e}".format(diff) if not math.isnan(diff) else "nan")
            out.write("  ".join(row) + "\n")
            n += 1
        _summary(device, n, worst if args.check else None)
    return 0


def _summary(device: Device, n: int, worst: Optional[float]) -> None:
    s = device.stats
    text = ("{} samples; {} lost (sequence gaps), {} CRC errors, {} bad lines, {} refused values, {} bytes "
            "skipped").format(n, s.lost, s.crc_errors, s.bad_lines, s.refused, s.skipped_bytes)
    if worst is not None:
        text += "; host vs firmware force: max |dF| = {:.3g} N".format(worst)
    print("magfab-readout: " + text, file=sys.stderr)


def _csv(x: Optional[float], decimals: int) -> str:
    return "{:.{}f}".format(x, decimals)


class _Interrupt:
    """SIGINT while recording: KeyboardInterrupt while waiting for the device, held back while a row is written."""

    requested = writing = False
    _previous = None

    def __call__(self, signum, frame) -> None:
        self.requested = True
        if not self.writing:
            raise KeyboardInterrupt

    def __enter__(self) -> "_Interrupt":
        try:
            self._previous = signal.signal(signal.SIGINT, self)
        except ValueError:  # not the main thread: Ctrl-C stays a KeyboardInterrupt, ended here
            self._previous = None
        return self

    def __exit__(self, kind, value, traceback) -> bool:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
        return kind is KeyboardInterrupt


def _record_header(f, device, info, columns: List[str], extra: Tuple[str, ...] = ()) -> None:
    f.write("# magfab-readout {} record\n".format(__version__))
    f.write("# spec: {}\n".format(json.dumps(_build.SPEC_NAME)))
    f.write("# calibration_sha256: {}\n".format(device.calibration.sha256))
    f.write("# device: {}\n".format(json.dumps(info.line)))
    f.write("# chip: gain_sel={} resolution={} osr={} dig_filt={} lsb_xy_uT={!r} lsb_z_uT={!r}\n".format(
        _build.GAIN_SEL, _build.RESOLUTION, _build.OSR, _build.DIG_FILT, _build.LSB_XY_UT, _build.LSB_Z_UT))
    f.write("# time_s: the device's clock; host_time_s: this computer's clock (Unix time, s) when the sample was read\n")
    f.write("# Fx_sensor_N, Fy_sensor_N, Fz_sensor_N: this sensor's own calibrated force, not a reference; to "
            "calibrate, log a reference force sensor during the scan with time_s on this computer's clock (Unix "
            "time, s) and Fx_N, Fy_N, Fz_N, and pass it: magfab calibrate THIS.csv --reference REFERENCE.csv\n")
    f.write("".join(line + "\n" for line in extra) + ",".join(columns) + "\n")


def _record(args: argparse.Namespace) -> int:
    if args.seconds is not None and not args.seconds > 0:
        raise DeviceError("--seconds must be positive")
    with _device(args, text=bool(args.text)) as device:
        info = device.info()
        for warning in device.check_info(info):
            print("magfab-readout: warning: " + warning, file=sys.stderr)
        temperature = _build.TEMPERATURE_ENABLED
        columns = [c for c in CSV_COLUMNS if temperature or c != "temperature_C"]
        written = skipped = 0
        stop = _Interrupt()
        with open(args.out, "w", encoding="utf-8", newline="") as f:
            _record_header(f, device, info, columns)
            with stop:
                for sample in device.samples(seconds=args.seconds):
                    stop.writing = True
                    host = time.time()
                    values = list(sample.B_uT) + list(sample.force_N)
                    if sample.chip_error or not all(math.isfinite(v) for v in values) or (
                            temperature and sample.temperature_C is None):
                        skipped += 1
                    else:
                        row = [_csv(sample.time_s, 6), _csv(host, 6)] + [_csv(b, 4) for b in sample.B_uT]
                        if temperature:
                            row.append(_csv(sample.temperature_C, 3))
                        row += [_csv(x, 6) for x in sample.force_N] + [str(sample.status), str(sample.seq)]
                        f.write(",".join(row) + "\n")
                        written += 1
                    stop.writing = False
                    if stop.requested:
                        break
        print("magfab-readout: wrote {} rows to {}{} ({} chip-error samples left out)".format(
            written, args.out, " (Ctrl-C)" if stop.requested else "", skipped), file=sys.stderr)
        _summary(device, written + skipped, None)
    return 0


def _info(args: argparse.Namespace, out) -> int:
    with _device(args, text=None) as device:
        info = device.info()
        out.write("device:  {}\n".format(info.line))
        out.write("  spec {}, calibration {}, gain_sel {}, resolution {}, osr {}, dig_filt {}\n".format(
            json.dumps(info.spec_name), info.calibration_hash, *info.settings))
        out.write("package: magfab-readout {}, spec {}, calibration {}\n".format(
            __version__, json.dumps(_build.SPEC_NAME), device.calibration.short_hash))
        warnings = device.check_info(info)
        for warning in warnings:
            out.write("warning: {}\n".format(warning))
        out.write("calibration: match\n")
    return 0


def at_fallback_baud(args: argparse.Namespace, out, open_device, action):
    """``action(device)`` on the board, and when nothing answers again at the fallback baud, which a board without a
    valid record speaks (docs/bundle.md section 4)."""
    try:
        with open_device(args) as device:
            return action(device)
    except NoData:
        if args.simulate or args.baud == eeprom.FALLBACK_BAUD:
            raise
        out.write("no answer at {} baud; trying {} baud (a board without a calibration)\n".format(
            args.baud, eeprom.FALLBACK_BAUD))
        with open_device(argparse.Namespace(**{**vars(args), "baud": eeprom.FALLBACK_BAUD})) as device:
            return action(device)


def _upload(args: argparse.Namespace, out) -> int:
    if args.calibration:
        try:
            with open(args.calibration, encoding="utf-8") as handle:
                data = json.load(handle)
        except ValueError as exc:
            raise CalibrationError("", args.calibration, "is not valid JSON ({})".format(exc)) from None
    else:
        data = json.loads(pkgutil.get_data("magfab_readout", "calibration.json").decode("utf-8"))  # type: ignore[union-attr]
    record = calibration_record(data)
    info = at_fallback_baud(args, out, lambda a: _device(a, text=None), lambda device: device.upload(data))
    out.write("uploaded {} bytes, read back equal; the board runs calibration {} (spec {})\n".format(
        len(record), info.calibration_hash, json.dumps(info.spec_name)))
    return 0


# --- the acceptance test -------------------------------------------------------------------------------------


class UsageError(ValueError):
    """A bad option value for ``check`` (exit status 2)."""


def load_acceptance() -> Optional[dict]:
    """The package's acceptance.json, checked by ``acceptance_json`` (the validator magfab ran on it before
    shipping it), or None when the package was built without one."""
    try:
        raw = pkgutil.get_data("magfab_readout", "acceptance.json")
    except OSError:
        return None
    if raw is None:
        return None
    try:
        return acceptance_json.loads(raw)
    except acceptance_json.AcceptanceError as exc:
        raise DeviceError("the package's {}: reinstall the readout package from the same magfab build".format(exc)) from None


class Bands:
    """The predicted bands of a validated acceptance.json (:func:`load_acceptance`)."""

    def __init__(self, data: dict) -> None:
        try:
            rest = data["rest"]
            self.rest = tuple(float(rest["Bz_uT"][k]) for k in ("min", "nominal", "max"))
            self.bxy_max = float(rest["Bxy_max_uT"])
            self.earth = float(rest["earth_field_uT"])
            self.inside = [str(g) for g in rest.get("grades_inside_band", [])]
            weight = data["weight"]
            self.weight_g = float(weight["weight_g"])
            self.max_weight_g = float(weight["max_weight_g"])
            table = weight["table"]
            self.force = [float(x) for x in table["force_N"]]
            self.delta = {k: [float(x) for x in table["delta_Bz_{}_uT".format(k)]] for k in ("min", "nominal", "max")}
            self.noise_z = float(data["measurement"]["noise_z_uT"])
            self.noise_xy = float(data["measurement"]["noise_xy_uT"])
            self.sigmas = float(data["measurement"]["allowance_sigmas"])
            magnet = data["magnet"]
            self.grade = str(magnet["grade"])
            self.remanence = tuple(float(magnet["remanence_T"][k]) for k in ("low", "nominal", "high"))
            self.grades = {str(k): float(v["remanence_T"]) for k, v in data.get("grades", {}).items()}
        except (KeyError, TypeError, ValueError, AttributeError) as exc:  # the optional grade tables
            raise DeviceError("the package's acceptance.json garbles {}: reinstall the readout package from "
                              "the magfab build".format(exc)) from None

    def rise(self, grams: float) -> Tuple[float, float, float]:
        """(min, nominal, max) predicted rise of Bz in uT under ``grams`` on the tip (linear in the table)."""
        f = grams * G0 / 1000.0
        xs = self.force
        if not (xs[0] <= f <= xs[-1] + 1e-9):
            raise UsageError("--weight-g {:g}: the prediction covers weights up to {:.0f} g".format(grams, self.max_weight_g))
        k = max(1, min(len(xs) - 1, next((i for i, x in enumerate(xs) if x >= f), len(xs) - 1)))
        t = (f - xs[k - 1]) / (xs[k] - xs[k - 1])
        return tuple(self.delta[c][k - 1] + t * (self.delta[c][k] - self.delta[c][k - 1])  # type: ignore[return-value]
                     for c in ("min", "nominal", "max"))

    def scale_of(self, grade: str) -> float:
        """Field scale of a magnet of ``grade`` (a grade name or a remanence in tesla) relative to the spec's."""
        names = {k.lower(): v for k, v in self.grades.items()}
        if grade.lower() in names:
            return names[grade.lower()] / self.remanence[1]
        try:
            value = float(grade)
        except ValueError:
            value = math.nan
        if not (0.0 < value < 2.0):
            raise UsageError("--simulate-grade {!r}: give a grade ({}) or a remanence in tesla (0 to 2)".format(
                grade, ", ".join(sorted(self.grades)) or "none known"))
        return value / self.remanence[1]


def _mean_field(device: Device, count: int) -> Tuple[Tuple[float, float, float], int]:
    """Mean (Bx, By, Bz) in uT of ``count`` good samples, and how many of them had an axis at full scale."""
    total = [0.0, 0.0, 0.0]
    used = skipped = full = 0
    for sample in device.samples():
        if sample.chip_error or not all(math.isfinite(b) for b in sample.B_uT):
            skipped += 1
            if skipped > 10 * count + 100:
                raise DeviceError("{} samples from {} were chip errors: check the sensor board's wiring and "
                                  "supply".format(skipped, device.port))
            continue
        full += bool(sample.full_scale)
        total = [t + b for t, b in zip(total, sample.B_uT)]
        used += 1
        if used == count:
            break
    return (total[0] / used, total[1] / used, total[2] / used), full


def _ask(prompt: str, yes: bool) -> None:
    sys.stderr.write(prompt + (" (--yes: not waiting)\n" if yes else ", then press Enter: "))
    sys.stderr.flush()
    if not yes and not sys.stdin.readline():
        raise DeviceError("no answer on stdin (end of input): run the check at a terminal, or pass --yes")


class _Steps:
    """The acceptance test's steps as they are reported: numbered PASS/FAIL lines, and the verdict."""

    def __init__(self, out) -> None:
        self.out, self.results = out, []  # (name, passed)

    def report(self, name: str, passed: bool, text: str) -> None:
        self.results.append((name, passed))
        self.out.write("step {}  {:<26} {}  {}\n".format(len(self.results), name, "PASS" if passed else "FAIL", text))
        self.out.flush()

    def verdict(self) -> int:
        failed = [k + 1 for k, (_, passed) in enumerate(self.results) if not passed]
        if failed:
            self.out.write("verdict: FAIL (step{} {} of {})\n".format("s" if len(failed) > 1 else "",
                                                                      ", ".join(map(str, failed)), len(self.results)))
            return 1
        self.out.write("verdict: PASS (all {} steps)\n".format(len(self.results)))
        return 0


def _check_options(args: argparse.Namespace, bands: "Bands", data: dict):
    """The weight, its predicted rise and the simulated tip the options ask for; UsageError when they clash."""
    if args.samples < 1:
        raise UsageError("--samples must be at least 1")
    if not args.settle >= 0:
        raise UsageError("--settle must be zero or positive")
    weight = bands.weight_g if args.weight_g is None else float(args.weight_g)
    rise = None
    if not args.no_weight:
        if not (math.isfinite(weight) and weight > 0):
            raise UsageError("--weight-g must be a positive number of grams")
        rise = bands.rise(weight)
    pattern = None
    if args.simulate:
        scale = bands.scale_of(args.simulate_grade) if args.simulate_grade else 1.0
        pattern = RestTip.from_acceptance(data, scale=scale, flipped=args.simulate_flipped)
    elif args.simulate_grade or args.simulate_flipped:
        raise UsageError("--simulate-grade and --simulate-flipped need --simulate")
    return weight, rise, pattern


def _check(args: argparse.Namespace, out) -> int:
    data = load_acceptance()
    if data is None:
        raise DeviceError("this readout package carries no acceptance.json (it was built without the acceptance "
                          "bands): rebuild with magfab build and reinstall ./readout")
    bands = Bands(data)
    weight, rise, pattern = _check_options(args, bands, data)
    n = args.samples
    allow = bands.sigmas * bands.noise_z / math.sqrt(n) + _build.LSB_Z_UT / 2.0
    steps = _Steps(out)
    with _device(args, text=None, pattern=pattern) as device:
        _check_header(out, device, bands, weight, rise, n)
        (bx, by, bz), full = _mean_field(device, n)
        _check_polarity(steps, bz, allow + bands.earth)
        _check_rest(steps, out, bands, bz, full, allow)
        _check_lateral(steps, bands, bx, by, bands.sigmas * bands.noise_xy / math.sqrt(n) + _build.LSB_XY_UT / 2.0)
        if not args.no_weight:
            _check_weight(steps, out, args, device, bands, weight, rise, bz)
    return steps.verdict()


def _check_header(out, device, bands: "Bands", weight: float, rise, n: int) -> None:
    lo, nom, hi = bands.rest
    out.write("# magfab-readout {} check: spec {}, calibration {}, {}\n".format(
        __version__, json.dumps(_build.SPEC_NAME), device.calibration.short_hash, device.port))
    out.write("# predicted (worst case over the magnet, material and assembly tolerances; magfab acceptance.json):\n"
              "#   Bz at rest {:.0f} .. {:.0f} uT (nominal {:.0f}), positive with the north pole away from the "
              "chip; |Bxy| at rest <= {:.0f} uT\n".format(lo, hi, nom, bands.bxy_max))
    if rise is not None:
        out.write("#   a {:g} g weight on the tip raises Bz by {:.0f} .. {:.0f} uT (nominal {:.0f})\n".format(
            weight, rise[0], rise[2], rise[1]))
    out.write("# reading {} samples with nothing touching the tip\n".format(n))
    out.flush()


def _check_polarity(steps: _Steps, bz: float, floor: float) -> None:
    """Step 1, the sign: an upside-down magnet reads the same field negated."""
    if bz > floor:
        steps.report("polarity (sign of Bz)", True, "measured {:+.0f} uT: positive, the north pole faces away from the "
                     "chip as designed".format(bz))
    elif bz < -floor:
        steps.report("polarity (sign of Bz)", False, "measured {:+.0f} uT: negative, the magnet is upside down (its "
                     "north pole faces the chip); push it out of the pocket and turn it over".format(bz))
    else:
        steps.report("polarity (sign of Bz)", False, "measured {:+.0f} uT: no field from the magnet (|Bz| under {:.0f} "
                     "uT); is there a magnet in the fingertip, and is the fingertip on the chip?".format(bz, floor))


def _check_rest(steps: _Steps, out, bands: "Bands", bz: float, full: int, allow: float) -> None:
    """Step 2, the field at rest against the predicted band, and the remanence it implies."""
    lo, nom, hi = bands.rest
    text = "measured {:+.0f} uT, predicted {:.0f} .. {:.0f} uT (nominal {:.0f})".format(bz, lo, hi, nom)
    if full:
        steps.report("Bz at rest", False, text + ": {} samples had an axis at the chip's full scale (magnet far too "
                     "close or too strong)".format(full))
    elif lo - allow <= bz <= hi + allow:
        steps.report("Bz at rest", True, text)
    elif bz < 0 and lo - allow <= -bz <= hi + allow:
        steps.report("Bz at rest", False, text + ": the magnet is upside down (|Bz| is inside the band)")
    elif bz > hi + allow:
        steps.report("Bz at rest", False, text + ": stronger than predicted - a stronger grade than {}, a bigger "
                     "magnet, or the magnet closer to the chip (not pushed home, thin pad or glue)".format(bands.grade))
    else:
        steps.report("Bz at rest", False, text + ": weaker than predicted - a weaker or partly demagnetised magnet "
                     "(heated above 80 C?), a smaller magnet, or the magnet further from the chip (thick glue, pad "
                     "not seated)")
    if abs(bz) > allow + bands.earth:
        implied = abs(bz) / nom * bands.remanence[1]
        note = "#   at the nominal stack-up this field means a remanence of {:.2f} T ({} is {:.2f} .. {:.2f} T)".format(
            implied, bands.grade, bands.remanence[0], bands.remanence[2])
        if len(bands.inside) > 1 and steps.results[-1][1]:
            note += "; the band also holds the nominal field of grades {}: it cannot tell those apart".format(
                ", ".join(g for g in bands.inside if g != bands.grade))
        out.write(note + "\n")


def _check_lateral(steps: _Steps, bands: "Bands", bx: float, by: float, allow_xy: float) -> None:
    """Step 3, the lateral field at rest: the magnet on the chip's axis and level."""
    bxy = math.hypot(bx, by)
    text = "measured {:.0f} uT, predicted at most {:.0f} uT".format(bxy, bands.bxy_max)
    if bxy <= bands.bxy_max + allow_xy:
        steps.report("|Bxy| at rest", True, text)
    else:
        steps.report("|Bxy| at rest", False, text + ": the magnet is off the chip's axis or tilted (check the pad on "
                     "its pins and the fingertip in the lip), or a magnetic object is near")


def _check_weight(steps: _Steps, out, args: argparse.Namespace, device, bands: "Bands", weight: float, rise,
                  bz: float) -> None:
    """Step 4, the known weight: the rise of Bz against the band the material and magnet predict."""
    n = args.samples
    _ask("place the {:g} g weight on the tip, centred, with nothing else touching".format(weight), args.yes)
    if args.simulate:
        device.transport.place_weight(weight)
    device.drain()
    start = None
    for sample in device.samples():
        start = sample.time_s if start is None else start
        if sample.time_s - start >= args.settle:
            break
    out.write("# reading {} samples with {:g} g on the tip\n".format(n, weight))
    (_, _, bz_w), full_w = _mean_field(device, n)
    delta = bz_w - bz
    allow_d = bands.sigmas * bands.noise_z * math.sqrt(2.0 / n) + _build.LSB_Z_UT
    name = "rise of Bz under {:g} g".format(weight)
    text = "measured {:+.0f} uT, predicted {:.0f} .. {:.0f} uT (nominal {:.0f})".format(delta, rise[0], rise[2], rise[1])
    if full_w:
        steps.report(name, False, text + ": {} samples had an axis at the chip's full scale".format(full_w))
    elif rise[0] - allow_d <= delta <= rise[2] + allow_d:
        steps.report(name, True, text)
    elif delta < -allow_d:
        steps.report(name, False, text + ": Bz fell under the weight - the magnet is upside down" if bz < 0 else
                     text + ": Bz fell under the weight - is the weight on the tip, and the fingertip glued down?")
    elif delta < rise[0] - allow_d:
        steps.report(name, False, text + ": a smaller rise than predicted - a stiffer silicone than the recipe's "
                     "band (mix ratio, cure), the weight off-centre or resting on something else, or the magnet "
                     "further from the chip")
    else:
        steps.report(name, False, text + ": a larger rise than predicted - a softer silicone (under-cured or "
                     "off-ratio) or the magnet closer to the chip")
    if not args.yes:
        sys.stderr.write("take the weight off the tip\n")


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of the ``magfab-readout`` command."""
    args = _parser().parse_args(argv)
    try:
        if (array := ArrayCalibration.embedded()) is not None:  # an array build's package: every taxel
            from . import array_cli
            return array_cli.run(args, array, sys.stdout)
        if args.command == "stream":
            return _stream(args, sys.stdout)
        if args.command == "record":
            return _record(args)
        if args.command == "check":
            return _check(args, sys.stdout)
        if args.command == "upload":
            return _upload(args, sys.stdout)
        return _info(args, sys.stdout)
    except BrokenPipeError:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # stdout's reader went away (| head): stop quietly
        return 0
    except UsageError as exc:
        print("magfab-readout: error: {}".format(exc), file=sys.stderr)
        return 2
    except (DeviceError, CalibrationError, OSError) as exc:
        print("magfab-readout: error: {}".format(exc), file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
