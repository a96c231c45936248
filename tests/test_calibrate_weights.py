"""``magfab calibrate --weights``: a sensor's record gets a model-based calibration with its fitted parameters and
predicted error; a new skin keeps the magnet's and the silicone's parameters, so three weighings do; a build is handed
the model's scan; and every wrong use is one line, exit 2, nothing written."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from dataclasses import replace
from unittest.mock import patch

import numpy as np
import pytest
from calibrate_support import add, tree, weigh_simulated
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab.formats.weights_csv import read_weights_csv, weights_csv
from magfab.models.weighing import RESKIN_KEPT, SensorModel, noise_uT, reskin_plan, weight_plan
from magfab.models.weighing_study import draw_sensor, truth_model, weighings


@pytest.fixture(scope="module")
def sensor_and_plan(magone_design, magone_prediction, magone_neo_hookean):
    """A drawn MagOne sensor of the other law (tests/models/test_weighing.py) and the plan's weighings of it."""
    model = SensorModel.of(magone_design, magone_prediction)
    truth = truth_model(magone_design, magone_prediction, model, magone_neo_hookean[1])
    rng = np.random.default_rng(7)
    sensor = draw_sensor(model, truth, rng)
    plan = weight_plan(magone_prediction, 5.0)
    return sensor, plan, noise_uT(magone_design), rng


def _write(path, sensor_and_plan, plan=None):
    sensor, full, noise, rng = sensor_and_plan
    path.write_text(weights_csv(weighings(sensor, plan or full, noise, rng), ["simulated"]))


def test_a_sensor_is_calibrated_from_weights_and_a_new_skin_from_three(bench, sensor_and_plan):
    project, out, calls, run = bench
    sensor = add(project, out, "finger-01")
    _write(project / "weights.csv", sensor_and_plan)
    before = tree(out)
    result = run("calibrate", "--weights", "weights.csv", "--sensor", "finger-01", "--out", str(out))
    assert result.exit_code == 0, result.output
    assert "predicted error over the region (9 in 10): Fz RMS" in result.output
    assert calls == [] and tree(out) == before
    event, cal = sensor.current_calibration()
    model = cal["scan"]["model"]
    assert model["weighings"] == 12 and model["kept"] == [] and set(model["theta"]) >= set(RESKIN_KEPT)
    assert event["predicted_error_Fz_mN"] == model["predicted_error_mN"]["Fz_rms"]["p90"] > 0
    assert sensor.file(event["files"]["weights.csv"]) == (project / "weights.csv").read_bytes()
    first = model["theta"]
    # a new skin: three weighings, the magnet's and the silicone's parameters kept from the first skin's fit
    assert run("sensor", "reskin", "finger-01").exit_code == 0
    _write(project / "skin2.csv", sensor_and_plan, reskin_plan(sensor_and_plan[1]))
    result = run("calibrate", "--weights", "skin2.csv", "--sensor", "finger-01", "--out", str(out))
    assert result.exit_code == 0, result.output
    _, cal2 = sensor.current_calibration()
    again = cal2["scan"]["model"]
    assert again["weighings"] == 3 and again["kept"] == sorted(RESKIN_KEPT)
    assert all(again["theta"][k] == pytest.approx(first[k], abs=1e-8) for k in RESKIN_KEPT)


def test_a_build_is_handed_the_models_scan(bench, sensor_and_plan):
    _, out, calls, run = bench
    _write(out / "weights.csv", sensor_and_plan)
    result = run("calibrate", "--weights", str(out / "weights.csv"), "--out", str(out))
    assert result.exit_code == 0, result.output
    (_, scan), = calls
    assert scan.model["weighings"] == 12 and scan.source.startswith("weights.csv (weight calibration")
    assert scan.rows > 1000 and scan.F_N is not None


@pytest.mark.parametrize("args, says", [
    (("scan.csv", "--weights", "weights.csv"), "give a SCAN, or --weights FILE"),
    ((), "give a SCAN, or --weights FILE"),
    (("--weights", "weights.csv", "--reference", "ref.csv"), "without --reference"),
    (("--weights", "weights.csv", "--taxel", "0"), "without --reference and --taxel"),
    (("--weights", "missing.csv"), "missing.csv: cannot read the weighings CSV"),
    (("--weights", "bad.csv"), "bad.csv: line 3 (row 2), column 'angle_deg'"),
    (("--weights", "heavy.csv"), "heavy.csv: weighing 4, 5005 g at 0 deg, pushes 49.1 N"),
    (("--weights", "n52.csv"), "n52.csv (weight calibration, 12 weighings): its field at rest"),
    (("--weights", "flat.csv"),
     "flat.csv: 4 weighings of 4 distinct loads, 0 of them on a stand tilted 10 deg or more: a first weight "
     "calibration needs at least 6"),
])
def test_a_wrong_use_is_one_line_and_writes_nothing(bench, sensor_and_plan, args, says):
    project, out, calls, run = bench
    _write(project / "weights.csv", sensor_and_plan)
    lines = (project / "weights.csv").read_text().splitlines()[1:]  # the header on line 1
    heavy = lines[:]
    heavy[4] = ",".join(["5005", *heavy[4].split(",")[1:]])  # weighing 4: 5 kg on the tip
    (project / "heavy.csv").write_text("\n".join(heavy) + "\n")
    parts = lines[2].split(",")
    parts[1] = "95"  # row 2's stand angle past 80 degrees
    lines[2] = ",".join(parts)
    (project / "bad.csv").write_text("\n".join(lines) + "\n")
    sensor, plan, noise, rng = sensor_and_plan
    n52 = replace(sensor, theta=sensor.theta.copy())
    n52.theta[1] = math.log(1.205)  # an N52 magnet (20.5 % more remanence) in the N35 design
    (project / "n52.csv").write_text(weights_csv(weighings(n52, plan, noise, rng)))
    (project / "flat.csv").write_text(weights_csv(weighings(sensor, [p for p in plan if p[1] == 0.0], noise, rng)))
    before = tree(project)
    result = run("calibrate", *args, "--out", str(out))
    assert result.exit_code == 2, result.output
    assert says in result.output and calls == [] and tree(project) == before
    assert len(result.output.strip().splitlines()) == 1


def test_an_arrays_weights_are_refused(tmp_path, monkeypatch, sensor_and_plan):
    from click.testing import CliRunner
    from conftest import EXAMPLES

    from magfab.cli import main

    _write(tmp_path / "weights.csv", sensor_and_plan)
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, ["calibrate", "--weights", "weights.csv", "--spec",
                                       str(EXAMPLES / "strip_1x5.toml"), "--out", str(tmp_path / "new")])
    assert result.exit_code == 2 and "a weight calibration is of a single taxel's sensor" in result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["weights.csv"]


def test_the_report_lists_a_weight_calibrations_fit(magone_design, magone_prediction, sensor_and_plan):
    """calibration.json's scan.model into the report's calibration section: every fitted parameter with its spread,
    the kept ones marked, and the predicted error (the same figures the record's event carries)."""
    from magfab.export.report.tables import calibration_summary
    from magfab.models.calibration import fit
    from magfab.models.weighing import calibration_scan, stated_error

    sensor, plan, noise, rng = sensor_and_plan
    kept = {"log_br": 0.0, "shape_1": 0.01}
    scan, _, bound = calibration_scan(magone_design, magone_prediction, weighings(sensor, plan, noise, rng),
                                      fixed=kept, source="w.csv")
    doc = fit(scan, magone_design, mls=False).calibration.to_json()
    summary = calibration_summary(doc, 5.0)
    assert summary is not None and not summary["provisional"]
    weights = summary["weights"]
    assert weights["weighings"] == 12
    how = {name: mark for name, _, _, mark in weights["parameters"]}
    assert how["br_ratio"] == how["shape_1"] == "kept" and how["mu_ratio"] == how["d_mm"] == "fitted"
    assert len(how) == 10
    assert float(weights["fz"][1]) == stated_error(doc)["predicted_error_Fz_mN"] == round(1000 * bound.fz_rms_N[1], 2)
    assert calibration_summary({**doc, "scan": {k: v for k, v in doc["scan"].items() if k != "model"}},
                               5.0)["weights"] is None


def test_the_readouts_weighings_calibrate_the_sensor(bench):
    """The bench's path end to end: ``magfab-readout weigh`` walks the build's plan on the simulated board (the nominal
    sensor under the jig's loads, with the chip's noise), and ``magfab calibrate --weights`` fits its file; the
    re-skin walks the plan's three steps; a wrong option is one line, exit 2, no file."""
    project, out, calls, run = bench
    plan = json.loads((out / "calibration" / "weigh_plan.json").read_text())
    proc = weigh_simulated(project, out, "w.csv", "--cap-g", "10.5", "--samples", "40", "--dwell-s", "0.1")
    assert proc.returncode == 0, proc.stderr[-2000:]
    rows = read_weights_csv(project / "w.csv")
    assert [(r.angle_deg, round(r.mass_g - 10.5, 6)) for r in rows] == [
        (s["angle_deg"], s["coins"] * plan["coin"]["mass_g"]) for s in plan["steps"]]
    result = run("calibrate", "--weights", "w.csv", "--out", str(out))
    assert result.exit_code == 0, result.output
    (_, scan), = calls
    assert scan.model["weighings"] == len(plan["steps"]) and scan.model["chi2_per_reading"] < 5
    proc = weigh_simulated(project, out, "skin.csv", "--cap-g", "9.8", "--coin-g", "4.1", "--reskin", "--samples", "40",
                  "--dwell-s", "0.1")
    assert proc.returncode == 0, proc.stderr[-2000:]
    steps = [plan["steps"][k] for k in plan["reskin"]]
    assert [(r.angle_deg, round(r.mass_g, 6)) for r in read_weights_csv(project / "skin.csv")] == [
        (s["angle_deg"], round(9.8 + 4.1 * s["coins"], 6)) for s in steps]
    before = (project / "w.csv").read_bytes()
    for args, says in ((("bad.csv", "--cap-g", "0"), "--cap-g 0.0: must be a positive number of grams"),
                       (("bad.csv", "--cap-g", "10", "--samples", "1"), "--samples must be at least 2"),
                       (("bad.csv", "--cap-g", "1e9"), "this build's cap weighs at most about"),
                       (("bad.csv", "--cap-g", "10", "--coin-g", "7.8"), "at most the plan's coin, 5 g"),
                       (("bad.csv", "--cap-g", "10", "--samples", "5000", "--settle-s", "5"), "two windows of 5000"),
                       (("w.csv", "--cap-g", "10"), "w.csv exists: weighings are not overwritten")):
        proc = weigh_simulated(project, out, *args)
        assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and says in proc.stderr, proc.stderr
        assert not (project / "bad.csv").exists() and (project / "w.csv").read_bytes() == before
    # no answer at the first prompt (end of input): one line, and no file that looks like a session
    env = {k: v for k, v in os.environ.items() if k != "MAGFAB_SENSORS"}
    env["PYTHONPATH"] = str(out / "readout" / "src")
    proc = subprocess.run([sys.executable, "-m", "magfab_readout", "weigh", "eof.csv", "--cap-g", "10", "--simulate"],
                          capture_output=True, text=True, timeout=300, env=env, cwd=project, stdin=subprocess.DEVNULL)
    assert proc.returncode == 2 and proc.stderr.splitlines()[-1].startswith("magfab-readout: error: no answer")
    assert not (project / "eof.csv").exists()


def test_the_report_charts_the_study(default_build):
    """Every single-taxel build charts the study (magfab/weights_bench.json: fifty sensors a row, as bench/weights.py
    saved them, its command without any machine's path) into its calibration section, the same bytes twice."""
    from magfab.export import weights_figures

    rows = weights_figures.bench_rows()
    assert len(rows) == 12 and {r["adaptive"] for r in rows} == {True, False}
    assert all(len(r["ratios"]) == len(r["reskin_ratios"]) == r["sensors"] == 50 for r in rows)
    assert all(r["command"].startswith("python bench/weights.py") and "--out" not in r["command"] for r in rows)
    assert weights_figures.figures(rows) == weights_figures.figures(rows)
    paths = {a.path for a in default_build.artifacts}
    assert {"calibration/weights_study.svg", "calibration/weights_study.png"} <= paths
    report = (default_build.out_dir / "report.html").read_text()
    assert "fig-calibration-weights_study" in report


# --- the guards against generated variants of their mistakes -----------------------------------------------------

#: A factor on an option's limit: just inside or just past it (by a drawn margin, from a billionth to nearly all of
#: it), or zero, negative, far too large, not finite.
_FACTOR = st.one_of(
    st.builds(lambda margin, past: 1.0 + margin if past else 1.0 - margin,
              st.sampled_from([1e-9, 1e-3, 0.05, 0.25, 0.5, 0.99]), st.booleans()),
    st.sampled_from([0.0, -0.0, -1.0, 1e6, math.inf, -math.inf, math.nan]))


_OPTIONS = ("--cap-g", "--coin-g", "--dwell-s", "--settle-s", "--samples")


@settings(max_examples=300, deadline=None)
@given(mistaken=st.lists(st.sampled_from(_OPTIONS), max_size=2).map(set), data=st.data(), exists=st.booleans(),
       force=st.booleans())
def test_weighs_options_are_refused_exactly_when_the_plan_cannot_take_them(
        weigh_package, tmp_path_factory, mistaken, data, exists, force):
    """``magfab-readout weigh``'s options, sound (left out, or inside their limits) but for one or two, each of those
    its limit scaled about 1, or zero, negative, not finite, far too large: refused in one UsageError exactly when
    one of them breaks its rule (the cap within twice its printed bound, the coin no heavier than the plan's, two
    windows inside the settle time at the chip's rate, no existing file overwritten without --force), naming an
    option that broke it."""
    sound = st.one_of(st.none(), st.floats(0.05, 1.0))
    cap, coin, dwell, settle = (data.draw(_FACTOR if flag in mistaken else sound, label=flag) for flag in _OPTIONS[:4])
    cap = 0.5 if cap is None and "--cap-g" not in mistaken else cap  # the cap's mass has no default
    if "--cap-g" in mistaken and data.draw(st.booleans(), label="--cap-g left out"):
        cap = None
    mistakes = st.one_of(st.integers(-5, 3), st.integers(4, 20000))
    samples = data.draw(mistakes if "--samples" in mistaken else st.one_of(st.none(), st.integers(2, 400)),
                        label="--samples")
    if "--settle-s" not in mistaken and settle is not None:
        settle = 1.0 / settle  # at or past the two windows' and the dwell's time
    out = tmp_path_factory.mktemp("weigh") / "w.csv"
    if exists:
        out.write_text("kept\n")
    plan = weigh_package.plan
    bound, coin_g, rate = plan["cap_mass_bound_g"], plan["coin"]["mass_g"], weigh_package.build.SAMPLE_RATE_HZ
    argv = ["weigh", str(out)]
    if samples is not None:
        argv += [f"--samples={samples}"]
    n = 200 if samples is None else samples
    # each factor scales the option's limit: the cap's (twice its bound), the coin's, the settle time two windows
    # and the dwell take, and a dwell of 2 s
    dwell_s = None if dwell is None else 2.0 * dwell
    need = (2.0 if dwell_s is None or not math.isfinite(dwell_s) else dwell_s) + 2.0 * max(n, 0) / rate
    for flag, factor, limit in (("--cap-g", cap, 2.0 * bound), ("--coin-g", coin, coin_g),
                                ("--dwell-s", dwell, 2.0), ("--settle-s", settle, need)):
        if factor is not None:
            argv += [f"{flag}={factor * limit!r}"]
    argv += ["--force"] if force else []
    args = weigh_package.cli._parser().parse_args(argv)
    ok = lambda x: math.isfinite(x) and x > 0
    broken = [flag for flag, bad in (
        ("--cap-g", args.cap_g is None or not ok(args.cap_g) or args.cap_g > 2 * bound),
        ("--coin-g", args.coin_g is not None and (not ok(args.coin_g) or args.coin_g > coin_g)),
        ("--settle-s", not ok(args.settle_s)),
        ("--dwell-s", not (math.isfinite(args.dwell_s) and args.dwell_s >= 0)),
        ("--samples", args.samples < 2)) if bad]
    if not broken and args.dwell_s + 2 * args.samples / rate > args.settle_s:
        broken = ["--settle-s"]
    if not broken and exists and not force:
        broken = [str(out)]
    try:
        coin_used = weigh_package.weigh._check(args, plan)
    except weigh_package.UsageError as e:
        message = str(e)
        assert broken and "\n" not in message and any(flag in message for flag in broken), (message, broken)
    else:
        assert not broken and coin_used == (coin_g if args.coin_g is None else args.coin_g)
    assert not exists or out.read_text() == "kept\n"  # nothing overwritten by the check


@settings(max_examples=150, deadline=None)
@given(picks=st.lists(st.integers(0, 11), min_size=1, max_size=16),
       tilt=st.sampled_from([None, 0.5, 2.0, 5.0, 9.9, 10.0, 15.0]),
       reskin=st.booleans())
def test_too_few_or_too_flat_weighings_are_refused_before_any_fit(
        magone_design, magone_prediction, sensor_and_plan, picks, tilt, reskin):
    """Weighings drawn from the plan's twelve (any number, repeated, in any order), their tilted stands turned down
    to a few degrees: a first calibration is refused, before any fit, exactly when they hold fewer than six distinct
    loads or none on a stand tilted 10 degrees or more (too little shear to tell the shear stiffness from the
    normal); a new skin, exactly when they hold fewer than three distinct loads."""
    from magfab.errors import ScanError
    from magfab.models import weighing

    sensor, plan, noise, rng = sensor_and_plan
    steps = [(m, a if a == 0.0 or tilt is None else tilt * a / max(q[1] for q in plan)) for m, a in plan]
    drawn = weighings(sensor, [steps[k] for k in picks], noise, rng)
    fixed = dict.fromkeys(RESKIN_KEPT, 0.0) if reskin else None

    class Fitted(Exception):
        pass

    def stop(*args, **kwargs):
        raise Fitted

    loads = {steps[k] for k in picks}
    tilted = sum(1 for _, angle in loads if angle >= 10.0)
    refused = len(loads) < 3 if reskin else (len(loads) < 6 or not tilted)
    with patch.object(weighing, "fit_weights", stop), pytest.raises(ScanError if refused else Fitted) as caught:
        weighing.calibration_scan(magone_design, magone_prediction, drawn, fixed=fixed, source="w.csv")
    if refused:
        assert str(caught.value).startswith(f"w.csv: {len(drawn)} weighings of {len(loads)} distinct loads")
