"""``magfab check`` and ``magfab build`` agree on every spec of the design space: check says ok (no finding that
stops a build) exactly when the build's stages that can refuse accept, and where they refuse, check's line is the
build's.

The space is the inverse design's: points of the variables' box (every stock disc in every grade it is sold in,
every silicone, both tips, d_max, d_min, the elastomer's diameter past the default box's 20 mm, the cover) made specs
as the search makes them (:func:`magfab.inverse.space.candidate_spec`), with the board's size left to the fit,
stated, or any, and the board's rules (clearances, track, via, density, pull-ups, holes) drawn too.

The stages of :func:`magfab.pipeline.plan` that can refuse, in order: the refusals before any work (preflight), the
design's checks, the CAD branch (the board placed, routed and checked, its Gerbers plotted; every solid modelled, its
mesh checked, the closed mould fitted), the prediction, the bundle and the papers (warnings: a stop only with
``build.strict``). Check (:func:`magfab.check.verdict`) runs all but the CAD branch, so what is to be shown is that
the CAD branch refuses nothing check lets through. Three tiers:

* fast (default): check's verdict before its prediction against the build's refusals up to and including the board
  routed and checked (its costly part, a few seconds a board): the prediction is the same call on the same design in
  both (:func:`magfab.check.predict_with_findings`), so it is stubbed in both;
* slow (``-m slow``): the same over more points, the solids, meshes and mould fit included (``pipeline._cad``);
* slow: the commands themselves, ``magfab check`` and ``magfab build``, on a few specs, prediction, bundle and
  ``build.strict`` included. By default only specs both refuse before any work run the commands (under a second).

Each disagreement found is kept below as an explicit example.
"""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path
from unittest import mock

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, assume, event, example, given, settings
from hypothesis import strategies as st

from magfab import pcb, pipeline
from magfab import verdict as verdict_module
from magfab.board.connect import _clash
from magfab.board.route import LAYERS, Copper, Router
from magfab.cli import main
from magfab.errors import BuildError, Finding, InputError, MagfabError, Severity
from magfab.inverse.files import spec_toml
from magfab.inverse.space import candidate_spec, choices
from magfab.inverse.targets import parse_targets
from magfab.recipes import catalogue
from magfab.spec import Spec, load_spec, spec_from_dict
from magfab.verdict import verdict

pytestmark = pytest.mark.filterwarnings("ignore")

TARGETS = parse_targets("")  # the default variables' box
BASE = load_spec(None)
MAGNETS = choices(TARGETS.variables)["magnet"]  # "DISC:GRADE", each stock disc in each grade it is sold in
MATERIALS = sorted(catalogue("materials"))
#: The elastomer's diameter: the default box (8-20 mm) and past it.
DIAMETER = (8.0, 26.0)


@st.composite
def points(draw) -> dict:
    disc, grade = draw(st.sampled_from(MAGNETS)).split(":")
    return {"magnet": disc, "grade": grade, "material": draw(st.sampled_from(MATERIALS)),
            "tip": draw(st.sampled_from(["hemisphere", "flat"])),
            "d_max_mm": draw(st.floats(3.0, 10.0)), "d_min_mm": draw(st.floats(2.0, 4.0)),
            "elastomer_diameter_mm": draw(st.floats(*DIAMETER)), "cover_mm": draw(st.floats(0.5, 4.0))}


@st.composite
def boards(draw) -> dict:
    """[pcb] over the base's: its size as the base states it (30 x 30), left to the fit, or any, each side; half
    of them with the rules drawn too."""
    pcb_ = dict(BASE.toml_dict()["pcb"])
    for side in ("width_mm", "height_mm"):
        how = draw(st.sampled_from(["base", "unstated", "any"]))
        if how == "unstated":
            pcb_.pop(side)
        elif how == "any":
            pcb_[side] = 0.5 * draw(st.integers(40, 120))
    if draw(st.booleans()):
        drill = round(draw(st.floats(0.2, 0.5)), 2)
        pcb_.update(clearance_mm=round(draw(st.floats(0.1, 0.4)), 2),
                    track_width_mm=round(draw(st.floats(0.1, 0.5)), 2),
                    via_drill_mm=drill, via_diameter_mm=round(drill + draw(st.floats(0.05, 0.5)), 2),
                    edge_clearance_mm=round(draw(st.floats(0.1, 1.0)), 2),
                    density=draw(st.sampled_from(["least", "nominal", "most"])), pullups=draw(st.booleans()),
                    mounting_hole_diameter_mm=draw(st.sampled_from([0.0, 2.2, 3.2])),
                    mounting_hole_inset_mm=draw(st.sampled_from([2.0, 3.0, 5.0])))
    return pcb_


def spec_of(point: dict, board: dict, strict: bool = False) -> Spec:
    """The point's spec as the search makes it, its [pcb] replaced by ``board``; a point or board that is no spec
    (d_min past d_max, a via's drill past its pad) is refused by loading, the same for both commands: not drawn."""
    try:
        raw = candidate_spec(point, BASE, TARGETS, "agree").toml_dict()
        raw["pcb"] = board
        raw["build"]["strict"] = strict
        return spec_from_dict(raw)
    except InputError:
        assume(False)
        raise


def _refusal(call) -> str | None:
    try:
        call()
    except MagfabError as exc:
        return str(exc)
    return None


def _no_prediction():
    """Check's prediction stubbed (module doc): no findings, no prediction (the bundle is then not run)."""
    stack = ExitStack()
    stack.enter_context(mock.patch.object(verdict_module, "predict_with_findings", return_value=(None, [])))
    return stack


def check_says(spec: Spec) -> str | None:
    """The line ``magfab check`` refuses ``spec`` with, its prediction aside, or None (it says ok)."""
    def run() -> None:
        stop = verdict(spec)[2]
        if stop:
            raise stop

    with _no_prediction():
        return _refusal(run)


def build_says(spec: Spec, cad: bool) -> str | None:
    """The line the build refuses ``spec`` with, up to its CAD branch: the board routed and checked (``cad``: the
    whole branch, the solids and the Gerbers too), or None."""
    def run() -> None:
        design = pipeline.preflight(pipeline.derive(spec))  # plan()'s own steps, in its order
        findings = pipeline.design_findings(design)
        pipeline._stop(findings, spec)
        if cad:
            found = pipeline._cad(design, lambda _: None, {}, parallel=False).findings
        else:
            found = pcb.findings(pcb.board(design))
        pipeline._stop(findings + found, spec)

    return _refusal(run)


def _agree(point: dict, board: dict, cad: bool) -> str | None:
    spec = spec_of(point, board)
    check = check_says(spec)
    assert build_says(spec, cad) == check, (point, board)
    return check


def _key(line: str | None) -> str:
    """The key a refusal names (or "ok"), for the statistics."""
    return "ok" if line is None else line.split(" = ")[0].split(":")[0]


# ---- the disagreements found, each an explicit example ------------------------------------------------------------

#: A narrow via (0.41 mm pad, 0.33 mm drill) holds its drill 0.21 mm from other nets' copper, past the 0.12 mm
#: clearance: the router's rip-up held vias to the clearance only and left a +3V3 track 0.161 mm from a GND via.
#: check: ok; build: "pcb: track (+3V3) and via (GND) are 0.161 mm apart; need 0.21 mm".
NARROW_VIA = ({"magnet": "d10_h1", "grade": "N35", "material": "ecoflex-00-50", "tip": "flat",
               "d_max_mm": 9.985326030806123, "d_min_mm": 2.0392614187406037,
               "elastomer_diameter_mm": 11.371532493061894, "cover_mm": 3.9854250214272673},
              {"thickness_mm": 1.6, "clearance_mm": 0.12, "track_width_mm": 0.17, "via_drill_mm": 0.33,
               "via_diameter_mm": 0.41, "edge_clearance_mm": 0.65, "density": "nominal", "pullups": False,
               "mounting_hole_diameter_mm": 0.0, "mounting_hole_inset_mm": 2.0})

#: Wide tracks and vias (0.31 mm, 0.84 mm, 0.23 mm apart) on the board sized to fit: the router finds no path for
#: SCL. check: ok (it did not route); build: "pcb: net SCL: no path from R2.2 to U1.3 with these rules". Check now
#: routes the board as the build does.
UNROUTABLE = ({"magnet": "d5_h2", "grade": "N52", "material": "ecoflex-00-30", "tip": "hemisphere",
               "d_max_mm": 6.863459040365544, "d_min_mm": 2.634884251277203,
               "elastomer_diameter_mm": 11.031883587759774, "cover_mm": 3.1030809314467698},
              {"thickness_mm": 1.6, "clearance_mm": 0.23, "track_width_mm": 0.31, "via_drill_mm": 0.41,
               "via_diameter_mm": 0.84, "edge_clearance_mm": 0.52, "density": "least", "pullups": True,
               "mounting_hole_diameter_mm": 0.0, "mounting_hole_inset_mm": 2.0})

#: A design a small study verified and built (MagOne's disc, a 11.6 mm elastomer): both commands accept it.
BUILDS = ({"magnet": "d5_h2", "grade": "N52", "material": "ecoflex-00-30", "tip": "hemisphere",
           "d_max_mm": 5.6345799453449334, "d_min_mm": 2.7567890606328733,
           "elastomer_diameter_mm": 11.592219932823458, "cover_mm": 1.8926675739083367},
          dict(BASE.toml_dict()["pcb"]))

#: The users' case: a 20 mm elastomer on the base's stated 30 x 30 mm board. Both refuse, with one line.
WIDE = ({"magnet": "d5_h2", "grade": "N52", "material": "ecoflex-00-30", "tip": "flat", "d_max_mm": 6.0,
         "d_min_mm": 2.5, "elastomer_diameter_mm": 20.0, "cover_mm": 1.9}, dict(BASE.toml_dict()["pcb"]))
#: The same left to the fit: both accept (the board grows).
WIDE_SIZED = (WIDE[0], {k: v for k, v in WIDE[1].items() if k not in ("width_mm", "height_mm")})


def test_a_via_is_held_to_its_drill_s_clearance_by_the_rip_up():
    """The narrow via's rule, on its own: a track of another net 0.161 mm from the via clashes (0.21 mm needed)."""
    router = Router((0.0, 0.0, 10.0, 10.0), 0.1, 0.17, 0.41, 0.33, 0.12, 0.25, 0.3)
    via = Copper.point(5.0, 5.0, 0.205, LAYERS, "GND")
    track = Copper.seg(5.0 + 0.205 + 0.161 + 0.085, 4.0, 5.0 + 0.205 + 0.161 + 0.085, 6.0, 0.17, "F.Cu", "+3V3")
    assert _clash(via, track, router) and _clash(track, via, router)
    far = Copper.seg(5.0 + 0.205 + 0.22 + 0.085, 4.0, 5.0 + 0.205 + 0.22 + 0.085, 6.0, 0.17, "F.Cu", "+3V3")
    assert not _clash(via, far, router)


@pytest.mark.slow
def test_the_narrow_via_board_is_routed_clean():
    assert _agree(*NARROW_VIA, cad=False) is None


@pytest.mark.slow
def test_an_unroutable_board_is_refused_by_check_with_the_build_s_line():
    """(A failing route spends its search budget: over a minute here, both sides.)"""
    line = _agree(*UNROUTABLE, cad=False)
    assert line is not None and line.startswith("pcb: net SCL: no path from R2.2 to U1.3 with these rules")


def test_the_users_wide_elastomer_both_refuse_or_both_accept():
    spec = spec_of(*WIDE)
    line = check_says(spec)
    assert line is not None and line.startswith("pcb.width_mm = 30.0: leaves no room for the Qwiic connector")
    assert build_says(spec, cad=False) == line
    assert check_says(spec_of(*WIDE_SIZED)) is None


def test_a_spec_file_keeps_a_board_left_to_the_fit_unstated(tmp_path):
    """A spec written out (designs/NAME.toml) is read back to the same spec: a side left to the fit stays unstated
    (it was written as the default 30 mm, which the file's reader then refused as stated)."""
    spec = spec_of(*WIDE_SIZED)
    path = tmp_path / "agree.toml"
    path.write_bytes(spec_toml(spec, "agree"))
    again = load_spec(path)
    assert again == spec and not {"width_mm", "height_mm"} & again.pcb.model_fields_set
    assert check_says(again) is None


# ---- over the space -----------------------------------------------------------------------------------------------


@settings(max_examples=20, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(points(), boards())
@example(*WIDE)
def test_check_and_build_agree_up_to_the_routed_board(point, board):
    event(_key(_agree(point, board, cad=False)))


@pytest.mark.slow
@settings(max_examples=150, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(points(), boards())
@example(*NARROW_VIA)
@example(*WIDE_SIZED)
def test_check_and_build_agree_up_to_the_whole_cad_branch(point, board):
    event(_key(_agree(point, board, cad=True)))


# ---- the commands -------------------------------------------------------------------------------------------------


def _commands(spec: Spec, folder: Path) -> tuple[tuple[int, str], tuple[int, str]]:
    """(exit code, last line of output) of ``magfab check`` and of ``magfab build`` on ``spec``'s file."""
    path = folder / f"{spec.name}.toml"
    path.write_bytes(spec_toml(spec, spec.name))
    out = []
    for args in (["check", str(path)], ["build", str(path), "--out", str(folder / "build")]):
        run = CliRunner().invoke(main, args)
        lines = run.output.strip().splitlines()
        out.append((run.exit_code, lines[-1] if lines else ""))
    return out[0], out[1]


def _same_verdict(spec: Spec, folder: Path) -> None:
    (check_code, check_line), (build_code, build_line) = _commands(spec, folder)
    assert check_code in (0, 2) and build_code in (0, 2), (check_line, build_line)
    assert (check_code == 0) == (build_code == 0), (check_line, build_line)
    if check_code:
        assert check_line == build_line


def test_the_commands_agree_on_the_users_wide_elastomer(tmp_path):
    _same_verdict(spec_of(*WIDE), tmp_path)


@pytest.mark.slow
@settings(max_examples=6, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                 HealthCheck.function_scoped_fixture])
@given(points(), boards(), st.booleans())
@example(*BUILDS, False)
@example(*WIDE_SIZED, True)
def test_the_commands_agree(tmp_path_factory, point, board, strict):
    _same_verdict(spec_of(point, board, strict), tmp_path_factory.mktemp("agree"))


def test_check_refuses_with_the_line_of_the_stage_the_build_stops_at(monkeypatch):
    """The build stops at its design's checks before it predicts: where both find errors, check lists them all but
    refuses with the design's alone, as the build does (it said "... (and 1 more error(s))", counting the
    prediction's, a line the build never prints)."""
    design_error = Finding(Severity.ERROR, "a", "the design's", "x")
    prediction_error = Finding(Severity.ERROR, "b", "the prediction's", "y")
    monkeypatch.setattr(verdict_module, "design_findings", lambda design: [design_error])
    monkeypatch.setattr(verdict_module, "predict_with_findings", lambda design: (None, [prediction_error]))
    _design, findings, stop = verdict(BASE)
    assert findings == [design_error, prediction_error]
    assert str(stop) == str(BuildError([design_error])) == "x: the design's"
    monkeypatch.setattr(verdict_module, "design_findings", lambda design: [])
    assert str(verdict(BASE)[2]) == str(BuildError([prediction_error]))  # plan's _predictions raises with these
