"""``magfab-readout weigh``: the bench side of a calibration with known weights (docs/bundle.md section 1b).

It walks the build's weight plan (``weigh_plan.json``, which magfab made for this design and the weight jig it
printed): for each step it asks for the board in the stand of the step's angle and for the coins in the cap's
pockets, waits until the reading is steady (after ``--dwell-s``, two windows of ``--samples`` readings whose means
agree within their noise), and writes the mean field and its spread as one row of the weighings CSV, which ``magfab
calibrate --weights`` fits. The mass on the tip is the cap's (``--cap-g``: weigh it once) plus the coins'. Each row
is written and flushed as it is measured, so an interrupted session keeps the weighings made; one that ends before
its first leaves no file, and an existing file is not overwritten without ``--force``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pkgutil
import sys
from typing import Any, Dict, List, Optional, Tuple

from . import _build, bounded
from .check import ask
from .cli_shared import UsageError
from .coins import coin_layout
from .device import DeviceError
from .simulate import WeighedTip

__all__ = ["add_parser", "run", "load_plan", "WEIGHT_COLUMNS", "steady_mean"]

#: The weighings CSV's columns (docs/bundle.md section 1b; magfab.formats.weights_csv reads them).
WEIGHT_COLUMNS = ("mass_g", "angle_deg", "Bx_uT", "By_uT", "Bz_uT", "Bx_sd_uT", "By_sd_uT", "Bz_sd_uT", "samples")
#: Two windows are steady when their means agree within this many standard errors of their difference (per axis).
STEADY_SIGMAS = 4.0


def add_parser(commands, common: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The ``weigh`` command and its options, on the command line's subcommands."""
    weigh = commands.add_parser(
        "weigh", parents=[common], help="walk the weight plan: the field under known weights on the weight jig",
        description="Calibration without a force sensor (docs/bundle.md section 1b). For each step of this build's "
        "weight plan, put the board in the stand of the step's angle (connector uphill), the cap on the "
        "tip and the step's coins in the cap's pockets as listed, and press Enter; the command waits until the "
        "reading is steady and writes its mean field and spread to OUT.csv. Then: magfab calibrate --weights OUT.csv.")
    weigh.add_argument("out", metavar="OUT.csv", help="the weighings file to write")
    weigh.add_argument("--cap-g", type=float, metavar="G",
                       help="the printed cap's mass in grams, weighed on a balance (needed)")
    weigh.add_argument("--coin-g", type=float, metavar="G",
                       help="one coin's mass in grams (default: the plan's coin, the US 5-cent piece, 5.000 g)")
    weigh.add_argument("--first", action="store_true",
                       help="only the plan's first two steps, flat: their fit tells how stiff this skin is; then "
                       "magfab weigh-plan OUT.csv PLAN.json makes the plan for it")
    weigh.add_argument("--plan", metavar="PLAN.json",
                       help="walk this plan (from magfab weigh-plan) instead of the build's plan for the softest skin")
    weigh.add_argument("--reskin", action="store_true",
                       help="only the three steps a new skin on a calibrated board needs (magfab calibrate --weights "
                       "with --sensor keeps the rest)")
    weigh.add_argument("--samples", type=int, default=200, metavar="N",
                       help="readings per window; the mean of the last steady window is recorded (default: "
                       "%(default)s)")
    weigh.add_argument("--settle-s", type=float, default=60.0, metavar="S",
                       help="longest wait for a steady reading, seconds of device time (default: %(default)s)")
    weigh.add_argument("--dwell-s", type=float, default=2.0, metavar="S",
                       help="seconds of device time after Enter before the first window, while the silicone creeps "
                       "(default: %(default)s)")
    weigh.add_argument("--force", action="store_true", help="overwrite OUT.csv when it exists")
    weigh.add_argument("--yes", "-y", action="store_true",
                       help="do not wait for Enter (non-interactive): each load is on the tip when the step asks")
    return weigh


def load_plan() -> Optional[Dict[str, Any]]:
    """The package's weight plan, or None when the build made none (an array; a design whose ranges the jig's loads
    do not fit)."""
    try:
        raw = pkgutil.get_data("magfab_readout", "weigh_plan.json")
    except OSError:
        return None
    if raw is None:
        return None
    plan = json.loads(raw.decode("utf-8"))
    if plan.get("format") != "magfab-weigh-plan/1":
        raise DeviceError("the package's weigh_plan.json is not magfab-weigh-plan/1: reinstall the readout package "
                          "from the same magfab build")
    return plan


def _positive(value: Optional[float], name: str, unit: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise UsageError(f"{name} {value}: must be a positive number of {unit}")


def steady_mean(device, samples: int, settle_s: float, dwell_s: float = 0.0
                ) -> Tuple[List[float], List[float], int]:
    """The field's mean and standard deviation (uT, per axis) over the first window of ``samples`` readings whose
    mean agrees with the window before it within :data:`STEADY_SIGMAS` standard errors of their difference on every
    axis (floored at the quantisation of a mean, one count over sqrt(12 n)), the first window starting ``dwell_s``
    after the load went on (the silicone's creep). A window with a chip error or an axis at the chip's full scale
    starts again; DeviceError when no window settles within ``settle_s`` seconds of device time, naming what kept
    it from settling."""
    device.drain()
    previous: Optional[Tuple[List[float], List[float]]] = None
    window: List[Tuple[float, float, float]] = []
    start: Optional[float] = None
    full = errors = 0
    floor = [lsb / math.sqrt(12.0 * samples) for lsb in (_build.LSB_XY_UT, _build.LSB_XY_UT, _build.LSB_Z_UT)]
    for sample in device.samples():
        start = sample.time_s if start is None else start
        if sample.time_s - start > settle_s:
            why = (f"an axis was at the chip's full scale in {full} readings (a load past what this chip setting "
                   "reads: the wrong plan or the wrong coins)" if full else
                   f"the chip reported {errors} errors" if errors else
                   "something touches the cap or the stand, or the tip is still creeping")
            raise DeviceError(f"the reading did not settle within {settle_s:g} s (--settle-s): {why}; take the load "
                              "off and try again")
        if sample.time_s - start < dwell_s:
            continue
        if sample.full_scale or sample.chip_error:
            full += bool(sample.full_scale)
            errors += bool(sample.chip_error and not sample.full_scale)
            previous, window = None, []
            continue
        window.append(tuple(sample.B_uT))
        if len(window) < samples:
            continue
        mean = [sum(b[k] for b in window) / samples for k in range(3)]
        sd = [math.sqrt(sum((b[k] - mean[k]) ** 2 for b in window) / max(samples - 1, 1)) for k in range(3)]
        if previous is not None and all(
                abs(mean[k] - previous[0][k]) <= max(STEADY_SIGMAS * math.hypot(sd[k], previous[1][k])
                                                     / math.sqrt(samples), floor[k]) for k in range(3)):
            return mean, sd, samples
        previous, window = (mean, sd), []
    raise DeviceError("the board stopped sending samples")


def _steps(plan: Dict[str, Any], args: argparse.Namespace) -> List[Dict[str, Any]]:
    steps = plan["steps"]
    which = "first" if args.first else "reskin" if args.reskin else None
    return [steps[k] for k in plan[which]] if which else list(steps)


def skin_plan(path: str, shipped: Dict[str, Any]) -> Dict[str, Any]:
    """The plan of ``--plan PATH`` (``magfab weigh-plan``'s), checked against the package's own: the same format,
    design, coin and cap; steps on the printed stands with whole coins in the cap's pockets, no more than the build's
    plans take; the first, re-skin and nominal entries whole. UsageError (one line) for anything else."""
    def bad(what: str) -> UsageError:
        return UsageError(f"--plan {path}: {what}; make it with magfab weigh-plan FIRST.csv PLAN.json from this "
                          "build's folder")

    try:
        plan = bounded.loads_json(bounded.read_text(path, "JSON"), "weight plan", path)
    except (OSError, ValueError) as exc:
        raise bad(f"not a readable JSON file ({exc})") from None
    if not isinstance(plan, dict) or plan.get("format") != shipped["format"]:
        raise bad(f"not a weight plan ({shipped['format']})")
    for key in ("spec", "coin", "pockets", "cap_mass_bound_g", "stands_deg", "stand_coins_most"):
        if plan.get(key) != shipped.get(key):
            raise bad(f"its {key} is {json.dumps(plan.get(key))}, this build's {json.dumps(shipped.get(key))}")
    steps, pockets = plan.get("steps"), int(shipped["pockets"])
    if not isinstance(steps, list) or not 1 <= len(steps) <= 100:
        raise bad("its steps are not a list of 1 to 100")
    most = dict(zip(shipped["stands_deg"], shipped["stand_coins_most"]))  # any skin's plan, per stand
    for k, step in enumerate(steps):
        step = step if isinstance(step, dict) else {}
        coins, angle = step.get("coins"), step.get("angle_deg")
        laid = (isinstance(coins, int) and not isinstance(coins, bool) and isinstance(angle, (int, float))
                and not isinstance(angle, bool) and angle in most and 0 <= coins <= most[angle] and coins % 2 == 0
                and step.get("layout") == coin_layout(coins, pockets))
        if not laid:
            raise bad(f"step {k + 1} is not a stand of {shipped['stands_deg']} deg with an even number of coins up "
                      f"to that stand's most ({shipped['stand_coins_most']}), laid in opposite pairs round the cap's "
                      f"{pockets} pockets")
    for key in ("first", "reskin"):
        index = plan.get(key)
        if not isinstance(index, list) or not index or not all(_whole(i) and 0 <= i < len(steps) for i in index):
            raise bad(f"its {key} steps are not indices of its steps")
    try:
        tip = WeighedTip(plan["nominal"])
        for step in steps:
            tip.place_load(0.0, float(step["angle_deg"]))
    except (KeyError, TypeError, ValueError, IndexError):
        raise bad("its nominal field tables do not cover its steps' stands") from None
    return plan


def _whole(value: Any) -> bool:
    """An int of JSON's, not a boolean."""
    return isinstance(value, int) and not isinstance(value, bool)


def _load_text(step: Dict[str, Any]) -> str:
    coins = int(step["coins"])
    if not coins:
        return "the cap alone, no coins"
    stacks = ", ".join(f"{n} in pocket {k + 1}" for k, n in enumerate(step["layout"]) if n)
    return f"{coins} coins: {stacks}"


def _check(args: argparse.Namespace, plan: Dict[str, Any]) -> float:
    """UsageError for an option the plan cannot take; the coin's mass."""
    if args.cap_g is None:
        raise UsageError("--cap-g G is needed: the printed cap's mass in grams (weigh it once on a balance)")
    _positive(args.cap_g, "--cap-g", "grams")
    _positive(args.coin_g, "--coin-g", "grams")
    _positive(args.settle_s, "--settle-s", "seconds")
    if not (math.isfinite(args.dwell_s) and args.dwell_s >= 0):
        raise UsageError(f"--dwell-s {args.dwell_s}: must be zero or a positive number of seconds")
    if args.samples < 2:
        raise UsageError("--samples must be at least 2 (a window's spread needs two readings)")
    bound = float(plan["cap_mass_bound_g"])
    if args.cap_g > 2.0 * bound:
        raise UsageError(f"--cap-g {args.cap_g:g}: this build's cap weighs at most about {bound:g} g (printed solid in "
                         "the densest filament); weigh the cap alone")
    coin_g = float(plan["coin"]["mass_g"])
    if args.coin_g is not None and args.coin_g > coin_g:
        raise UsageError(f"--coin-g {args.coin_g:g}: at most the plan's coin, {coin_g:g} g (a heavier coin would push "
                         "the plan's loads past the sensor's range)")
    need = args.dwell_s + 2.0 * args.samples / _build.SAMPLE_RATE_HZ
    if need > args.settle_s:
        raise UsageError(f"--settle-s {args.settle_s:g}: two windows of {args.samples} readings after the "
                         f"{args.dwell_s:g} s dwell take {need:.3g} s at the chip's {_build.SAMPLE_RATE_HZ:g} Hz")
    if os.path.exists(args.out) and not args.force:
        raise UsageError(f"{args.out} exists: weighings are not overwritten (another name, or --force)")
    return coin_g if args.coin_g is None else float(args.coin_g)


def run(args: argparse.Namespace, out, open_device) -> int:
    """The weighings as the command line asks them; ``open_device(args, text, pattern)`` opens the board (or the
    simulated one, which then serves the nominal sensor's field under each load). A session that ends before its
    first weighing leaves no file."""
    plan = load_plan()
    if plan is None:
        raise UsageError("this build has no weight plan (an array, or a design whose ranges the weight jig's loads "
                         "do not fit; the build's report says why): calibrate it from a scan")
    if args.first and (args.plan is not None or args.reskin):
        raise UsageError("--first walks the build's plan's first two steps: give it without --plan and --reskin")
    if args.reskin and args.plan is not None:
        raise UsageError("--reskin walks the build's plan's re-skin steps, safe for any new skin: give it without "
                         "--plan (a skin's plan is the old skin's, and may press a softer new one past its range)")
    if args.plan is not None:
        plan = skin_plan(args.plan, plan)
    coin_g = _check(args, plan)
    steps = _steps(plan, args)
    nominal = WeighedTip(plan["nominal"])  # the nominal sensor's field under each load, printed beside the reading
    pattern = nominal if args.simulate else None  # which the simulated board serves
    written = 0
    try:
        with open_device(args, text=None, pattern=pattern) as device, \
                open(args.out, "w", encoding="utf-8", newline="") as f:
            f.write(f"# magfab-readout {_build.VERSION} weigh: spec {json.dumps(_build.SPEC_NAME)}, cap "
                    f"{args.cap_g:g} g, coin {coin_g:g} g, {_which(args, len(steps))}\n")
            f.write(",".join(WEIGHT_COLUMNS) + "\n")
            f.flush()
            for k, step in enumerate(steps):
                angle, mass = float(step["angle_deg"]), args.cap_g + int(step["coins"]) * coin_g
                ask(f"step {k + 1} of {len(steps)}: the board in the {angle:g} deg stand (weigh_stand_{angle:g}), "
                    f"connector uphill, the cap on the tip; {_load_text(step)} ({mass:.2f} g on the tip)", args.yes)
                nominal.place_load(mass, angle)
                mean, sd, n = steady_mean(device, args.samples, args.settle_s, args.dwell_s)
                f.write(",".join([f"{mass:.4f}", f"{angle:g}", *(f"{b:.3f}" for b in mean),
                                  *(f"{s:.3f}" for s in sd), str(n)]) + "\n")
                f.flush()
                written += 1
                out.write("step {} of {}: {:.2f} g at {:g} deg: B = ({:.1f}, {:.1f}, {:.1f}) uT, sd ({:.1f}, {:.1f}, "
                          "{:.1f}); the nominal sensor reads ({:.0f}, {:.0f}, {:.0f})\n".format(
                              k + 1, len(steps), mass, angle, *mean, *sd, *nominal.field(0.0)))
                out.flush()
    except BaseException:
        if written == 0 and os.path.exists(args.out):
            os.remove(args.out)  # nothing measured: no file that looks like a session
        raise
    after = (f"magfab weigh-plan {args.out} PLAN.json (the plan for this skin)" if args.first else
             f"magfab calibrate --weights {args.out}")
    sys.stderr.write(f"magfab-readout: wrote {len(steps)} weighings to {args.out}; next: {after}\n")
    return 0


def _which(args: argparse.Namespace, steps: int) -> str:
    """The header's name of the steps walked."""
    if args.first:
        return f"the build's plan's first {steps} steps"
    if args.reskin:
        return f"the build's plan's {steps} re-skin steps"
    if args.plan is not None:
        return f"the plan {json.dumps(args.plan)} of {steps} steps"
    return f"the build's plan of {steps} steps"
