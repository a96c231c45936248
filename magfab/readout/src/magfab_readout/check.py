"""``magfab-readout check``: the acceptance test at the end of the fabrication checklist, against the bands magfab
predicted for this build (the package's acceptance.json). Each step prints one PASS or FAIL line with the measured
and the predicted values; :func:`run` returns 0 when every step passes, 1 otherwise."""

from __future__ import annotations

import argparse
import json
import math
import pkgutil
import sys
from typing import Any, Dict, List, Optional, Tuple

from . import _build, acceptance_json, board_sensor
from .cli_shared import FAILED, UsageError
from .device import Device, DeviceError
from .rest import slope_mN_per_uT
from .simulate import RestTip

G0 = RestTip.G0  # m/s^2


def add_parser(commands, common: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The ``check`` command and its options, on the command line's subcommands."""
    check = commands.add_parser(
        "check", parents=[common], help="acceptance test: the field at rest and under a known weight vs the prediction",
        description="The acceptance test at the end of the fabrication checklist. With nothing touching the tip it "
        "averages the field and compares it with the band magfab predicted from the magnet, material and assembly "
        "tolerances (its sign tells an upside-down magnet); then it asks for a known weight on the tip and compares "
        "the rise of Bz with the predicted band. --rotation adds turning the sensor over, --warmup warming it. "
        "Prints PASS or FAIL per step with the measured and predicted values; exit status 0 when every step passes, "
        f"{FAILED} when one fails.")
    check.add_argument("--weight-g", type=float, metavar="W",
                       help="the known weight in grams (default: the one the build chose, in acceptance.json)")
    check.add_argument("--samples", type=int, default=500, metavar="N",
                       help="samples averaged per reading (default: %(default)s)")
    check.add_argument("--settle", type=float, default=1.0, metavar="S",
                       help="seconds of device time to wait after the weight is on before reading "
                            "(default: %(default)s)")
    check.add_argument("--no-weight", action="store_true", help="skip the known-weight step")
    check.add_argument("--rotation", action="store_true",
                       help="add the turn-over step: the whole sensor turned upside down, nothing touching the tip; "
                       "the field may change by the Earth's field and the fingertip's own weight, no more")
    check.add_argument("--warmup", action="store_true",
                       help="add the warm-up step: the chip warmed by a few C, nothing touching the tip; the rest "
                       "force may move by the predicted compensated drift per C, no more")
    check.add_argument("--warmup-seconds", type=float, default=600.0, metavar="S",
                       help="longest wait for the chip to warm, seconds of device time (default: %(default)s)")
    check.add_argument("--yes", "-y", action="store_true",
                       help="do not wait for Enter (non-interactive): the weight is on the tip when the check asks")
    sensor = check.add_argument_group("simulated sensor (with --simulate)")
    sensor.add_argument("--simulate-grade", metavar="GRADE",
                        help="the simulated magnet's grade (a name from acceptance.json: N35, N42, N45, N52) or "
                        "its remanence in tesla, instead of the spec's")
    sensor.add_argument("--simulate-flipped", action="store_true", help="the simulated magnet is upside down")
    sensor.add_argument("--simulate-loose", type=float, default=0.0, metavar="MM",
                        help="the simulated magnet is loose: it slides MM mm away from the chip when the sensor is "
                        "turned over")
    return check


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
        raise DeviceError(f"the package's {exc}: reinstall the readout package from the same magfab build") from None


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
            self.delta = {k: [float(x) for x in table[f"delta_Bz_{k}_uT"]] for k in ("min", "nominal", "max")}
            self.noise_z = float(data["measurement"]["noise_z_uT"])
            self.noise_xy = float(data["measurement"]["noise_xy_uT"])
            self.sigmas = float(data["measurement"]["allowance_sigmas"])
            magnet = data["magnet"]
            self.grade = str(magnet["grade"])
            self.remanence = tuple(float(magnet["remanence_T"][k]) for k in ("low", "nominal", "high"))
            self.grades = {str(k): float(v["remanence_T"]) for k, v in data.get("grades", {}).items()}
            self.rotation = data.get("rotation")  # validated whole when present (acceptance_json.SECTIONS)
            self.warmup = data.get("warmup")
        except (KeyError, TypeError, ValueError, AttributeError) as exc:  # the optional grade tables
            raise DeviceError(f"the package's acceptance.json garbles {exc}: reinstall the readout package from "
                              "the magfab build") from None

    def rise(self, grams: float) -> Tuple[float, float, float]:
        """(min, nominal, max) predicted rise of Bz in uT under ``grams`` on the tip (linear in the table)."""
        f = grams * G0 / 1000.0
        xs = self.force
        if not (xs[0] <= f <= xs[-1] + 1e-9):
            raise UsageError(f"--weight-g {grams:g}: the prediction covers weights up to {self.max_weight_g:.0f} g")
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


class _Reading:
    """Means of ``count`` good samples: ``B`` (Bx, By, Bz) uT, ``force`` (Fx, Fy, Fz) N, ``temperature`` C (None
    without), ``full`` how many had an axis at full scale, and ``time_s`` the device time of the last."""

    def __init__(self, B, force, temperature, full: int, time_s: float) -> None:
        self.B, self.force, self.temperature, self.full, self.time_s = B, force, temperature, full, time_s


def _mean_reading(device: Device, count: int) -> _Reading:
    """:class:`_Reading` of the next ``count`` samples without a chip error."""
    total = [0.0] * 7
    used = skipped = full = warm = 0
    for sample in device.samples():
        if sample.chip_error or not all(math.isfinite(b) for b in sample.B_uT):
            skipped += 1
            if skipped > 10 * count + 100:
                raise DeviceError(f"{skipped} samples from {device.port} were chip errors: check the sensor board's "
                                  "wiring and supply")
            continue
        full += bool(sample.full_scale)
        temperature = sample.temperature_C if sample.temperature_C is not None else math.nan
        warm += math.isfinite(temperature)
        total = [t + x for t, x in zip(total, tuple(sample.B_uT) + tuple(sample.force_N) + (temperature,))]
        used += 1
        if used == count:
            break
    mean = [x / used for x in total]
    assert sample.time_s is not None, "Device.samples stamps every sample with its device time"
    return _Reading(tuple(mean[:3]), tuple(mean[3:6]), mean[6] if warm == used else None, full, sample.time_s)


def _mean_field(device: Device, count: int) -> Tuple[Tuple[float, float, float], int]:
    """Mean (Bx, By, Bz) in uT of ``count`` good samples, and how many of them had an axis at full scale."""
    reading = _mean_reading(device, count)
    return reading.B, reading.full


def settle(device: Device, seconds: float) -> None:
    """Drop what the board sent before, then wait ``seconds`` of device time."""
    device.drain()
    start = None
    for sample in device.samples():
        assert sample.time_s is not None, "Device.samples stamps every sample with its device time"
        start = sample.time_s if start is None else start
        if sample.time_s - start >= seconds:
            break


def ask(prompt: str, yes: bool) -> None:
    sys.stderr.write(prompt + (" (--yes: not waiting)\n" if yes else ", then press Enter: "))
    sys.stderr.flush()
    if not yes and not sys.stdin.readline():
        sys.stderr.write("\n")  # the error's line starts on a line of its own, after the prompt's
        raise DeviceError("no answer on stdin (end of input): run the command at a terminal, or pass --yes")


class Steps:
    """The acceptance test's steps as they are reported: numbered PASS/FAIL lines, and the verdict."""

    def __init__(self, out, prefix: str = "") -> None:
        self.out = out
        self.prefix = prefix  # before each line: an array's taxel
        self.results: List[Tuple[str, bool]] = []  # (name, passed)
        self.texts: List[str] = []
        #: What was measured, by name with its unit (the sensor record's check event keeps them).
        self.figures: Dict[str, Optional[float]] = {}

    def figure(self, **values: float) -> None:
        self.figures.update({k: float(v) if math.isfinite(v) else None for k, v in values.items()})

    def report(self, name: str, passed: bool, text: str) -> None:
        self.results.append((name, passed))
        self.texts.append(text)
        self.out.write("{}step {}  {:<26} {}  {}\n".format(self.prefix, len(self.results), name,
                                                          "PASS" if passed else "FAIL", text))
        self.out.flush()

    def verdict(self) -> int:
        failed = [k + 1 for k, (_, passed) in enumerate(self.results) if not passed]
        if failed:
            self.out.write("verdict: FAIL (step{} {} of {})\n".format("s" if len(failed) > 1 else "",
                                                                      ", ".join(map(str, failed)), len(self.results)))
            return FAILED
        self.out.write(f"verdict: PASS (all {len(self.results)} steps)\n")
        return 0

    def event(self, calibration_sha256: str, simulated: bool) -> Dict[str, Any]:
        """The sensor record's ``check`` event data (docs/sensors.md): the verdict, the figures, every step."""
        passed = all(ok for _, ok in self.results)
        data: Dict[str, Any] = {
            "taxel": None, "verdict": "pass" if passed else "fail", "calibration_sha256": calibration_sha256,
            "figures": dict(self.figures),
            "steps": [{"name": name, "verdict": "pass" if ok else "fail", "text": text}
                      for (name, ok), text in zip(self.results, self.texts)]}
        if simulated:
            data["simulated"] = True
        return data


def _check_options(args: argparse.Namespace, bands: Bands, data: dict):
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
    _drift_options(args, bands)
    pattern = None
    if args.simulate:
        scale = bands.scale_of(args.simulate_grade) if args.simulate_grade else 1.0
        pattern = RestTip.from_acceptance(data, scale=scale, flipped=args.simulate_flipped,
                                          loose_mm=args.simulate_loose)
    elif args.simulate_grade or args.simulate_flipped or args.simulate_loose:
        raise UsageError("--simulate-grade, --simulate-flipped and --simulate-loose need --simulate")
    return weight, rise, pattern


def _drift_options(args: argparse.Namespace, bands: Bands) -> None:
    """UsageError for --rotation, --warmup and their options where this package or build cannot run them."""
    for wanted, section, name in ((args.rotation, bands.rotation, "--rotation"),
                                  (args.warmup, bands.warmup, "--warmup")):
        if wanted and section is None:
            raise UsageError(f"{name}: this package's acceptance.json has no band for it (a build before magfab had "
                             "one, or a design without a drift budget): rebuild with magfab build")
    if args.warmup and not _build.TEMPERATURE_ENABLED:
        raise UsageError("--warmup needs the chip's temperature, which this build's firmware does not read "
                         "(firmware.temperature = false)")
    if not (args.warmup_seconds > 0 and math.isfinite(args.warmup_seconds)):
        raise UsageError("--warmup-seconds must be a positive number of seconds")
    if not (math.isfinite(args.simulate_loose) and args.simulate_loose >= 0):
        raise UsageError("--simulate-loose must be zero or a positive number of millimetres")


def run(args: argparse.Namespace, out, open_device) -> int:
    """The check as the command line asks it; ``open_device(args, text, pattern)`` opens the board (or the simulated
    one)."""
    data = load_acceptance()
    if data is None:
        raise DeviceError("this readout package carries no acceptance.json (it was built without the acceptance "
                          "bands): rebuild with magfab build and reinstall ./readout")
    bands = Bands(data)
    weight, rise, pattern = _check_options(args, bands, data)
    n = args.samples
    allow = bands.sigmas * bands.noise_z / math.sqrt(n) + _build.LSB_Z_UT / 2.0
    steps = Steps(out)
    with open_device(args, text=None, pattern=pattern) as device:
        linked = _link(args, device)
        _check_header(out, device, bands, weight, rise, n)
        (bx, by, bz), full = _mean_field(device, n)
        steps.figure(Bx_rest_uT=bx, By_rest_uT=by, Bz_rest_uT=bz, Bxy_rest_uT=math.hypot(bx, by), samples=n)
        check_polarity(steps, bz, allow + bands.earth)
        check_rest(steps, out, bands, bz, full, allow)
        check_lateral(steps, bands, bx, by, bands.sigmas * bands.noise_xy / math.sqrt(n) + _build.LSB_XY_UT / 2.0)
        if not args.no_weight:
            _check_weight(steps, out, args, device, bands, weight, rise, bz)
        if args.rotation:
            _check_rotation(steps, out, args, device, bands)
        if args.warmup:
            _check_warmup(steps, out, args, device, bands)
        sha = device.calibration.sha256
    verdict = steps.verdict()
    if args.sensor and linked.sensor is not None:
        event = linked.sensor.append("check", steps.event(sha, bool(args.simulate)))
        out.write(f"record: check {event['number']} of sensor {linked.sensor.id} in {linked.sensor.path}\n")
    return verdict


def _link(args: argparse.Namespace, device) -> board_sensor.Link:
    """The sensor on the board (``--sensor ID``, or the one its EEPROM names) and its current calibration as the
    device's; with ``--sensor`` the board must run that calibration (or, not calibrated yet, the package's)."""
    info = device.info()
    linked = board_sensor.link(device, info, args)
    if linked.superseded:  # an acceptance test of an old skin's calibration on the new skin would judge nothing
        raise UsageError(linked.superseded_note())
    if args.sensor:
        for warning in device.check_info(info):
            sys.stderr.write(f"magfab-readout: warning: {warning}\n")
    return linked


def _check_header(out, device, bands: Bands, weight: float, rise, n: int) -> None:
    lo, nom, hi = bands.rest
    out.write(f"# magfab-readout {_build.VERSION} check: spec {json.dumps(_build.SPEC_NAME)}, "
              f"calibration {device.calibration.short_hash}, {device.port}\n")
    out.write("# predicted (worst case over the magnet, material and assembly tolerances; magfab acceptance.json):\n"
              f"#   Bz at rest {lo:.0f} .. {hi:.0f} uT (nominal {nom:.0f}), positive with the north pole away from the "
              f"chip; |Bxy| at rest <= {bands.bxy_max:.0f} uT\n")
    if rise is not None:
        out.write(f"#   a {weight:g} g weight on the tip raises Bz by {rise[0]:.0f} .. {rise[2]:.0f} uT "
                  f"(nominal {rise[1]:.0f})\n")
    out.write(f"# reading {n} samples with nothing touching the tip\n")
    out.flush()


def check_polarity(steps: Steps, bz: float, floor: float) -> None:
    """Step 1, the sign: an upside-down magnet reads the same field negated."""
    if bz > floor:
        steps.report("polarity (sign of Bz)", True,
                     f"measured {bz:+.0f} uT: positive, the north pole faces away from the chip as designed")
    elif bz < -floor:
        steps.report("polarity (sign of Bz)", False, f"measured {bz:+.0f} uT: negative, the magnet is upside down (its "
                     "north pole faces the chip); push it out of the pocket and turn it over")
    else:
        steps.report("polarity (sign of Bz)", False,
                     f"measured {bz:+.0f} uT: no field from the magnet (|Bz| under {floor:.0f} uT); is there a magnet "
                     "in the fingertip, and is the fingertip on the chip?")


def check_rest(steps: Steps, out, bands: Bands, bz: float, full: int, allow: float) -> None:
    """Step 2, the field at rest against the predicted band, and the remanence it implies."""
    lo, nom, hi = bands.rest
    text = f"measured {bz:+.0f} uT, predicted {lo:.0f} .. {hi:.0f} uT (nominal {nom:.0f})"
    if full:
        steps.report("Bz at rest", False, text + f": {full} samples had an axis at the chip's full scale (magnet far "
                     "too close or too strong)")
    elif lo - allow <= bz <= hi + allow:
        steps.report("Bz at rest", True, text)
    elif bz < 0 and lo - allow <= -bz <= hi + allow:
        steps.report("Bz at rest", False, text + ": the magnet is upside down (|Bz| is inside the band)")
    elif bz > hi + allow:
        steps.report("Bz at rest", False, text + f": stronger than predicted - a stronger grade than {bands.grade}, a "
                     "bigger magnet, or the magnet closer to the chip (not pushed home, thin pad or glue)")
    else:
        steps.report("Bz at rest", False, text + ": weaker than predicted - a weaker or partly demagnetised magnet "
                     "(heated above 80 C?), a smaller magnet, or the magnet further from the chip (thick glue, pad "
                     "not seated)")
    if abs(bz) > allow + bands.earth:
        implied = abs(bz) / nom * bands.remanence[1]
        note = (f"#   at the nominal stack-up this field means a remanence of {implied:.2f} T ({bands.grade} is "
                f"{bands.remanence[0]:.2f} .. {bands.remanence[2]:.2f} T)")
        if len(bands.inside) > 1 and steps.results[-1][1]:
            note += "; the band also holds the nominal field of grades {}: it cannot tell those apart".format(
                ", ".join(g for g in bands.inside if g != bands.grade))
        out.write(note + "\n")


def check_lateral(steps: Steps, bands: Bands, bx: float, by: float, allow_xy: float) -> None:
    """Step 3, the lateral field at rest: the magnet on the chip's axis and level."""
    bxy = math.hypot(bx, by)
    text = f"measured {bxy:.0f} uT, predicted at most {bands.bxy_max:.0f} uT"
    if bxy <= bands.bxy_max + allow_xy:
        steps.report("|Bxy| at rest", True, text)
    else:
        steps.report("|Bxy| at rest", False, text + ": the magnet is off the chip's axis or tilted (check the pad on "
                     "its pins and the fingertip in the lip), or a magnetic object is near")


def _check_weight(steps: Steps, out, args: argparse.Namespace, device, bands: Bands, weight: float, rise,
                  bz: float) -> None:
    """Step 4, the known weight: the rise of Bz against the band the material and magnet predict."""
    n = args.samples
    ask(f"place the {weight:g} g weight on the tip, centred, with nothing else touching", args.yes)
    if args.simulate:
        device.transport.place_weight(weight)
    settle(device, args.settle)
    out.write(f"# reading {n} samples with {weight:g} g on the tip\n")
    (_, _, bz_w), full_w = _mean_field(device, n)
    judge_rise(steps, bands, weight, rise, bz_w - bz, full_w, bz, n)
    if not args.yes:
        sys.stderr.write("take the weight off the tip\n")
    if args.simulate:
        device.transport.place_weight(0.0)


def judge_rise(steps: Steps, bands: Bands, weight: float, rise, delta: float, full_w: int, bz: float,
               n: int) -> None:
    """The known weight's step: the rise of Bz ``delta`` (uT, means of ``n`` samples; ``bz`` the field at rest)
    against the band the material and magnet predict, ``rise`` (min, nominal, max)."""
    steps.figure(weight_g=weight, Bz_rise_uT=delta)
    allow_d = bands.sigmas * bands.noise_z * math.sqrt(2.0 / n) + _build.LSB_Z_UT
    name = f"rise of Bz under {weight:g} g"
    text = f"measured {delta:+.0f} uT, predicted {rise[0]:.0f} .. {rise[2]:.0f} uT (nominal {rise[1]:.0f})"
    if full_w:
        steps.report(name, False, text + f": {full_w} samples had an axis at the chip's full scale")
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


def _check_rotation(steps: Steps, out, args: argparse.Namespace, device, bands: Bands) -> None:
    """The turn-over step: the field change against the Earth's field turned over and the fingertip's own weight
    reversed (acceptance.json ``rotation``), and the force it is worth against the drift budget's."""
    rot, n = bands.rotation, args.samples
    assert rot is not None, "_drift_options refuses --rotation without acceptance.json's rotation section"
    ask("turning over: the sensor upright as before, nothing touching the tip", args.yes)
    settle(device, args.settle)
    upright = _mean_reading(device, n)
    ask("turn the whole sensor (board and fingertip) upside down, 180 deg about a horizontal axis, with nothing "
         "touching the tip", args.yes)
    if args.simulate:
        device.transport.turn(True)
    settle(device, args.settle)
    out.write(f"# reading {n} samples turned upside down\n")
    turned = _mean_reading(device, n)
    if args.simulate:
        device.transport.turn(False)
    if not args.yes:
        sys.stderr.write("turn the sensor back upright\n")
    dB = [b - a for a, b in zip(upright.B, turned.B)]
    change = math.sqrt(sum(d * d for d in dB))
    per_axis = [bands.sigmas * noise * math.sqrt(2.0 / n) + lsb for noise, lsb in (
        (bands.noise_xy, _build.LSB_XY_UT), (bands.noise_xy, _build.LSB_XY_UT), (bands.noise_z, _build.LSB_Z_UT))]
    allow = math.sqrt(sum(a * a for a in per_axis))
    dF = 1000.0 * (turned.force[2] - upright.force[2])
    steps.figure(turned_dB_uT=change, turned_dBz_uT=dB[2], turned_dFz_mN=dF)
    name = "turned over"
    text = ("measured |dB| {:.0f} uT (dBz {:+.0f}), predicted at most {:.0f} uT (the Earth's field turned over {:.0f}, "
            "the fingertip's own weight reversed {:.0f}); force {:+.1f} mN (predicted: {} the Earth, {:.1f} the own "
            "weight)").format(change, dB[2], rot["band_uT"], rot["earth_change_uT"], rot["self_weight_change_uT"], dF,
                              "n/a" if rot.get("predicted_normal_rest_mN") is None else
                              "{:.1f}".format(rot["predicted_normal_rest_mN"]), rot["self_weight_mN"])
    if upright.full or turned.full:
        steps.report(name, False, text + ": samples had an axis at the chip's full scale")
    elif change <= rot["band_uT"] + allow:
        steps.report(name, True, text)
    else:
        travel_um = 1000.0 * abs(dB[2]) / rot["gradient_uT_per_mm"]
        steps.report(name, False, text + ": more than the Earth's field and the fingertip's weight can change - the "
                     f"magnet moved ({travel_um:.0f} um at the rest gradient): loose in its pocket, shifting under its "
                     "own weight (glue it in), or steel or magnetised parts near the sensor turned with it (screws, a "
                     "clamp, a steel bench: move them away and repeat)")


def _warm(device, args: argparse.Namespace, start_C: float, least_C: float):
    """Blocks of ``args.samples`` readings until their mean temperature is ``least_C`` above ``start_C`` or
    ``args.warmup_seconds`` of device time have passed: (the last block's reading, seconds waited, warmed)."""
    began = reported = None
    while True:
        reading = _mean_reading(device, args.samples)
        began = reading.time_s if began is None else began
        reported = began if reported is None else reported
        waited = reading.time_s - began
        rise = (reading.temperature if reading.temperature is not None else start_C) - start_C
        if rise >= least_C or waited >= args.warmup_seconds:
            return reading, waited, rise >= least_C
        if reading.time_s - reported >= 10.0:
            reported = reading.time_s
            sys.stderr.write(f"chip at {start_C + rise:.1f} C (+{rise:.1f} C of the {least_C:g} C needed)\n")
            sys.stderr.flush()


def _thermal_case(device) -> Tuple[str, str]:
    """Which of the warm-up's per-degree figures applies to this package's calibration, and what it is."""
    thermal = device.calibration.thermal
    if thermal is None:
        return "without", "no temperature correction in this calibration"
    if thermal.source == "fit":
        return "fitted", "the calibration's fitted thermal coefficients"
    return "with", "the recipe's thermal coefficients"


def _check_warmup(steps: Steps, out, args: argparse.Namespace, device, bands: Bands) -> None:
    """The warm-up step: the rest force's change against the drift budget's compensated figure per degree times
    the warming (acceptance.json ``warmup``)."""
    w, n = bands.warmup, args.samples
    assert w is not None, "_drift_options refuses --warmup without acceptance.json's warmup section"
    least = float(w["min_change_C"])
    ask("warm-up: nothing touching the tip, the sensor where it will stay", args.yes)
    settle(device, args.settle)
    cold = _mean_reading(device, n)
    ask(f"warm the sensor by at least {least:g} C with nothing touching the tip: hold the board (not the fingertip) "
         "in your hand, or power it up from cold; warm it evenly, so the magnet keeps up with the chip",
         args.yes)
    if args.simulate:
        device.transport.warm(args.simulate_warm if args.simulate_warm is not None else least + 1.0)
    out.write(f"# waiting for the chip to warm by {least:g} C from {cold.temperature:.1f} C "
              f"(at most {args.warmup_seconds:g} s)\n")
    out.flush()
    warm, waited, warmed = _warm(device, args, cold.temperature, least)
    dT = warm.temperature - cold.temperature
    dF = 1000.0 * (warm.force[2] - cold.force[2])
    steps.figure(warmup_dT_C=dT, warmup_dFz_mN=dF)
    case, what = _thermal_case(device)
    k = slope_mN_per_uT(device.calibration, cold.B, cold.temperature) / float(w["channel_mN_per_uT"])
    per_C = float(w["per_C_mN"][case]) * k
    band = per_C * abs(dT) + bands.sigmas * float(w["noise_mN"]) * k * math.sqrt(2.0 / n)
    name = "warm-up"
    text = ("measured {:+.1f} mN over {:+.1f} C ({:+.2f} mN/C), predicted at most {:.1f} mN ({:.2f} mN/C with {}; "
            "uncompensated {:.2f} mN/C; the drift budget's figures x {:.2f}, this calibration's force per field at "
            "rest over the budget's)").format(dF, dT, dF / dT if dT else math.nan, band, per_C, what,
                                              float(w["per_C_mN"]["without"]) * k, k)
    if cold.full or warm.full:
        steps.report(name, False, text + ": samples had an axis at the chip's full scale")
    elif not warmed:
        steps.report(name, False, text + f": the chip warmed by only {dT:.1f} C in {waited:.0f} s - warm it by at "
                     f"least {least:g} C (or give --warmup-seconds more) and repeat")
    elif abs(dF) <= band:
        steps.report(name, True, text)
    else:
        steps.report(name, False, text + ": the rest force follows the temperature more than the correction leaves "
                     "- the board runs a calibration without its thermal block or a wrong one (magfab-readout upload, "
                     "then info), or the magnet is not the {} NdFeB of the spec, whose remanence falls {:g} %/C "
                     "(another material drifts at another rate)".format(bands.grade, abs(w["magnet_pct_per_C"])))
