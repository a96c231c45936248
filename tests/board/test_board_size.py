"""The board's size: ``magfab check`` and ``magfab build`` agree on it for every spec, and a spec that leaves it
unstated gets the least board that holds its parts (magfab.board.fit, README "Spec reference").

The issue this answers: an ``[array]`` spec without ``[pcb]`` passed ``magfab check`` while ``magfab build`` refused
it with "pcb.width_mm = 30.0: must be at least 34.5 mm", a value the user never wrote.

Check's verdict is what ``magfab check`` runs before its predictions (derive, then preflight; one CLI test below holds
the command to that). The build's verdict is what :func:`magfab.pipeline.plan` refuses, else what its board stage
refuses for the design plan goes on with: :func:`magfab.pcb.board` itself with the router stubbed out (the routing is
the only costly part and decides nothing about the size), then :func:`magfab.pcb.findings` less the connectivity only
routing makes.
"""

from __future__ import annotations

import itertools
import json
import re
import tomllib
from importlib import resources
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from magfab import derive, parse_spec, pcb, pipeline
from magfab.check import preflight
from magfab.cli import main
from magfab.errors import BuildError, MagfabError, Severity
from magfab.limits import check_limits
from magfab.reference_chip import reference_chip
from magfab.spec import default_spec_text, spec_from_dict

pytestmark = pytest.mark.filterwarnings("ignore")

#: Findings of the routed board's check that only routing makes (an unrouted board has every net in pieces).
ROUTING = {"pcb-unconnected", "pcb-unrouted"}
EXAMPLES = ("strip_1x5", "fingertip_2x2")
#: The issue's spec: the strip's taxels two to a row, 14 mm apart, no [pcb]: the build asked for 34.5 mm.
ISSUE = "[array]\nrows = 1\ncols = 2\npitch_mm = 14.0\n"


def _example_text(name: str) -> str:
    return resources.files("magfab.examples").joinpath(f"{name}.toml").read_text(encoding="utf-8")


def _example(name: str) -> dict:
    return tomllib.loads(_example_text(name))


def _without_pcb(name: str) -> str:
    """The example's text with its [pcb] section cut out."""
    text = _example_text(name)
    return re.sub(r"^\[pcb\]\n(?:(?!\[).*\n?)*", "", text, flags=re.MULTILINE)


def check_verdict(spec) -> str | None:
    """The line ``magfab check`` refuses ``spec`` with before its predictions, or None."""
    try:
        preflight(derive(spec))
    except MagfabError as exc:
        return str(exc)
    return None


class _Planned(Exception):
    """Carries the design :func:`plan` goes on with past its refusals, out of the build."""


def _planned(spec):
    """The design :func:`plan` goes on with (caught at the first step after its refusals), or its refusal."""
    def stop(design):
        raise _Planned(design)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(pipeline, "design_findings", stop)
        try:
            pipeline.plan(spec, parallel=False)
        except _Planned as planned:
            return planned.args[0]
        except MagfabError as exc:
            return exc
    raise AssertionError("plan neither refused nor reached its design findings")


def board_stage(design) -> str | None:
    """What the build's board stage refuses ``design``'s board with, routing aside (module doc), or None."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(pcb, "route_all", lambda router, parts, order: ([], []))
        try:
            board = pcb.board(design)
        except MagfabError as exc:
            return str(exc)
    errors = [f for f in pcb.findings(board) if f.severity is Severity.ERROR and f.code not in ROUTING]
    return str(BuildError(errors)) if errors else None


def build_verdict(spec) -> str | None:
    """The line the build refuses ``spec`` with, as far as its board's size goes (module doc), or None."""
    planned = _planned(spec)
    return str(planned) if isinstance(planned, MagfabError) else board_stage(planned)


# ---- the issue ---------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("text, width", [(ISSUE, 34.5), (_without_pcb("strip_1x5"), 76.5)],
                         ids=["issue-1x2", "strip_1x5-without-pcb"])
def test_an_array_without_a_board_size_passes_check_and_the_build_places_a_board_sized_to_fit(text, width):
    spec = parse_spec(text, "strip")
    assert spec.array is not None and not spec.pcb.model_fields_set
    assert check_verdict(spec) is None
    assert build_verdict(spec) is None  # was "pcb.width_mm = 30.0: must be at least 34.5 mm ..."
    design = _planned(spec)
    board = pcb.placed(design)
    size = (design.spec.pcb.width_mm, design.spec.pcb.height_mm)
    x0, y0, x1, y1 = board.outline
    assert size[0] == width and (x1 - x0, y1 - y0) == pytest.approx(size)
    assert json.loads(json.dumps(design.as_dict()))["pcb_sized"] == {"width_mm": size[0], "height_mm": size[1]}


def test_check_refuses_a_stated_board_too_small_with_the_build_s_line_and_passes_the_issue_spec(tmp_path):
    """The command itself, not only its first two steps: exit 2 and the build's one line before any prediction; the
    issue's spec passes, saying which size it chose."""
    small = tmp_path / "small.toml"
    small.write_text(ISSUE + "[pcb]\nwidth_mm = 30.0\nheight_mm = 34.0\n")
    refused = CliRunner().invoke(main, ["check", str(small)])
    line = board_stage(derive(parse_spec(small.read_text(), "small")))  # the build's own refusal of this board
    assert refused.exit_code == 2 and line == "pcb.width_mm = 30.0: must be at least 34.5 mm so the array's 34 x 20 " \
        "mm mounting pad fits on the board, centred on it"
    assert refused.output.strip().endswith(line) and check_verdict(parse_spec(small.read_text())) == line
    issue = tmp_path / "issue.toml"
    issue.write_text(ISSUE)
    passed = CliRunner().invoke(main, ["check", str(issue)])
    assert passed.exit_code == 0, passed.output
    assert "info: board sized to fit, 34.5 x " in passed.output and "[pcb]" in passed.output


# ---- over the space ----------------------------------------------------------------------------------------------


@st.composite
def array_specs(draw):
    """An example's array, its grid and pitch scaled, its board stated (each side near the example's, or far off)
    or not; half of them with a coarse mould, which the cost limits let through for more of the larger grids."""
    name = draw(st.sampled_from(EXAMPLES))
    raw = _example(name)
    rows, cols = draw(st.integers(1, 4)), draw(st.integers(1, 4))
    raw["array"].update(rows=rows, cols=cols, pitch_mm=round(raw["array"]["pitch_mm"] * draw(st.floats(0.9, 1.6)), 1))
    board = {}
    for side in ("width_mm", "height_mm"):
        how = draw(st.sampled_from(["unstated", "near", "any"]))
        if how == "near":
            board[side] = raw["pcb"][side] + 0.5 * draw(st.integers(-30, 30))
        elif how == "any":
            board[side] = float(draw(st.integers(15, 120)))
    raw["pcb"] = board
    if draw(st.booleans()):
        raw["mould"] = {"tessellation_tolerance_mm": 0.1, "angular_tolerance_deg": 30.0}
    return spec_from_dict(raw)


def _agree(spec) -> str | None:
    """Check's verdict is the build's; a board check lets through is the least that holds the parts, fitted once for
    all (its spec.json rebuilds it), and check refuses no stated board the build would make."""
    check = check_verdict(spec)
    assert check == build_verdict(spec)
    stated = {"width_mm", "height_mm"} <= spec.pcb.model_fields_set
    if check is None:
        design = preflight(derive(spec))
        assert preflight(design) is design  # a fitted board stays as it is
        again = preflight(derive(spec_from_dict(design.spec.toml_dict())))  # spec.json: every side stated
        assert again.spec.pcb == design.spec.pcb and again.pcb_sized == ()
        for side in design.pcb_sized:  # the least: a step smaller is refused, unless it is where the search starts
            smaller = getattr(design.spec.pcb, side) - 0.5
            if smaller >= 30.0 and smaller >= _pad_side(design, side):
                less = design.spec.model_copy(update={"pcb": design.spec.pcb.model_copy(update={side: smaller})})
                assert check_verdict(less) is not None, (side, smaller)
    elif stated:  # refused for the board: the build's board stage, asked without check, says the same line
        try:
            design = derive(spec)
            reference_chip(design)
            check_limits(design)
        except MagfabError:
            return check
        assert board_stage(design) == check
    return check


def _pad_side(design, side: str) -> float:
    from magfab.board.placement import pad_room_mm

    return dict(zip(("width_mm", "height_mm"), pad_room_mm(design)))[side]


@settings(max_examples=50, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(array_specs())
def test_check_and_build_agree_on_the_board_over_arrays(spec):
    check = _agree(spec)
    event("ok" if check is None else check.split(" = ")[0].split(":")[0])  # the key refused, in the statistics


@pytest.mark.slow
def test_check_and_build_agree_on_the_board_over_every_small_grid():
    """Exhaustive: each example, every grid up to 4 x 4, three pitches, the board unstated, one side stated near
    the example's, both stated."""
    for name, rows, cols, scale in itertools.product(EXAMPLES, range(1, 5), range(1, 5), (0.95, 1.0, 1.5)):
        raw = _example(name)
        raw["array"].update(rows=rows, cols=cols, pitch_mm=round(raw["array"]["pitch_mm"] * scale, 1))
        example = raw.pop("pcb")
        for board in ({}, {"width_mm": example["width_mm"]}, {"height_mm": example["height_mm"] - 6.0}, example):
            _agree(spec_from_dict({**raw, "pcb": board}))


# ---- the rule's parts ---------------------------------------------------------------------------------------------


def test_a_board_the_default_holds_is_left_as_it_is():
    """MagOne states 30 x 30; a spec without [pcb] keeps the default where it holds the parts: the same design."""
    smaller_pad = "[pad]\ndiameter_mm = 18\nalignment_hole_spacing_mm = 15\n"
    for spec in (parse_spec(default_spec_text()), parse_spec(""), parse_spec(smaller_pad)):
        design = derive(spec)
        assert preflight(design) is design and "pcb_sized" not in design.as_dict()


def test_a_single_taxel_whose_pad_outgrows_the_default_gets_a_board_sized_to_fit():
    spec = parse_spec("[pad]\ndiameter_mm = 30\nalignment_hole_spacing_mm = 24\n")
    assert check_verdict(spec) is None and build_verdict(spec) is None
    design = preflight(derive(spec))
    assert design.pcb_sized == ("width_mm", "height_mm") and design.spec.pcb.width_mm == 30.5
    assert design.spec.pcb.height_mm > 30.5  # the connector goes below the pad


def test_a_side_stated_too_small_is_refused_with_the_user_s_value_and_the_other_is_sized():
    spec = parse_spec(ISSUE + "[pcb]\nwidth_mm = 33\n")
    assert check_verdict(spec) == build_verdict(spec) == ("pcb.width_mm = 33.0: must be at least 34.5 mm so the "
                                                          "array's 34 x 20 mm mounting pad fits on the board, centred "
                                                          "on it")
    design = preflight(derive(parse_spec(ISSUE + "[pcb]\nwidth_mm = 34.5\n")))
    assert design.spec.pcb.width_mm == 34.5 and design.pcb_sized == ("height_mm",) and design.spec.pcb.height_mm > 30
    wide = derive(parse_spec(ISSUE + "[pcb]\nwidth_mm = 50\n"))  # the connector beside the pad: 30 mm high holds it
    assert preflight(wide) is wide


def test_a_board_beyond_the_largest_a_spec_may_state_is_refused_saying_it_was_not_stated():
    with pytest.raises(MagfabError) as refused:
        # five chips (few enough to route within the budget) 50 mm apart: a 220 mm pad
        preflight(derive(parse_spec("[array]\nrows = 1\ncols = 5\npitch_mm = 50\n[mould]\ncavities = 1\n"
                                     "tessellation_tolerance_mm = 0.1\nangular_tolerance_deg = 30\n")))
    text = str(refused.value)
    assert text.startswith("pcb.width_mm = 200.0: must be at least 220.5 mm") and "not stated" in text, text


@pytest.mark.slow
def test_the_least_found_by_bisection_is_the_least_a_scan_finds():
    """Two searches agree: stepping up 0.5 mm at a time from where the rule starts (the default or the pad's side
    with its keep-out, rounded up) finds the width the fit chose (at the largest height it may try) and then its
    height (at that width), for every grid the fit sizes."""
    from magfab.board.fit import refusal
    from magfab.board.placement import pad_room_mm, resized

    def first(design, side, start, other):
        size = start
        while refusal(resized(design, {side: size, **other}), hint=False) is not None:
            size += 0.5
        return size

    checked = 0
    for name, rows, cols in itertools.product(EXAMPLES, range(1, 5), range(1, 5)):
        raw = _example(name)
        raw["array"].update(rows=rows, cols=cols)
        raw["pcb"] = {}
        raw["mould"] = {"tessellation_tolerance_mm": 0.1, "angular_tolerance_deg": 30.0}
        try:
            design = derive(spec_from_dict(raw))
            fitted = preflight(design)
        except MagfabError:
            continue
        if not fitted.pcb_sized:
            continue
        start = [max(30.0, -(-need // 0.5) * 0.5) for need in pad_room_mm(design)]
        width = first(design, "width_mm", start[0], {"height_mm": min(start[1] + 40.0, 200.0)})
        height = first(design, "height_mm", start[1], {"width_mm": width})
        assert (fitted.spec.pcb.width_mm, fitted.spec.pcb.height_mm) == (width, height), (name, rows, cols)
        checked += 1
    assert checked >= 10


@pytest.mark.slow
def test_the_issue_spec_builds_with_its_board_sized_to_fit_and_rebuilds_from_its_spec_json(tmp_path):
    """The whole build: exit 0; design.json, spec.json, findings.json and the board's outline say 34.5 mm; the
    routed board passes its check; the folder's spec.json (what ``magfab calibrate`` rebuilds from) states the size,
    and check lets it through unchanged."""
    from magfab.spec import load_build_spec

    spec = tmp_path / "issue.toml"
    spec.write_text(ISSUE)
    out = tmp_path / "out"
    result = CliRunner().invoke(main, ["build", str(spec), "--out", str(out)])
    assert result.exit_code == 0, result.output
    sized = json.loads((out / "design.json").read_text())["pcb_sized"]
    assert sized["width_mm"] == 34.5 and sized["height_mm"] > 30.0
    assert {k: v for k, v in json.loads((out / "spec.json").read_text())["pcb"].items() if k in sized} == sized
    codes = {f["code"] for f in json.loads((out / "findings.json").read_text())}
    assert {"pcb-sized", "pcb-ok"} <= codes
    board = (out / "pcb" / "issue.kicad_pcb").read_text()
    x0, y0, x1, y1 = map(float, re.search(r'\(gr_rect \(start ([\d.]+) ([\d.]+)\) \(end ([\d.]+) ([\d.]+)\) '
                                          r'\(layer "Edge.Cuts"\)', board).groups())
    assert (x1 - x0, y1 - y0) == pytest.approx((sized["width_mm"], sized["height_mm"]))
    again = derive(load_build_spec(out))
    size = (again.spec.pcb.width_mm, again.spec.pcb.height_mm)
    assert preflight(again) is again and size == (sized["width_mm"], sized["height_mm"])


def test_the_readme_s_example_is_the_size_the_fit_chooses():
    readme = (Path(__file__).parents[2] / "README.md").read_text(encoding="utf-8")
    design = preflight(derive(parse_spec(ISSUE)))
    size = f"{design.spec.pcb.width_mm:g} x {design.spec.pcb.height_mm:g} mm"
    assert f"get a {size} board" in readme and f"board sized to fit, {size}:" in readme
