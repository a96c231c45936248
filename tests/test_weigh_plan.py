"""The two-stage weights bench: ``magfab-readout weigh --first`` weighs the build's plan's first two steps,
``magfab weigh-plan`` fits them and writes the plan for the skin's own stiffness, and ``magfab-readout weigh --plan``
walks it. The plan stays inside every drawn skin's range, a stiff skin gets a heavier plan than a soft one, and every
wrong use is one line, exit 2, nothing written."""

from __future__ import annotations

import copy
import json
import math
import subprocess
import sys

import numpy as np
import pytest
from calibrate_support import tree, weigh_simulated
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from test_fuzz_readers import paths

from magfab.export.weigh_plan import adapted_plan, stiffest_skin
from magfab.formats.weights_csv import read_weights_csv, weights_csv
from magfab.jig import coin_layout, jig_of, jig_plans
from magfab.models.weighing import SensorModel, first_weighings, load_of, noise_uT
from magfab.models.weighing_study import draw_sensor, truth_model, weighings


@pytest.fixture(scope="module")
def drawn(magone_design, magone_prediction, magone_neo_hookean):
    """MagOne's model, a truth of the other law, the build's plan's first two weighings and the chip's noise."""
    model = SensorModel.of(magone_design, magone_prediction)
    truth = truth_model(magone_design, magone_prediction, model, magone_neo_hookean[1])
    first = first_weighings(jig_plans(magone_design, magone_prediction)(1.0))
    return model, truth, first, noise_uT(magone_design)


def _sensor(drawn, seed: int, log_mu: float | None = None, centred: bool = False):
    model, truth, _, _ = drawn
    sensor = draw_sensor(model, truth, np.random.default_rng(seed), centred)
    if log_mu is not None:
        sensor.theta[0] = log_mu
    return sensor


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), centred=st.booleans(), edge=st.sampled_from([None, -2.0, 2.0]))
def test_a_skins_plan_stays_inside_its_range(magone_design, magone_prediction, drawn, seed, centred, edge):
    """Sensors drawn across the bands (the other law, the magnet tilted and offset or centred, the Earth's field,
    the chip's noise; the skin also at either end of its band): the plan made from their first two weighings keeps
    every load's normal and shear parts inside the drawn skin's ranges (the softest skin's times its stiffness),
    and is never lighter than the softest skin's plan."""
    model, _, first, noise = drawn
    mean, sigma = model.prior.mean[0], model.prior.sigma[0]
    sensor = _sensor(drawn, seed, None if edge is None else mean + edge * sigma, centred)
    rng = np.random.default_rng(seed)
    doc = adapted_plan(magone_design, magone_prediction, weighings(sensor, first, noise, rng), "first.csv", "")
    soft = float(magone_prediction.curves["soft"].mu_kPa) / float(magone_prediction.curves["nominal"].mu_kPa)
    stiffness = math.exp(float(sensor.theta[0])) / soft
    jig = jig_of(magone_design)
    cap = jig.cap_mass_bound_g()
    masses = [cap + s["coins"] * jig.coin_g for s in doc["steps"]]
    f = load_of(masses, [s["angle_deg"] for s in doc["steps"]])
    assert np.all(f[:, 2] <= stiffness * magone_prediction.normal.range_N), (doc["stiffness"], stiffness)
    assert np.all(f[:, 1] <= stiffness * magone_prediction.shear.range_N), (doc["stiffness"], stiffness)
    assert 1.0 <= doc["stiffness"] <= round(stiffest_skin(magone_prediction), 4)
    assert max(masses) >= max(m for m, _, _ in jig.plan(magone_prediction))
    assert doc["coins_most"] >= max(s["coins"] for s in doc["steps"])


def test_the_plan_is_made_and_walked_as_the_readme_runs_it(bench, drawn):
    """``magfab weigh-plan`` on a stiff skin's first two weighings writes the jig's plan for the stiffness it states
    (heavier than a soft skin's), which ``magfab-readout weigh --plan`` walks on the simulated board; ``--first``
    walks the build's plan's first two steps."""
    project, out, calls, run = bench
    _, _, first, noise = drawn
    model = drawn[0]
    mean, sigma = model.prior.mean[0], model.prior.sigma[0]
    docs = {}
    for name, log_mu in (("soft", mean - 2 * sigma), ("stiff", mean + 2 * sigma)):
        rng = np.random.default_rng(11)
        (project / f"{name}.csv").write_text(weights_csv(weighings(_sensor(drawn, 11, log_mu), first, noise, rng)))
        result = run("weigh-plan", f"{name}.csv", f"{name}.json", "--out", str(out))
        assert result.exit_code == 0, result.output
        assert f"written to {name}.json" in result.output and calls == []
        docs[name] = json.loads((project / f"{name}.json").read_text())
    soft, stiff = docs["soft"], docs["stiff"]
    assert stiff["stiffness"] > soft["stiffness"] >= 1.0
    heaviest = lambda doc: max(s["coins"] for s in doc["steps"] if s["angle_deg"] == 0.0)
    assert heaviest(stiff) > heaviest(soft)
    from magfab import derive
    from magfab.models.predict import predict
    from magfab.spec import load_build_spec

    design = derive(load_build_spec(out))
    plan = jig_of(design).plan(predict(design), stiffness=stiff["stiffness"])
    assert [(s["angle_deg"], s["coins"]) for s in stiff["steps"]] == [(a, n) for _, a, n in plan]
    # the readout walks it, and the build's plan's first two steps with --first
    proc = weigh_simulated(project, out, "w.csv", "--cap-g", "10.5", "--plan", "stiff.json", "--samples", "40",
                  "--dwell-s", "0.1")
    assert proc.returncode == 0, proc.stderr[-2000:]
    rows = read_weights_csv(project / "w.csv")
    assert [(r.angle_deg, round(r.mass_g - 10.5, 6)) for r in rows] == [
        (s["angle_deg"], s["coins"] * stiff["coin"]["mass_g"]) for s in stiff["steps"]]
    proc = weigh_simulated(project, out, "f.csv", "--cap-g", "10.5", "--first", "--samples", "40", "--dwell-s", "0.1")
    assert proc.returncode == 0 and "next: magfab weigh-plan f.csv" in proc.stderr, proc.stderr[-2000:]
    shipped = json.loads((out / "calibration" / "weigh_plan.json").read_text())
    assert [(r.angle_deg, round(r.mass_g - 10.5, 6)) for r in read_weights_csv(project / "f.csv", least=2)] == [
        (shipped["steps"][k]["angle_deg"], shipped["steps"][k]["coins"] * 5.0) for k in shipped["first"]]


@pytest.mark.parametrize("name, says", [
    ("one.csv", "one.csv: 1 weighings; a skin's plan takes 2 to 500"),
    ("same.csv", "same.csv: 2 weighings of 1 distinct masses, 0 of them tilted"),
    ("tilted.csv", "tilted.csv: 2 weighings of 2 distinct masses, 1 of them tilted"),
    ("heavy.csv", "the plan's first weighings are flat, the cap alone (at most 53.1 g) and with up to 260.0 g"),
    ("n52.csv", "n52.csv: the weighings"),
    ("kept.csv", "kept.json exists: a plan is not overwritten"),
])
def test_a_wrong_first_file_is_one_line_and_writes_nothing(bench, drawn, name, says):
    project, out, calls, run = bench
    _, _, first, noise = drawn
    rng = np.random.default_rng(5)
    sensor = _sensor(drawn, 5)
    rows = weighings(sensor, first, noise, rng)
    n52 = copy.deepcopy(sensor)
    n52.theta[1] = math.log(1.5)  # a far stronger magnet than the design's grade
    files = {"one.csv": rows[:1], "same.csv": [rows[0], rows[0]],
             "tilted.csv": [rows[0], weighings(sensor, [(first[1][0], 20.0)], noise, rng)[0]],
             "heavy.csv": weighings(sensor, [first[0], (first[1][0] + 60.0, 0.0)], noise, rng),
             "n52.csv": weighings(n52, first, noise, rng), "kept.csv": rows}
    (project / name).write_text(weights_csv(files[name]))
    (project / "kept.json").write_text("{}\n")
    before = tree(project)
    result = run("weigh-plan", name, "kept.json" if name == "kept.csv" else "plan.json", "--out", str(out))
    assert result.exit_code == 2, result.output
    assert says in result.output and len(result.output.strip().splitlines()) == 1, result.output
    assert tree(project) == before and calls == []


def _mutations(plan: dict) -> list[tuple[str, dict]]:
    """A valid plan each broken one way, with what the refusal names."""
    out = []

    def broken(what, change):
        doc = copy.deepcopy(plan)
        change(doc)
        out.append((what, doc))

    broken("not a weight plan", lambda d: d.update(format="magfab-weigh-plan/2"))
    broken("its spec is", lambda d: d.update(spec="other"))
    broken("its coin is", lambda d: d["coin"].update(mass_g=6.0))
    broken("its pockets is", lambda d: d.update(pockets=d["pockets"] + 1))
    broken("its cap_mass_bound_g is", lambda d: d.update(cap_mass_bound_g=d["cap_mass_bound_g"] / 2))
    broken("its stand_coins_most is", lambda d: d["stand_coins_most"].__setitem__(2, 144))
    broken("its steps are not a list", lambda d: d.update(steps=[]))

    def coins(k: int, n: int, layout: list | None = None):  # step k given n coins, laid as the jig lays them
        return lambda d: d["steps"][k].update(coins=n, layout=layout or coin_layout(n, d["pockets"]))

    flat, steep = plan["stand_coins_most"][0], plan["stand_coins_most"][2]
    at_40 = next(k for k, step in enumerate(plan["steps"]) if step["angle_deg"] == 40.0)
    broken("step 2 is not a stand", lambda d: d["steps"][1].update(angle_deg=30.0))
    broken("step 2 is not a stand", lambda d: d["steps"][1].update(angle_deg=[0.0]))
    broken("step 2 is not a stand", coins(1, flat + 2))  # past the flat stand's most, laid right
    broken(f"step {at_40 + 1} is not a stand", coins(at_40, steep + 2))  # past the steep stand's, within the flat's
    broken("step 2 is not a stand", lambda d: d["steps"][1].update(coins=d["steps"][1]["coins"] + 1))  # odd
    broken("step 2 is not a stand", coins(1, 4, [4] + [0] * (plan["pockets"] - 1)))  # one pocket, not pairs
    broken("step 1 is not a stand", lambda d: d["steps"][0].update(coins=False))  # laid right for no coins
    broken("step 2 is not a stand", lambda d: d["steps"].__setitem__(1, "ten coins"))
    broken("its first steps are not indices", lambda d: d.update(first=[0, len(d["steps"])]))
    broken("its first steps are not indices", lambda d: d.update(first=[0, True]))
    broken("its reskin steps are not indices", lambda d: d.update(reskin=None))
    broken("its reskin steps are not indices", lambda d: d.update(reskin=[]))
    broken("its nominal field tables do not cover", lambda d: d["nominal"].pop())
    broken("its nominal field tables do not cover", lambda d: d.pop("nominal"))
    broken("its nominal field tables do not cover", lambda d: d["nominal"][0]["mass_g"].__setitem__(1, 0.0))
    broken("its nominal field tables do not cover", lambda d: d["nominal"][0]["field_uT"][3].pop())
    return out


def test_a_plan_file_that_is_not_this_builds_is_refused(weigh_package, tmp_path):
    """``weigh --plan``: the build's own plan passes; each of its keys broken one way (another format, design,
    coin, pocket count, cap or stand maxima; a step off the stands, past the coins any skin's plan takes on its stand
    though laid right, an odd count, coins not in opposite pairs, a boolean; first or re-skin steps that are not
    steps; a stand without a whole nominal table), or a file that is not JSON, is one UsageError line naming --plan
    and what is wrong."""
    shipped = weigh_package.plan
    path = tmp_path / "plan.json"
    path.write_text(json.dumps(shipped))
    assert weigh_package.weigh.skin_plan(str(path), shipped)["steps"] == shipped["steps"]
    for what, doc in [*_mutations(shipped), ("not a readable JSON file", None)]:
        path.write_text("{not json" if doc is None else json.dumps(doc))
        with pytest.raises(weigh_package.UsageError) as e:
            weigh_package.weigh.skin_plan(str(path), shipped)
        message = str(e.value)
        assert message.startswith(f"--plan {path}: ") and what in message and "\n" not in message, (what, message)


def test_a_fit_past_the_band_plans_for_the_stiffest_skin_and_a_heavy_cap_is_taken(magone_design, magone_prediction,
                                                                                  drawn, monkeypatch):
    """The plan is never for a skin stiffer than the band's stiffest, however high the fit; the first weighings of a
    cap up to twice its printed bound (what weigh takes) are accepted."""
    import magfab.export.weigh_plan as W

    _, _, first, noise = drawn
    rng = np.random.default_rng(3)
    sensor = _sensor(drawn, 3)
    heavy = weighings(sensor, [(m + 3.5, a) for m, a in first], noise, rng)  # a 30 g cap: 3.5 g over its bound
    monkeypatch.setattr(W, "stiffness_of", lambda fit, model, prediction: 50.0)
    doc = adapted_plan(magone_design, magone_prediction, heavy, "heavy.csv", "")
    assert doc["stiffness"] == round(stiffest_skin(magone_prediction), 4)
    stiffest = jig_of(magone_design).plan(magone_prediction, stiffness=stiffest_skin(magone_prediction))
    assert [(s["angle_deg"], s["coins"]) for s in doc["steps"]] == [(a, n) for _, a, n in stiffest]


def test_weigh_refuses_a_plan_with_first_or_reskin_and_never_overwrites_a_partial_recording(bench):
    """``--first`` and ``--reskin`` walk the build's own plan (a skin's plan may press a softer new skin past its
    range), so each is refused with ``--plan``, as is an empty ``--plan``; and ``record OUT.parquet`` refuses while
    an earlier recording's OUT.parquet.partial.csv (its only copy of the rows) is there. One line, exit 2, nothing
    written."""
    project, out, _, _ = bench
    (project / "plan.json").write_text((out / "calibration" / "weigh_plan.json").read_text())
    for args, says in ((("--first", "--plan", "plan.json"), "--first walks the build's plan's first two steps"),
                       (("--reskin", "--plan", "plan.json"), "--reskin walks the build's plan's re-skin steps"),
                       (("--plan", ""), "--plan : not a readable JSON file")):
        proc = weigh_simulated(project, out, "x.csv", "--cap-g", "10", *args)
        assert proc.returncode == 2 and proc.stderr.count("\n") == 1 and says in proc.stderr, proc.stderr
        assert not (project / "x.csv").exists()
    (project / "r.parquet.partial.csv").write_text("kept\n")
    env_src = str(out / "readout" / "src")
    proc = subprocess.run([sys.executable, "-c", f"import sys; sys.path.insert(0, {env_src!r}); "
                           "from magfab_readout.cli import main; sys.exit(main())", "record", "r.parquet",
                           "--simulate", "--seconds", "0.1"], capture_output=True, text=True, timeout=120,
                          cwd=project)
    assert proc.returncode == 2 and "r.parquet.partial.csv exists" in proc.stderr, proc.stderr
    assert (project / "r.parquet.partial.csv").read_text() == "kept\n" and not (project / "r.parquet").exists()


#: The plan's keys that must be this build's, as the guard compares them (the refusal names the key).
BUILD_KEYS = ("format", "spec", "coin", "pockets", "cap_mass_bound_g", "stands_deg", "stand_coins_most")


def _at(doc, path):
    """The container holding ``path``'s value, and its key there."""
    for k in path[:-1]:
        doc = doc[k]
    return doc, path[-1]


def _changed_value(data, value):
    """A drawn other value for a leaf: a number scaled or shifted, any value turned into another JSON type."""
    kinds = ["string", "null", "list"] + (["scale", "shift"] if isinstance(value, (int, float))
                                          and not isinstance(value, bool) else ["longer"])
    kind = data.draw(st.sampled_from(kinds))
    if kind == "scale":
        return value * data.draw(st.floats(0.25, 4.0).filter(lambda f: abs(f - 1.0) > 1e-3))
    if kind == "shift":
        return value + data.draw(st.sampled_from([-1, 1])) * data.draw(st.floats(1e-3, 100.0))
    return {"string": str(value), "null": None, "list": [value], "longer": f"{value}x"}[kind]


def _broken_plan(data, plan):
    """(the plan with one drawn mistake of a drawn class, what its refusal must name; None: the mistake leaves a
    plan the guard must take). The classes: a build key's leaf changed or removed; a step off its stand (an angle
    of no stand, an odd count, more coins than the stand takes, a count of another type, coins laid another way);
    a first or re-skin index that is not one of the steps; a nominal table dropped, cut short or out of order."""
    doc = copy.deepcopy(plan)
    steps = doc["steps"]
    cls = data.draw(st.sampled_from(["build", "step", "index", "nominal"]))
    if cls == "build":
        key = data.draw(st.sampled_from(BUILD_KEYS))
        leaves = [p for p in paths(doc[key], (key,)) if not isinstance(_at(doc, p)[0][p[-1]], (dict, list))]
        path = data.draw(st.sampled_from(leaves))
        parent, last = _at(doc, path)
        if data.draw(st.booleans()):
            del parent[last]
        else:
            old = parent[last]
            parent[last] = _changed_value(data, old)
            assume(parent[last] != old)
        return doc, "not a weight plan" if key == "format" else f"its {key} is"
    if cls == "step":
        k = data.draw(st.integers(0, len(steps) - 1))
        step, most = steps[k], dict(zip(plan["stands_deg"], plan["stand_coins_most"]))[steps[k]["angle_deg"]]
        how = data.draw(st.sampled_from(["angle", "odd", "past", "negative", "type", "layout"]))
        if how == "angle":
            step["angle_deg"] = data.draw(st.floats(-90, 90).filter(lambda a: a not in plan["stands_deg"]))
        elif how in ("odd", "past", "negative"):
            n = {"odd": data.draw(st.integers(0, most // 2)) * 2 + 1,
                 "past": most + 2 * data.draw(st.integers(1, 50)), "negative": -2 * data.draw(st.integers(1, 50))}[how]
            layout = coin_layout(abs(n) - n % 2, plan["pockets"])  # an odd count: its extra coin in the first pocket
            layout[0] += n % 2
            step.update(coins=n, layout=layout)
        elif how == "type":
            step["coins"] = data.draw(st.sampled_from([float(step["coins"]) + 0.5, str(step["coins"]), True, None]))
        else:
            shift = data.draw(st.integers(1, plan["pockets"] - 1))
            step["layout"] = step["layout"][shift:] + step["layout"][:shift]
            assume(step["layout"] != plan["steps"][k]["layout"])
        return doc, f"step {k + 1} is not a stand"
    if cls == "index":
        key = data.draw(st.sampled_from(["first", "reskin"]))
        wrong = data.draw(st.one_of(st.integers(len(steps), len(steps) + 100), st.integers(-100, -1),
                                    st.just(True), st.floats(0.5, len(steps) - 0.5).filter(lambda f: f != int(f)),
                                    st.just("0")))
        if data.draw(st.booleans()):
            doc[key] = data.draw(st.sampled_from([[], None, {}, 0]))
        else:
            doc[key].insert(data.draw(st.integers(0, len(doc[key]))), wrong)
        return doc, f"its {key} steps are not indices"
    used = {s["angle_deg"] for s in steps}
    t = data.draw(st.integers(0, len(doc["nominal"]) - 1))
    table = doc["nominal"][t]
    how = data.draw(st.sampled_from(["drop", "short", "row", "order", "value"]))
    if how == "drop":
        doc["nominal"].pop(t)
        if table["angle_deg"] not in used:
            return doc, None  # a table no step needs: still a plan
    elif how == "short":
        column = table[data.draw(st.sampled_from(["mass_g", "field_uT"]))]
        column.pop(data.draw(st.integers(0, len(column) - 1)))
    elif how == "row":
        table["field_uT"][data.draw(st.integers(0, len(table["field_uT"]) - 1))].pop()
    elif how == "order":
        i = data.draw(st.integers(0, len(table["mass_g"]) - 2))
        table["mass_g"][i], table["mass_g"][i + 1] = table["mass_g"][i + 1], table["mass_g"][i]
    else:
        row = table["field_uT"][data.draw(st.integers(0, len(table["field_uT"]) - 1))]
        row[data.draw(st.integers(0, 2))] = data.draw(st.sampled_from(["1.0x", None, [1.0]]))
    return doc, "its nominal field tables do not cover"


@settings(max_examples=300, deadline=None)
@given(data=st.data())
def test_generated_mistakes_in_a_plan_file_are_refused(weigh_package, tmp_path_factory, data):
    """``weigh --plan`` against a generator of the mistakes it guards (:func:`_broken_plan`: any leaf of the build's
    keys changed by a drawn scale, shift or type, or removed; a drawn step moved off its stand; a drawn index out of
    the steps; a nominal table dropped, cut or disordered): each is refused in one line naming --plan and what is
    wrong; a table no step needs may go."""
    shipped = weigh_package.plan
    doc, what = _broken_plan(data, shipped)
    path = tmp_path_factory.mktemp("plan") / "plan.json"
    path.write_text(json.dumps(doc))
    if what is None:
        assert weigh_package.weigh.skin_plan(str(path), shipped)["steps"] == shipped["steps"]
        return
    with pytest.raises(weigh_package.UsageError) as e:
        weigh_package.weigh.skin_plan(str(path), shipped)
    message = str(e.value)
    assert message.startswith(f"--plan {path}: ") and what in message and "\n" not in message, (what, message)
