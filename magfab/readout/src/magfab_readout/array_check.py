"""``magfab-readout check`` for an array: the acceptance test of every taxel, guided taxel by taxel.

With nothing touching the array it averages each taxel's own field (the compensation of docs/bundle.md section 5
removes the other magnets') and judges its sign, its Bz and its lateral field against the bands magfab predicted
(acceptance.json, signed by the taxel's polarity), as the single taxel's check does. Then it asks for the known
weight on each taxel in turn and judges

- the rise of that taxel's own Bz against the predicted band, and
- the **crosstalk**: the force every other taxel reads meanwhile (the larger of its normal and its lateral force's
  change from rest, mN, as the budget counts it) against the build's crosstalk budget (the package's crosstalk.json,
  magfab's array/crosstalk.json): the larger of the spec's tolerance (``tolerance_mN``) and what the budget predicts
  for that pair with the host's compensation (``residual_mN``, for a neighbour pressed to the range: a bound for a
  lighter load; plus, through a continuous skin, ``coupling`` times the weight), plus the noise of a difference of
  two means through that taxel's calibration (``allowance_sigmas`` x the normal force's noise x sqrt(2 / N), and
  one count).

Each taxel's steps are numbered on their own; the verdict passes when every step of every taxel does. With
``--sensor ID`` each taxel's result is appended to the record as its own ``check`` event (``taxel`` k, its figures
with the crosstalk on each other taxel). :func:`run` returns 0 when every step passes, 1 otherwise.
"""

from __future__ import annotations

import argparse
import json
import math
import pkgutil
import sys
from typing import Any, Dict, List, Optional, Sequence, Tuple

from . import _build, array_sensor
from .array_sim import ArrayRestTip
from .check import G0, Bands, Steps, ask, check_lateral, check_polarity, check_rest, judge_rise, load_acceptance, settle
from .cli_shared import FAILED, UsageError
from .device import DeviceError
from .frames import STATUS_FULL_SCALE
from .rest import slope_mN_per_uT
from .taxels import ArrayCalibration, ArrayReader

__all__ = ["Budget", "load_crosstalk", "run"]

Vector = Tuple[float, float, float]


def load_crosstalk() -> Optional[dict]:
    """The package's crosstalk.json (magfab's array/crosstalk.json), or None when the package ships none."""
    try:
        raw = pkgutil.get_data("magfab_readout", "crosstalk.json")
    except OSError:
        return None
    return None if raw is None else json.loads(raw.decode("utf-8"))


class Budget:
    """What crosstalk.json allows taxel i to read while taxel k carries a weight (module doc)."""

    def __init__(self, data: dict, taxels: int) -> None:
        try:
            self.tolerance_mN = float(data["tolerance_mN"])
            self.residual_mN = [[float(x) for x in row] for row in data["residual_mN"]]
            self.coupling = [[float(x) for x in row] for row in data["coupling"]]
            tables: List[list] = [self.residual_mN, self.coupling, *self.residual_mN, *self.coupling]
            ok = math.isfinite(self.tolerance_mN) and self.tolerance_mN > 0 and all(len(t) == taxels for t in tables)
        except (KeyError, TypeError, ValueError):
            ok = False
        if not ok:
            raise DeviceError(f"the package's crosstalk.json is not the budget of {taxels} taxels (tolerance_mN, "
                              "residual_mN, coupling): reinstall the readout package from the same magfab build")

    def allowed_mN(self, i: int, k: int, weight_g: float) -> Tuple[float, float]:
        """(what taxel i may read with ``weight_g`` on taxel k, what the budget predicts it reads), mN."""
        predicted = self.residual_mN[i][k] + abs(self.coupling[i][k]) * weight_g * G0
        return max(self.tolerance_mN, predicted), predicted


class _Means:
    """Each taxel's mean own field (uT) and force (N) over ``count`` good readings, and its full-scale count."""

    def __init__(self, own: List[Vector], force: List[Vector], full: List[int]) -> None:
        self.own, self.force, self.full = own, force, full


def _mean_cycles(device, array: ArrayCalibration, count: int) -> _Means:
    """:class:`_Means` of the next ``count`` good readings of every taxel."""
    n = array.taxels
    sums = [[0.0] * 6 for _ in range(n)]
    used, full = [0] * n, [0] * n
    for cycles, cycle in enumerate(ArrayReader(device, array).cycles(), start=1):
        for t in cycle:
            values = tuple(t.own_uT) + tuple(t.force_N)
            if t.ok and used[t.taxel] < count and all(math.isfinite(v) for v in values):
                sums[t.taxel] = [a + v for a, v in zip(sums[t.taxel], values)]
                used[t.taxel] += 1
                full[t.taxel] += bool(t.status & STATUS_FULL_SCALE)
        if min(used) >= count:
            break
        if cycles > 10 * count + 100:
            failing = ", ".join(str(k) for k in range(n) if used[k] < count)
            raise DeviceError(f"taxel(s) {failing} gave {min(used)} good readings in {cycles} cycles from "
                              f"{device.port}: check the chips' wiring and addresses (magfab-readout info)")
    means = [[x / count for x in s] for s in sums]
    return _Means([(m[0], m[1], m[2]) for m in means], [(m[3], m[4], m[5]) for m in means], full)


def _options(args: argparse.Namespace, bands: Bands) -> Tuple[float, Optional[Tuple[float, float, float]]]:
    """The weight and its predicted rise (None with --no-weight); UsageError for what an array's check cannot do."""
    if args.samples < 1:
        raise UsageError("--samples must be at least 1")
    if not args.settle >= 0:
        raise UsageError("--settle must be zero or positive")
    for wanted, name in ((args.rotation, "--rotation"), (args.warmup, "--warmup"),
                         (args.simulate_grade, "--simulate-grade"), (args.simulate_flipped, "--simulate-flipped"),
                         (args.simulate_loose, "--simulate-loose")):
        if wanted:
            raise UsageError(f"{name} is a single taxel's step: an array's check judges each taxel at rest, under the "
                             "known weight, and the crosstalk on the others")
    weight = bands.weight_g if args.weight_g is None else float(args.weight_g)
    if args.no_weight:
        return weight, None
    if not (math.isfinite(weight) and weight > 0):
        raise UsageError("--weight-g must be a positive number of grams")
    return weight, bands.rise(weight)


def run(args: argparse.Namespace, array: ArrayCalibration, out, open_device) -> int:
    """The array's check as the command line asks it; ``open_device(args, text, pattern)`` opens the board (or the
    simulated array with ``pattern``)."""
    data = load_acceptance()
    if data is None:
        raise DeviceError("this readout package carries no acceptance.json (it was built without the acceptance "
                          "bands): rebuild with magfab build and reinstall ./readout")
    bands = Bands(data)
    weight, rise = _options(args, bands)
    crosstalk = load_crosstalk()
    if rise is not None and crosstalk is None:
        raise DeviceError("this readout package carries no crosstalk.json (the build's crosstalk budget, which the "
                          "check judges the neighbours against): rebuild with magfab build and reinstall ./readout")
    budget = None if crosstalk is None else Budget(crosstalk, array.taxels)
    pattern = ArrayRestTip.from_acceptance(array, data, crosstalk) if args.simulate else None
    steps = [Steps(out, prefix=f"taxel {k:<2d} ") for k in range(array.taxels)]
    with open_device(args, None, pattern) as device:
        info = device.info()
        linked = array_sensor.link(device, info, args, array)
        array = linked.array
        array_sensor.checked_info(device, array, info)
        _header(out, device, array, bands, weight, rise, args.samples)
        rest = _mean_cycles(device, array, args.samples)
        for k in range(array.taxels):
            _rest_steps(steps[k], out, array, bands, rest, k, args.samples)
        if rise is not None and budget is not None:
            for k in range(array.taxels):
                _weight_on(steps, out, args, device, array, (bands, budget), (weight, rise), rest, k)
    verdict = _verdict(out, steps)
    if args.sensor and linked.sensor is not None:
        for k, taxel in enumerate(steps):
            event = taxel.event(array.calibrations[k].sha256, bool(args.simulate))
            event["taxel"] = k
            written = linked.sensor.append("check", event)
            out.write(f"record: check {written['number']} of sensor {linked.sensor.id}, taxel {k}, in "
                      f"{linked.sensor.path}\n")
    return verdict


def _header(out, device, array: ArrayCalibration, bands: Bands, weight: float, rise, n: int) -> None:
    lo, nom, hi = bands.rest
    out.write(f"# magfab-readout {_build.VERSION} check: spec {json.dumps(_build.SPEC_NAME)}, array of "
              f"{array.taxels} taxels, calibrations {array.board_hash}, {device.port}\n")
    out.write("# predicted for each taxel's own field (the other magnets' removed; magfab acceptance.json), signed by "
              f"its magnet's polarity:\n#   Bz at rest {lo:.0f} .. {hi:.0f} uT (nominal {nom:.0f}); |Bxy| at rest <= "
              f"{bands.bxy_max:.0f} uT\n")
    if rise is not None:
        out.write(f"#   a {weight:g} g weight on a taxel raises its Bz by {rise[0]:.0f} .. {rise[2]:.0f} uT (nominal "
                  f"{rise[1]:.0f}); the others read no more than the crosstalk budget (crosstalk.json)\n")
    out.write(f"# reading {n} cycles with nothing touching the array\n")
    out.flush()


def _rest_steps(steps: Steps, out, array: ArrayCalibration, bands: Bands, rest: _Means, k: int, n: int) -> None:
    """Taxel k's field at rest: its sign, Bz and lateral field, as a single taxel's (its own field, signed)."""
    s = array.compensator.polarity[k]
    bx, by, bz = rest.own[k]
    bz *= s
    steps.figure(Bx_rest_uT=bx, By_rest_uT=by, Bz_rest_uT=bz, Bxy_rest_uT=math.hypot(bx, by), samples=n)
    allow = bands.sigmas * bands.noise_z / math.sqrt(n) + _build.LSB_Z_UT / 2.0
    check_polarity(steps, bz, allow + bands.earth)
    check_rest(steps, out, bands, bz, rest.full[k], allow)
    check_lateral(steps, bands, bx, by, bands.sigmas * bands.noise_xy / math.sqrt(n) + _build.LSB_XY_UT / 2.0)


def _weight_on(steps: Sequence[Steps], out, args: argparse.Namespace, device, array: ArrayCalibration, judges,
               load, rest: _Means, k: int) -> None:
    """The known weight on taxel k: its rise, and the crosstalk on every other taxel."""
    (bands, budget), (weight, rise) = judges, load
    t = array.layout[k]
    ask(f"place the {weight:g} g weight on taxel {k} (x {t.get('x_mm', math.nan):+.1f} y "
        f"{t.get('y_mm', math.nan):+.1f} mm, address 0x{int(t['i2c_address']):02X}), centred, with nothing else "
        "touching", args.yes)
    if args.simulate:
        device.transport.place_weight(weight, k)
    settle(device, args.settle)
    out.write(f"# reading {args.samples} cycles with {weight:g} g on taxel {k}\n")
    loaded = _mean_cycles(device, array, args.samples)
    s = array.compensator.polarity[k]
    judge_rise(steps[k], bands, weight, rise, s * (loaded.own[k][2] - rest.own[k][2]), loaded.full[k],
               s * rest.own[k][2], args.samples)
    _crosstalk(steps[k], array, bands, budget, weight, rest, loaded, k, args.samples)
    if not args.yes:
        sys.stderr.write(f"take the weight off taxel {k}\n")
    if args.simulate:
        device.transport.place_weight(0.0, k)


def _crosstalk(steps: Steps, array: ArrayCalibration, bands: Bands, budget: Budget, weight: float, rest: _Means,
               loaded: _Means, k: int, n: int) -> None:
    """The crosstalk step of the weight on taxel k: what every other taxel reads, against the budget (module doc)."""
    rows: List[Tuple[float, float, float, int]] = []  # (read, allowed + noise, predicted, taxel)
    figures: Dict[str, Any] = {}
    for i in range(array.taxels):
        if i == k:
            continue
        d = [a - b for a, b in zip(loaded.force[i], rest.force[i])]
        read = 1000.0 * max(abs(d[2]), math.hypot(d[0], d[1]))
        slope = slope_mN_per_uT(array.calibrations[i], rest.own[i])
        noise = bands.sigmas * bands.noise_z * slope * math.sqrt(2.0 / n) + slope * _build.LSB_Z_UT
        allowed, predicted = budget.allowed_mN(i, k, weight)
        rows.append((read, allowed + noise, predicted, i))
        figures[f"crosstalk_taxel_{i:02d}_mN"] = read
    worst = max(rows, key=lambda r: r[0] / r[1])  # the nearest its limit
    steps.figure(crosstalk_max_mN=max(r[0] for r in rows), **figures)
    text = ("nearest its limit taxel {}: {:.2f} mN, allowed {:.2f} mN (budget {:.2f} mN, predicted {:.2f} mN with the "
            "host's compensation); the others: {}").format(
        worst[3], worst[0], worst[1], budget.tolerance_mN, worst[2],
        ", ".join(f"{i} {r:.2f}" for r, _, _, i in rows if i != worst[3]) or "none")
    name = "crosstalk on the others"
    over = [i for r, a, _, i in rows if r > a]
    if not over:
        steps.report(name, True, text)
    else:
        steps.report(name, False, text + ": taxel(s) {} read more than the budget - the compensation does not "
                     "match this board (a magnet upside down, a chip at another address: magfab-readout info), the "
                     "skin couples the taxels (a continuous skin, or tips glued to each other), or the weight touches "
                     "a neighbour".format(", ".join(map(str, over))))


def _verdict(out, steps: Sequence[Steps]) -> int:
    failed = [(k, [j + 1 for j, (_, ok) in enumerate(s.results) if not ok]) for k, s in enumerate(steps)]
    failed = [(k, f) for k, f in failed if f]
    if failed:
        out.write("verdict: FAIL ({})\n".format("; ".join(
            "taxel {}: step{} {}".format(k, "s" if len(f) > 1 else "", ", ".join(map(str, f))) for k, f in failed)))
        return FAILED
    out.write(f"verdict: PASS (all {len(steps)} taxels, {sum(len(s.results) for s in steps)} steps)\n")
    return 0
