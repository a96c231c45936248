"""What `magfab design` reports: requirements met by a margin (the model chain's error, or the targets'), drift and
Earth-field requirements, pareto.csv, the plot's requirement lines, the exit code when nothing meets the targets and
specs written on the printer's step. Everything here but one evaluation of MagOne's geometry runs without a cluster."""

from __future__ import annotations

import csv
import math

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab import load_spec
from magfab.errors import SpecError
from magfab.inverse import evaluate as ev
from magfab.inverse.files import spec_toml
from magfab.inverse.page import pareto_rows, write_outputs
from magfab.inverse.result import DesignResult, closest, margins, nearest
from magfab.inverse.space import candidate_spec
from magfab.inverse.study import Record
from magfab.inverse.targets import parse_targets
from magfab.spec import spec_from_dict
from magfab.toml_input import loads_toml

VARIABLES = """
[variables]
materials = ["ecoflex-00-30", "ecoflex-00-50"]
tips = ["hemisphere"]
d_max_mm = [4.0, 8.0]
d_min_mm = [2.5, 3.5]
elastomer_diameter_mm = [10.0, 12.0]
cover_mm = [1.0, 2.5]
"""
BASE = load_spec()
POINT = {"magnet": "d4_h2", "grade": "N45", "material": "ecoflex-00-50", "tip": "hemisphere", "d_max_mm": 4.55,
         "d_min_mm": 2.75, "elastomer_diameter_mm": 10.95, "cover_mm": 1.25}


def targets(require: str = "", objectives: str = '["normal_resolution_mN", "normal_range_N"]'):
    return parse_targets(f"name = \"t\"\nobjectives = {objectives}\n[require]\n{require}\n{VARIABLES}")


@pytest.fixture(scope="module")
def magone_like():
    """One design evaluated by the cheap chain with every requirement given (its figures: the property tests'
    design)."""
    t = targets("normal_resolution_mN = 4.0\nnormal_range_N = 1.0\nmax_diameter_mm = 12.0\nmax_height_mm = 12.0\n"
                "max_drift_mN_per_C = 100.0\nmax_earth_field_mN = 500.0\nshear_resolution_mN = 5.0\n"
                "shear_range_N = 0.1")
    out = ev.evaluate(POINT, BASE.model_dump_json(), t.model_dump_json(), ev.SURROGATE)
    assert out["metrics"], out["reason"]
    return t, out


def test_the_model_margin_is_the_chains_own_error(magone_like):
    t, out = magone_like
    m = out["metrics"]
    model = m["field_error"] + m["mechanics_error"]
    assert 0.0 < model < 0.2  # the surrogate's held-out force error, the exact field's none
    assert m["range_error"] > m["mechanics_error"]  # where the surrogate's travel ends is uncertain too
    for name in ev.requirement_names(t):
        expected = {"max_diameter_mm": 0.0, "max_height_mm": 0.0, "normal_range_N": m["field_error"] + m["range_error"],
                    "shear_range_N": m["field_error"] + m["range_error"]}.get(name, model)
        assert ev.margin_of(t, name, m) == pytest.approx(expected), name
    fixed = targets("normal_range_N = 1.0\nmax_diameter_mm = 12.0\nmargin = 7")
    assert ev.margin_of(fixed, "normal_range_N", m) == pytest.approx(0.07)
    assert ev.margin_of(fixed, "max_diameter_mm", m) == 0.0  # sizes are exact


def test_drift_and_earth_field_are_the_drift_budgets(magone_like):
    """The drift and Earth-field figures are finite, positive and the budget's: turned over in 0.65 G the field
    changes by 1.3 G on an axis, far above the chip's noise, so the error is mN, not uN."""
    _, out = magone_like
    m = out["metrics"]
    assert m["drift_mN_per_C"] > 0 and math.isfinite(m["drift_mN_per_C"])
    assert m["earth_field_mN"] > m["normal_resolution_mN"]  # what swamps a delicate design's resolution


@settings(max_examples=200, deadline=None)
@given(data=st.data())
def test_met_with_margin_means_every_constraint_at_least_the_margin_away(magone_like, data):
    """Over random targets: a design reported as meeting every requirement with margin has each constraint <= 0, and
    meets each requirement by at least its margin (its figure that far inside it); a design that misses one is
    infeasible to the sampler."""
    _, out = magone_like
    m = out["metrics"]
    scale = st.floats(0.5, 1.5)
    keys = {"normal_resolution_mN": m["normal_resolution_mN"], "normal_range_N": m["normal_range_N"],
            "max_diameter_mm": m["diameter_mm"], "max_drift_mN_per_C": m["drift_mN_per_C"],
            "max_earth_field_mN": m["earth_field_mN"], "shear_range_N": m["shear_range_N"]}
    chosen = data.draw(st.lists(st.sampled_from(sorted(keys)), min_size=1, unique=True))
    # (a diameter requirement below the variables' smallest elastomer is refused: not a design question)
    lines = [f"{k} = {keys[k] * data.draw(st.floats(0.92, 1.5) if k == 'max_diameter_mm' else scale):.6g}"
             for k in chosen]
    margin = data.draw(st.one_of(st.just('"model"'), st.floats(0.0, 50.0).map(lambda x: f"{x:.3f}")))
    t = targets("\n".join([*lines, f"margin = {margin}"]))
    constraints = ev._constraints(t, m, [])
    rec = Record(0, POINT, "ok", "", "surrogate", m, constraints, [])
    ms = margins(t, rec)
    assert [x.name for x in ms] == ev.requirement_names(t)
    for x, c in zip(ms, constraints):
        sense = ev.REQUIREMENTS[x.name][1]
        inside = x.need - x.value if sense == "at_most" else x.value - x.need
        if x.met:
            assert c <= 1e-12 and inside >= x.margin * x.need - 1e-9 * x.need
        else:
            assert c > 0
    assert all(x.met for x in ms) == all(c <= 0 for c in constraints[:-1])


def test_the_reported_margin_of_a_real_verification(magone_like):
    """The cheap chain's own verdict, state and reason agree with the margins."""
    t, out = magone_like
    rec = Record(0, POINT, out["state"], out["reason"], out["model"], out["metrics"], out["constraints"],
                 out["errors"])
    ms = margins(t, rec)
    assert (out["state"] == "ok") == (all(x.met for x in ms) and not out["errors"])
    for x in ms:
        if not x.met:
            assert f"{x.name} " in out["reason"] and "short by" in out["reason"]


@pytest.mark.parametrize("value, words", [('"big"', '"model"'), ("60", "0 to 50"), ("-1", "0 to 50"),
                                          ("true", '"model"')])
def test_a_bad_margin_is_one_line_naming_the_key(value, words):
    with pytest.raises(SpecError) as err:
        targets(f"margin = {value}")
    assert err.value.key == "require.margin" and words in str(err.value) and "\n" not in str(err.value)


def test_new_requirements_and_objectives_parse():
    t = targets("max_drift_mN_per_C = 2.0\nmax_earth_field_mN = 3.0",
                objectives='["drift_mN_per_C", "earth_field_mN", "normal_resolution_mN"]')
    assert ev.requirement_names(t) == ["max_drift_mN_per_C", "max_earth_field_mN"]
    assert t.directions() == ["minimize", "minimize", "minimize"]
    with pytest.raises(SpecError):
        targets("max_drift_mN_per_C = 0")


@settings(max_examples=60, deadline=None)
@given(d_max=st.floats(4.0, 8.0), d_min=st.floats(2.5, 3.5), diameter=st.floats(10.0, 12.0),
       cover=st.floats(1.0, 2.5))
def test_written_dimensions_are_on_the_printers_step(d_max, d_min, diameter, cover):
    """Every dimension of a verified design is on the resin printer's 0.05 mm layer height, within the variables'
    ranges, and the elastomer's height too."""
    t = targets()
    point = {**POINT, "d_max_mm": d_max, "d_min_mm": d_min, "elastomer_diameter_mm": diameter, "cover_mm": cover}
    step = ev.bench_step_mm(BASE)
    assert step == 0.05
    p = ev.bench_point(point, BASE, t)
    spec = candidate_spec(p, BASE, t, "x")
    for v in (p["d_max_mm"], p["d_min_mm"], p["elastomer_diameter_mm"], spec.elastomer.height_mm):
        assert abs(v / step - round(v / step)) < 1e-6, v
    assert 4.0 <= p["d_max_mm"] <= 8.0 and 2.5 <= p["d_min_mm"] <= 3.5 and 10.0 <= p["elastomer_diameter_mm"] <= 12.0
    assert 1.0 - 1e-9 <= p["cover_mm"] <= 2.5 + 1e-9 or p["cover_mm"] == cover
    assert abs(p["d_max_mm"] - d_max) <= step / 2 + 1e-9


def test_the_written_spec_has_the_address_in_hex_and_reads_back():
    text = spec_toml(BASE, "header").decode()
    assert "i2c_address = 0x0C" in text
    assert spec_from_dict(loads_toml(text, "spec", "<test>")) == BASE


def _result(tmp_path, verified_states, chosen=None):
    t = targets("normal_resolution_mN = 4.0\nnormal_range_N = 1.0\nmax_diameter_mm = 12.0")
    m = {"normal_resolution_mN": 2.6, "shear_resolution_mN": 2.0, "normal_range_N": 1.07, "shear_range_N": 0.9,
         "diameter_mm": 10.95, "height_mm": 6.1, "drift_mN_per_C": 5.8, "earth_field_mN": 27.8,
         "field_error": 1e-5, "mechanics_error": 0.044, "normal_sensitivity_at_rest_G_per_N": 86.0,
         "Bz_rest_G": 275.0, "range_limit": "stretch"}
    short = {**m, "normal_range_N": 1.014}  # +1.4 % against a 4.4 % mechanics error: short of its margin
    recs = []
    for i, state in enumerate(verified_states):
        metrics = m if state == "ok" else short
        recs.append(Record(i, POINT, state, "", "fe", metrics, ev._constraints(t, metrics, []), []))
    trials = [Record(i, POINT, "infeasible", "x", "surrogate", short, ev._constraints(t, short, []), [])
              for i in range(5)]
    front = [i for i, s in enumerate(verified_states) if s == "ok"]
    return DesignResult(t, tmp_path / "study", trials, recs, recs, front, chosen,
                        [f"t-{i}" for i in range(len(recs))])


def test_pareto_csv_lists_the_verified_designs_with_margins_and_specs(tmp_path):
    result = _result(tmp_path, ["ok", "infeasible"], chosen=0)
    write_outputs(result, BASE)
    with open(result.folder / "pareto.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["design"] for r in rows] == ["t-0", "t-1"] and all(r["verified"] == "True" for r in rows)
    assert rows[0]["meets_targets"] == "True" and rows[1]["meets_targets"] == "False"
    assert float(rows[1]["normal_range_N_met_by_pct"]) == pytest.approx(1.4, abs=1e-3)
    assert float(rows[1]["normal_range_N_margin_pct"]) == pytest.approx(4.4, abs=1e-2)
    for r in rows:
        spec = load_spec(result.folder / r["spec"])
        assert spec.elastomer.diameter_mm == pytest.approx(10.95)
    head = (result.folder / rows[1]["spec"]).read_text().splitlines()
    assert any(line.startswith("# DOES NOT MEET normal_range_N") for line in head)
    svg = (result.folder / "pareto.svg").read_text()
    assert "requirement" in svg and "margin band" in svg
    page = (result.folder / "README.md").read_text()
    assert "It meets every requirement with margin: " in page
    assert "normal\\_range\\_N 1.07 &gt;= 1: by +7.0 % (margin 4.4 %)" in page


def test_nothing_verified_still_fills_pareto_csv(tmp_path):
    result = _result(tmp_path, [])
    rows = pareto_rows(result, BASE)
    assert rows and all(r["verified"] is False and r["model"] == "surrogate" for r in rows)
    line = closest(result.targets, result.trials)
    assert line.startswith("closest: trial-0 (surrogate), normal_range_N 1.014 against >= 1 (margin 4.4 %): short by "
                           "3.0 %"), line


def test_nothing_meets_the_targets_exits_3_with_the_closest_requirement(tmp_path, monkeypatch):
    from magfab import cli
    from magfab.inverse import run

    result = _result(tmp_path, ["infeasible"])
    monkeypatch.setattr(run, "design", lambda *a, **k: result)
    (tmp_path / "t.toml").write_text("")
    out = CliRunner().invoke(cli.main, ["design", str(tmp_path / "t.toml")])
    assert out.exit_code == cli.EXIT_UNMET == 3, out.output
    errors = [line for line in out.output.splitlines() if line.startswith("magfab: error:")]
    assert len(errors) == 1 and "closest: t-0 (fe), normal_range_N 1.014 against >= 1 (margin 4.4 %): short by 3.0 %" \
        in errors[0], out.output


def test_the_full_chain_verifies_the_design_as_printed():
    """The full chain evaluates the point on the printer's step: its figures are the written spec's."""
    t = targets("normal_range_N = 0.5")
    off = {**POINT, "elastomer_diameter_mm": 10.97, "d_max_mm": 4.56}
    out = ev.evaluate(off, BASE.model_dump_json(), t.model_dump_json(), ev.FE)
    assert out["model"] == ev.FE and out["metrics"], out["reason"]
    assert out["metrics"]["diameter_mm"] == pytest.approx(10.95)
    spec = candidate_spec(ev.bench_point(off, BASE, t), BASE, t, "x")
    assert out["metrics"]["height_mm"] == pytest.approx(spec.elastomer.height_mm)


def test_the_nearest_design_has_its_figures_and_no_error_findings_first():
    t = targets("normal_range_N = 1.0")
    base = {"normal_range_N": 0.9, "field_error": 0.0, "mechanics_error": 0.02}
    recs = [Record(0, POINT, "infeasible", "", "surrogate", {**base, "normal_range_N": 1.2}, [], ["chip-saturates"]),
            Record(1, POINT, "infeasible", "", "surrogate", {**base, "normal_range_N": math.nan}, [], []),
            Record(2, POINT, "infeasible", "", "surrogate", base, [], []),
            Record(3, POINT, "infeasible", "", "surrogate", {**base, "normal_range_N": 0.95}, [], [])]
    assert nearest(t, recs) == [3, 2, 0, 1]
    assert closest(t, recs).startswith("closest: trial-3 (surrogate), normal_range_N 0.95 against >= 1 (margin 2.0 "
                                       "%): short by 7.0 %")


@pytest.mark.parametrize("limit, at_least", [("material data", True), ("model", True), ("d_min", False),
                                             ("scan depth", False), ("invertibility", False), ("stretch", False)])
def test_a_range_a_model_ended_reads_at_least(tmp_path, limit, at_least):
    """A verified design whose range a model's reach ended (the material law's data, the FE stopping) shows its
    range requirement's figure as "at least" it (Margin.shown: what the design's header, the page and magfab
    design's summary print); a range the sensor ends (d_min, the scan depth, ...) without it."""
    result = _result(tmp_path, ["ok"], chosen=0)
    rec = result.verified[0]
    rec = Record(rec.number, rec.point, rec.state, rec.reason, rec.model, {**rec.metrics, "range_limit": limit},
                 rec.constraints, rec.errors)
    (m,) = [m for m in margins(result.targets, rec) if m.name == "normal_range_N"]
    assert m.at_least == at_least and m.shown.startswith("at least ") == at_least
    assert not any(x.at_least for x in margins(result.targets, rec) if x.name != "normal_range_N")
