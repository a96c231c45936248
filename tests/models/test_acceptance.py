"""The acceptance test: magfab.models.acceptance's bands against an independent evaluation of the
field over a denser grid than its corners, their response to the tolerances, and the readout package's
``check`` command on the simulated sensor (nominal, wrong magnet, upside-down magnet) through the installed
command line."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest
from readout_support import imported, install, make_calibration, ref_decode, write_tree

from magfab import SpecError, derive, parse_spec
from magfab.export.readout import render, validate_acceptance
from magfab.models.acceptance import FORMAT, G0, Tolerances, acceptance, default_weight_g
from magfab.models.field import Magnet, bz_br

PKG = "readout/src/magfab_readout"


@pytest.fixture(scope="module")
def acc(design, pred):
    return acceptance(design, pred)


def bz_G(radius, height, br, d):
    return np.asarray(bz_br(Magnet(radius, height, br), np.asarray(d, dtype=float), 0.0, model="exact")[0])


# --- the bands ------------------------------------------------------------------------------------------------

def test_output_is_json_deterministic_and_self_consistent(design, pred, acc):
    text = json.dumps(acc, allow_nan=False, sort_keys=True)
    assert json.loads(text) == acc
    assert json.dumps(acceptance(design, pred.as_json()), allow_nan=False, sort_keys=True) == text  # data alone
    assert acc["format"] == FORMAT == "magfab-acceptance/1" and acc["spec_name"] == "magone"
    rest, weight = acc["rest"]["Bz_uT"], acc["weight"]["delta_Bz_uT"]
    assert acc["rest_Bz_uT"] == [rest["min"], rest["max"]] and acc["delta_Bz_uT"] == [weight["min"], weight["max"]]
    assert acc["weight_g"] == acc["weight"]["weight_g"] == default_weight_g(pred.as_json()) == 50.0
    assert acc["weight"]["force_N"] == pytest.approx(0.05 * G0)
    assert acc["rest"]["sign"] == 1 and "north pole up" in acc["rest"]["orientation"]
    names = {a["name"] for a in acc["assumptions"]}
    assert {"remanence_T", "magnet_diameter_mm", "magnet_height_mm", "printer_mm", "glue_fraction", "sensing_depth_mm",
            "chip_height_mm", "seating_mm", "sensitivity_pct", "earth_field_uT"} <= names
    assert all(a["source"].strip() for a in acc["assumptions"])
    table = acc["weight"]["table"]
    k = table["force_N"].index(acc["weight"]["force_N"])  # the weight's own force is a table row
    assert [table[c][k] for c in ("delta_Bz_min_uT", "delta_Bz_max_uT")] == acc["delta_Bz_uT"]
    assert all(np.diff(table["force_N"]) > 0) and table["delta_Bz_max_uT"][0] == 0.0


def test_bands_contain_the_prediction(pred, acc):
    field = pred.as_json()["field"]
    lo, hi = acc["rest_Bz_uT"]
    assert lo < field["Bz_rest_G"] * 100 < hi
    assert acc["rest"]["Bz_uT"]["nominal"] == pytest.approx(field["Bz_rest_G"] * 100, rel=1e-4)
    # The prediction's own band (material soft..stiff x magnet low..high, at the nominal distance), from its
    # arrays: force -> magnet travel (normal curves) -> Bz along the normal curve.
    u, force = pred.arrays["u"], 0.05 * G0
    dlo, dhi = acc["delta_Bz_uT"]
    rises = {}
    for material, curve in pred.curves.items():
        travel = np.interp(force, curve.force_N, u)
        for band in ("low", "nominal", "high"):
            bz = pred.arrays[f"bz_{band}"]
            rises[material, band] = 100 * (np.interp(travel, u, bz) - bz[0])
    assert all(dlo < r < dhi for r in rises.values()), (rises, dlo, dhi)
    assert acc["weight"]["delta_Bz_uT"]["nominal"] == pytest.approx(rises["nominal", "nominal"], rel=0.01)
    assert acc["weight"]["prediction_delta_Bz_uT"] == pytest.approx(rises["nominal", "nominal"], rel=0.01)


def test_corners_hold_the_extremes_of_a_denser_grid(design, acc):
    """Three levels of remanence, diameter and height and seven distances (the box around every corner) give
    nothing outside the band, and its extremes are the band's ends: the field is monotonic over the box."""
    R, H = design.magnet_radius_mm, design.magnet_height_mm
    rem = acc["magnet"]["remanence_T"]
    dist = acc["rest"]["distance_mm"]
    g_lo, g_hi = acc["rest"]["gain"]
    earth = acc["rest"]["earth_field_uT"]
    levels = [np.linspace(rem["low"], rem["high"], 3), np.linspace(R - 0.025, R + 0.025, 3),
              np.linspace(H - 0.05, H + 0.05, 3)]
    ds = np.linspace(dist["min"], dist["max"], 7)
    rest = np.array([bz_G(r, h, br, ds) for br, r, h in itertools.product(*levels)]) * 100
    lo, hi = acc["rest"]["worst_case_Bz_uT"]
    assert rest.min() * g_lo - earth == pytest.approx(lo, abs=0.01)
    assert rest.max() * g_hi + earth == pytest.approx(hi, abs=0.01)
    # the band the check uses (root-sum-square of the effects) lies inside the worst case, around the nominal
    rss_lo, rss_hi = acc["rest_Bz_uT"]
    assert lo < rss_lo < acc["rest"]["Bz_uT"]["nominal"] < rss_hi < hi
    # the known weight: every material's travel at 50 g, the same box
    travel = acc["weight"]["travel_mm"]
    rises = []
    for (br, r, h), u in itertools.product(itertools.product(*levels), travel.values()):
        rises.append(100 * (bz_G(r, h, br, ds - u) - bz_G(r, h, br, ds)))
    rises = np.array(rises)
    dlo, dhi = acc["delta_Bz_uT"]
    assert rises.min() * g_lo == pytest.approx(dlo, abs=0.01) and rises.max() * g_hi == pytest.approx(dhi, abs=0.01)
    assert travel["soft"] > travel["nominal"] > travel["stiff"] > 0


def test_distance_band_is_the_sum_of_the_stack_up(design, acc):
    stack = acc["rest"]["stack_mm"]
    assert stack["pad thickness"] == stack["pocket roof (mould core length)"] == [-0.1, 0.1]  # SLA: 0.2/2 > 0.05
    assert stack["glue thickness"] == [-0.05, 0.05] and stack["Hall point: sensing depth"] == [-0.15, 0.15]
    dist = acc["rest"]["distance_mm"]
    # closest: a 0.05 mm taller magnet (it fills the pocket, so it cannot sit lower); furthest: a 0.05 mm shorter
    # one with its top at the roof
    assert dist["min"] == pytest.approx(design.d_rest_mm + sum(v[0] for v in stack.values()) - 0.05, abs=1e-9)
    assert dist["max"] == pytest.approx(design.d_rest_mm + sum(v[1] for v in stack.values()) + 0.05, abs=1e-9)
    assert next(a for a in acc["assumptions"] if a["name"] == "chip_height_mm")["rest_Bz_uT"][0] == \
        next(a for a in acc["assumptions"] if a["name"] == "chip_height_mm")["rest_Bz_uT"][1]  # no effect (doc)


ZERO = Tolerances(magnet_diameter_mm=0.0, magnet_height_mm=0.0, printer_mm=0.0, glue_fraction=0.0,
                  sensing_depth_mm=(0.0, 0.0), solder_standoff_mm=(0.0, 0.0), seating_mm=0.0,
                  sensitivity_pct=(0.0, 0.0), ambient_C=(20.0, 20.0), earth_field_uT=0.0)


def width(a):
    return a["rest_Bz_uT"][1] - a["rest_Bz_uT"][0], a["delta_Bz_uT"][1] - a["delta_Bz_uT"][0]


def test_band_widths_follow_the_tolerances(design, pred, acc):
    nominal = acc["rest"]["Bz_uT"]["nominal"]
    rem = acc["magnet"]["remanence_T"]
    # No tolerance at all: the rest band is the nominal prediction itself.
    none = acceptance(design, pred, tolerances=replace(ZERO, remanence_T=(rem["nominal"], rem["nominal"])))
    assert none["rest_Bz_uT"] == pytest.approx([nominal, nominal], abs=0.002)
    # The remanence band alone scales the field: its ends are the grade's ends.
    grade = acceptance(design, pred, tolerances=ZERO)
    assert grade["rest_Bz_uT"] == pytest.approx([nominal * rem["low"] / rem["nominal"],
                                                 nominal * rem["high"] / rem["nominal"]], rel=1e-6)
    wider = acceptance(design, pred, tolerances=replace(ZERO, remanence_T=(1.10, 1.30)))
    assert wider["rest_Bz_uT"][0] < grade["rest_Bz_uT"][0] and wider["rest_Bz_uT"][1] > grade["rest_Bz_uT"][1]
    assert wider["delta_Bz_uT"][0] < grade["delta_Bz_uT"][0] and wider["delta_Bz_uT"][1] > grade["delta_Bz_uT"][1]
    # Every tolerance widens both bands; the Earth's field widens the rest band by twice itself and not the rise.
    base = width(acc)
    for change in ({"magnet_height_mm": 0.1}, {"printer_mm": 0.2}, {"glue_fraction": 1.0},
                   {"sensitivity_pct": (5.0, 5.0)}, {"sensing_depth_mm": (0.3, 0.3)}, {"seating_mm": 0.2}):
        w = width(acceptance(design, pred, tolerances=replace(Tolerances(), **change)))
        assert w[0] > base[0] and w[1] > base[1], change
    earthy = acceptance(design, pred, tolerances=Tolerances(earth_field_uT=165.0))
    assert width(earthy)[0] == pytest.approx(base[0] + 200.0, abs=0.01) and width(earthy)[1] == base[1]
    # The printer's tolerance comes from printers.toml: an FDM pad and core (0.15 mm layers) widen the band.
    fdm = derive(parse_spec('name = "magone"\n[mould]\nprinter = "fdm"\n'))
    fdm_acc = acceptance(fdm, pred)
    assert fdm_acc["rest"]["stack_mm"]["pad thickness"] == [-0.15, 0.15]
    assert width(fdm_acc)[0] > base[0]


def test_the_weight_and_its_limits(design, pred, acc):
    bands = [acceptance(design, pred, weight_g=w)["delta_Bz_uT"] for w in (20.0, 50.0, 100.0)]
    assert bands[1] == acc["delta_Bz_uT"]
    assert bands[0][0] < bands[1][0] < bands[2][0] and bands[0][1] < bands[1][1] < bands[2][1]
    with pytest.raises(ValueError, match=r"beyond the predicted range .* use a lighter weight"):
        acceptance(design, pred, weight_g=500.0)
    with pytest.raises(ValueError, match="positive number of grams"):
        acceptance(design, pred, weight_g=-1.0)


def test_which_magnet_grades_the_rest_band_tells_apart(design, acc):
    """Numerically: an N52 magnet where the spec says N35 (remanence 1.44 vs 1.195 T, +20.5 %) reads 22.6 mT at
    the nominal stack-up. That is inside the every-corner worst case (14.3-25.3 mT: the stack-up alone moves the
    distance 5.48-6.45 mm) but outside the root-sum-square band the check uses (about -10/+11 %); N42 (+8.8 %)
    stays inside it. A ferrite-strength magnet (0.4 T) is far below either."""
    R, H, d = design.magnet_radius_mm, design.magnet_height_mm, design.d_rest_mm
    lo, hi = acc["rest_Bz_uT"]
    w_lo, w_hi = acc["rest"]["worst_case_Bz_uT"]
    n52 = float(bz_G(R, H, 1.44, [d])[0]) * 100
    assert acc["grades"]["N52"]["rest_Bz_uT"] == pytest.approx(n52, abs=0.01)
    assert hi < n52 < w_hi and not acc["grades"]["N52"]["inside_rest_band"]
    assert acc["rest"]["grades_inside_band"] == ["N35", "N42"]
    dist = acc["rest"]["distance_mm"]
    assert float(bz_G(R, H, 1.195, [dist["min"]])[0]) * 100 > n52  # the closest stack-up alone outdoes N52
    assert float(bz_G(R, H, 0.40, [d])[0]) * 100 < w_lo < lo


def test_bxy_bound(acc):
    bound = acc["rest"]["Bxy_max_uT"]
    assert acc["rest"]["lateral_offset_mm"] == pytest.approx(0.4) and 5.0 < acc["rest"]["tilt_deg"] < 7.0
    # an upper bound: the radial gradient at rest (36 G/mm) x 0.4 mm plus a tilt, well below Bz at rest
    assert 0.4 * 36.3 * 100 < bound < 0.25 * acc["rest_Bz_uT"][0]


def test_rotation_band_is_the_earth_turned_over_plus_the_tips_own_weight(design, pred, acc):
    """Turned over, the band is twice the Earth band's strongest field (65 uT: 130 uT) plus the fingertip's own
    weight reversed (the magnet's rho g V and half the silicone's, x the weight table's steepest rise per newton);
    the check adds the noise terms. A stated weaker place shrinks the Earth part only; the force it is worth scales
    the drift budget's turned-over figure."""
    from magfab.models.acceptance_steps import self_weight_N

    rot = acc["rotation"]
    magnet_N, silicone_N = self_weight_N(design)
    assert magnet_N == pytest.approx(7.5e-6 * design.magnet_volume_mm3 * G0)
    table = acc["weight"]["table"]
    slope = (table["delta_Bz_max_uT"][1] - table["delta_Bz_max_uT"][0]) / table["force_N"][1]
    own = 2.0 * (magnet_N + silicone_N / 2.0) * slope
    assert rot["earth_change_uT"] == pytest.approx(2 * 65.0) and \
        rot["self_weight_change_uT"] == pytest.approx(own, rel=1e-3)
    assert rot["band_uT"] == pytest.approx(130.0 + own, rel=1e-3)
    assert rot["predicted_normal_rest_mN"] == pytest.approx(abs(pred.drift.rotation_band[1].normal_rest_mN), rel=1e-3)
    assert rot["gradient_uT_per_mm"] == pytest.approx(pred.field.dBz_dz_rest_G_per_mm * 100, rel=1e-4)
    from magfab.spec import Environment

    quiet = design.spec.model_copy(update={"environment": Environment(earth_field_G=0.4)})
    there = acceptance(derive(quiet), pred)["rotation"]
    assert there["earth_change_uT"] == pytest.approx(80.0) and \
        there["self_weight_change_uT"] == rot["self_weight_change_uT"]
    assert there["predicted_normal_rest_mN"] == pytest.approx(rot["predicted_normal_rest_mN"] * 80 / 130, rel=1e-3)


def test_warmup_band_is_the_drift_budgets_per_degree(pred, acc):
    """The warm-up's per-degree figures are the drift budget's at rest (with: the recipe coefficients, fitted: a
    calibration fitted over temperature, without: none), the noise its resolution; the band scales with them."""
    w = acc["warmup"]
    per_C = pred.drift.temperature.per_C["normal_rest"]
    assert w["per_C_mN"] == {k: pytest.approx(abs(per_C[k]), abs=1e-4) for k in ("without", "with", "fitted")}
    assert w["per_C_mN"]["fitted"] < w["per_C_mN"]["with"] < w["per_C_mN"]["without"]
    assert w["noise_mN"] == pytest.approx(pred.normal.resolution_mN, abs=1e-4) and w["min_change_C"] == 4.0
    assert w["magnet_pct_per_C"] == pytest.approx(-0.12)
    # the budget's calibration at rest (mN per uT), which the check rescales to the sensor's own: its inverse's slope
    ch = pred.drift.channel
    slope = 1e3 * float(ch.force_N(ch.field_at(0.0) + 0.01) - ch.force_N(ch.field_at(0.0))) / 1.0
    assert w["channel_mN_per_uT"] == pytest.approx(slope, rel=0.02)
    from magfab.models.acceptance_steps import warmup_section

    assert warmup_section({**pred.as_json(), "drift": None}) is None


# --- the readout package ----------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def rendered(design, acc):
    return render(design, make_calibration(), acc)


def test_render_embeds_acceptance_and_stays_compatible(design, acc, rendered):
    assert json.loads(rendered[f"{PKG}/acceptance.json"]) == acc
    plain = render(design, make_calibration())
    assert set(rendered) - set(plain) == {f"{PKG}/acceptance.json"}
    assert {k: v for k, v in rendered.items() if k.endswith(".py")} == {k: v for k, v in plain.items()
                                                                         if k.endswith(".py")}
    readme = rendered["readout/README.md"].decode()
    assert "magfab-readout check" in readme and f"{acc['rest_Bz_uT'][0]:.0f} to {acc['rest_Bz_uT'][1]:.0f} uT" in readme
    assert render(design, make_calibration(), acc) == rendered


@pytest.mark.parametrize("change, key", [
    (lambda a: a.update(format="magfab-acceptance/2"), "acceptance.json:format"),
    (lambda a: a["rest"]["Bz_uT"].update(max=float("nan")), "acceptance.json"),
    (lambda a: a["rest"].pop("Bxy_max_uT"), "acceptance.json:rest.Bxy_max_uT"),
    (lambda a: a["weight"]["table"]["force_N"].reverse(), "acceptance.json:weight.table.force_N"),
    (lambda a: a["weight"]["table"]["delta_Bz_max_uT"].pop(), "acceptance.json:weight.table"),
    (lambda a: a["magnet"].update(grade=35), "acceptance.json:magnet.grade"),
    (lambda a: a["rotation"].pop("band_uT"), "acceptance.json:rotation.band_uT"),
    (lambda a: a["rotation"].update(predicted_normal_rest_mN="40"),
     "acceptance.json:rotation.predicted_normal_rest_mN"),
    (lambda a: a["warmup"]["per_C_mN"].pop("fitted"), "acceptance.json:warmup.per_C_mN.fitted"),
])
def test_malformed_acceptance_is_refused_by_key(design, acc, change, key):
    bad = json.loads(json.dumps(acc))
    change(bad)
    with pytest.raises(SpecError) as err:
        render(design, make_calibration(), bad)
    assert err.value.key == key, err.value.message
    assert validate_acceptance(acc) == acc


@pytest.fixture(scope="module")
def pkg(rendered, tmp_path_factory):
    with imported(rendered, tmp_path_factory.mktemp("acceptance-src")) as module:
        yield module


def test_simulated_sensor_sends_firmware_frames_of_the_predicted_field(pkg, acc):
    build = sys.modules["magfab_readout._build"]
    calibration = pkg.Calibration.embedded()

    def frames(tip, n=400):
        sim = pkg.SimulatedDevice(realtime=False, chunk=n, text=False, pattern=tip)
        return ref_decode(sim.read(10**6)), sim

    def mean_bz(decoded):
        return sum(f["counts"][2] for f in decoded) / len(decoded) * build.LSB_Z_UT

    nominal = acc["rest"]["Bz_uT"]["nominal"]
    decoded, sim = frames(pkg.RestTip.from_acceptance(acc))
    assert mean_bz(decoded) == pytest.approx(nominal, abs=2.0)
    for f in decoded[:20]:  # the forces are the embedded calibration's at the quantised field, as the firmware's
        B = (f["counts"][0] * build.LSB_XY_UT, f["counts"][1] * build.LSB_XY_UT, f["counts"][2] * build.LSB_Z_UT)
        want = calibration.evaluate(*B, method="poly")
        assert f["forces"] == pytest.approx(want, rel=1e-6, abs=1e-6)
    sim.place_weight(50.0)
    loaded = ref_decode(sim.read(10**6))
    assert mean_bz(loaded) - mean_bz(decoded) == pytest.approx(acc["weight"]["delta_Bz_uT"]["nominal"], abs=3.0)
    flipped, _ = frames(pkg.RestTip.from_acceptance(acc, flipped=True))
    assert mean_bz(flipped) == pytest.approx(-nominal, abs=2.0)
    n52, _ = frames(pkg.RestTip.from_acceptance(acc, scale=1.44 / 1.195))
    assert mean_bz(n52) == pytest.approx(acc["grades"]["N52"]["rest_Bz_uT"], abs=2.0)
    with pytest.raises(ValueError, match="press pattern"):
        pkg.SimulatedDevice(realtime=False).place_weight(10.0)


@pytest.fixture(scope="module")
def installed(rendered, tmp_path_factory):
    """The package with acceptance.json pip-installed into a fresh virtual environment."""
    return install(rendered, tmp_path_factory.mktemp("acceptance-venv"))


FAST = ("--samples", "150", "--settle", "0.1")


def check(installed, *args, stdin=None):
    feed = {"input": stdin} if stdin is not None else {"stdin": subprocess.DEVNULL}
    return subprocess.run([str(installed.script), "check", "--simulate", *FAST, *args], capture_output=True,
                          text=True, timeout=60, **feed)


def steps(stdout: str) -> dict:
    out = {}
    for line in stdout.splitlines():
        if line.startswith("step "):
            parts = line.split()
            out[int(parts[1])] = line
    return out


def test_installed_check_passes_on_the_simulated_sensor(installed, acc):
    proc = check(installed, "--yes")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    lines = steps(proc.stdout)
    assert len(lines) == 4 and all(" PASS " in line for line in lines.values())
    assert "verdict: PASS (all 4 steps)" in proc.stdout
    lo, hi = acc["rest_Bz_uT"]
    assert f"predicted {lo:.0f} .. {hi:.0f} uT (nominal {acc['rest']['Bz_uT']['nominal']:.0f})" in lines[2]
    measured = float(lines[2].split("measured ")[1].split(" uT")[0])
    assert measured == pytest.approx(acc["rest"]["Bz_uT"]["nominal"], abs=3.0)
    dlo, dhi = acc["delta_Bz_uT"]
    assert "rise of Bz under 50 g" in lines[4] and f"predicted {dlo:.0f} .. {dhi:.0f} uT" in lines[4]
    assert "place the 50 g weight on the tip" in proc.stderr
    # interactive: Enter on stdin puts the (simulated) weight on
    proc = check(installed, stdin="\n")
    assert proc.returncode == 0 and "press Enter" in proc.stderr, proc.stdout + proc.stderr
    proc = check(installed)  # no terminal, no --yes: says what to do
    assert proc.returncode == 2 and "no answer on stdin" in proc.stderr and "--yes" in proc.stderr


def test_installed_check_fails_on_an_upside_down_magnet(installed):
    proc = check(installed, "--yes", "--simulate-flipped")
    assert proc.returncode == 3  # the sensor failed: the check's verdict, not an error
    lines = steps(proc.stdout)
    assert " FAIL " in lines[1] and "the magnet is upside down" in lines[1] and "measured -" in lines[1]
    assert " FAIL " in lines[2] and "upside down" in lines[2]
    assert " FAIL " in lines[4] and "Bz fell under the weight - the magnet is upside down" in lines[4]
    assert "verdict: FAIL (steps 1, 2, 4 of 4)" in proc.stdout


def test_installed_check_on_other_magnets(installed, acc):
    # N52 instead of N35 fails the rest band (see test_which_magnet_grades_the_rest_band_tells_apart) ...
    proc = check(installed, "--yes", "--no-weight", "--simulate-grade", "N52")
    assert proc.returncode == 3, proc.stdout
    assert "stronger than predicted" in steps(proc.stdout)[2]
    # ... N42 passes: the band cannot tell N35 and N42 apart, and the check says so
    proc = check(installed, "--yes", "--no-weight", "--simulate-grade", "N42")
    assert proc.returncode == 0, proc.stdout
    assert "means a remanence of 1.30 T" in proc.stdout and "cannot tell those apart" in proc.stdout
    # a ferrite-strength magnet (0.4 T) and an impossible 1.8 T one fail the rest band, each with its cause
    proc = check(installed, "--yes", "--simulate-grade", "0.4")
    assert proc.returncode == 3
    lines = steps(proc.stdout)
    assert " PASS " in lines[1] and " FAIL " in lines[2] and "weaker than predicted" in lines[2]
    assert " FAIL " in lines[4] and "smaller rise than predicted" in lines[4]
    proc = check(installed, "--yes", "--no-weight", "--simulate-grade", "1.8")
    assert proc.returncode == 3 and "stronger than predicted - a stronger grade than N35" in steps(proc.stdout)[2]
    assert len(steps(proc.stdout)) == 3 and "verdict: FAIL (step 2 of 3)" in proc.stdout


def test_installed_check_weight_and_usage(installed, acc):
    proc = check(installed, "--yes", "--weight-g", "20")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    line = steps(proc.stdout)[4]
    band = acceptance_band_at(acc, 20.0)
    assert "rise of Bz under 20 g" in line and f"predicted {band[0]:.0f} .. {band[1]:.0f} uT" in line
    # 320 g: the soft material's range, 3.14 N, ended by the 3 mm scan depth (the default law, Ecoflex 00-30's Yeoh
    # fit; the neo-Hookean law's data end at 1.03 N, 105 g)
    for args, message in ((("--weight-g", "500"), "covers weights up to 320 g"),
                          (("--simulate-grade", "N99"), "give a grade (N35, N42, N45, N52) or a remanence"),
                          (("--samples", "0"), "--samples must be at least 1")):
        proc = check(installed, "--yes", *args)
        assert proc.returncode == 2 and message in proc.stderr, (args, proc.stderr)
    proc = subprocess.run([str(installed.script), "check", "--simulate-flipped", "--yes"], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2 and "need --simulate" in proc.stderr


def acceptance_band_at(acc, grams):
    table = acc["weight"]["table"]
    f = grams * G0 / 1000
    return (float(np.interp(f, table["force_N"], table["delta_Bz_min_uT"])),
            float(np.interp(f, table["force_N"], table["delta_Bz_max_uT"])))


def test_check_without_acceptance_data_says_so(design, tmp_path):
    root = write_tree(render(design, make_calibration()), tmp_path)
    proc = subprocess.run([sys.executable, "-m", "magfab_readout", "check", "--simulate", "--yes"],
                          capture_output=True, text=True, timeout=60, cwd=root / "readout" / "src")
    assert proc.returncode == 2 and "carries no acceptance.json" in proc.stderr
