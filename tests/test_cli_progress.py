"""Progress on stderr (magfab.cli_progress): plain lines where the output is not a terminal, none with --quiet, and
never a line before a refusal by the build's preflight (the one-line rule for bad input holds)."""

from __future__ import annotations

import contextlib
import io
import re

import pytest
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from magfab import cli_progress
from magfab.cli import main
from magfab.errors import InputError

LINE = re.compile(r"^magfab: (?P<phase>[a-z ()]+) (?P<done>\d+)/(?P<total>\d+) \((?P<pct>\d+) %\) in [0-9.]+ s"
                  r"(?P<left>, about .+ left)?$")


@st.composite
def _progress(draw):
    """A phase's calls as a study makes them: a total, a starting count (a resumed study starts part way) and
    counts that rise, in any steps, to the total."""
    total = draw(st.integers(1, 5000))
    first = draw(st.integers(0, total))
    steps = draw(st.lists(st.integers(1, max(1, total // 3)), max_size=60))
    done, counts = first, [first]
    for s in steps:
        done = min(total, done + s)
        counts.append(done)
    if counts[-1] != total:
        counts.append(total)
    return total, counts


@settings(max_examples=300, deadline=None)
@given(_progress())
def test_a_phase_is_written_at_each_tenth_and_at_its_end(drawn):
    """The lines of one phase: each in the documented form, at most one per tenth of it (so at most ten), each at a
    higher tenth than the last, the time left on every line but the one at the end; the end is always written when
    the phase did any work in this run."""
    total, counts = drawn
    err = io.StringIO()
    with contextlib.redirect_stderr(err), cli_progress.phases("lines") as say:
        assert say is not None
        for n in counts:
            say("search", n, total)
    lines = err.getvalue().splitlines()
    parsed = [LINE.match(line) for line in lines]
    assert all(parsed) and all(cli_progress.PROGRESS_LINE.fullmatch(line) for line in lines), lines
    tenths = [10 * int(m["done"]) // total for m in parsed if m]
    assert tenths == sorted(set(tenths)) and len(lines) <= 10
    assert all(m["total"] == str(total) and m["phase"] == "search" for m in parsed if m)
    assert all((m["left"] is None) == (m["done"] == str(total)) for m in parsed if m)
    if counts[-1] > counts[0]:
        assert parsed[-1] and parsed[-1]["done"] == str(total)
    else:
        assert lines == []


def test_the_way_follows_the_output(monkeypatch):
    monkeypatch.setattr("sys.stderr.isatty", lambda: True)
    assert cli_progress.way(False) == "live" and cli_progress.way(True) == "off"
    monkeypatch.setattr("sys.stderr.isatty", lambda: False)
    assert cli_progress.way(False) == "lines"


def _stages_then(stages: list[str], error: str | None):
    """A stand-in for the pipeline's build: says ``stages`` in turn, then refuses with ``error`` (or stops the test:
    the build's summary is not what is tested here)."""
    def build(spec, out_dir, progress, scan):
        for s in stages:
            if progress:
                progress(s)
        raise InputError(error or "stop here")
    return build


@pytest.mark.parametrize("quiet", [False, True])
def test_a_refusal_in_the_first_stage_is_the_only_line(monkeypatch, tmp_path, quiet):
    """The build's preflight runs in its first stage: a refusal there is the command's one line, progress or not."""
    monkeypatch.setattr("magfab.pipeline.build", _stages_then(["deriving the design"], "pcb.width_mm = 30.0: no room"))
    run = CliRunner().invoke(main, ["build", "--out", str(tmp_path / "b"), *(["--quiet"] if quiet else [])])
    assert run.exit_code == 2 and run.output.strip().splitlines() == ["magfab: error: pcb.width_mm = 30.0: no room"]


@pytest.mark.parametrize("quiet", [False, True])
def test_each_stage_is_a_line_when_done(monkeypatch, tmp_path, quiet):
    """Stages done before a later refusal are written, each once, in order, with their time; --quiet writes none."""
    monkeypatch.setattr("magfab.pipeline.build", _stages_then(["deriving the design", "modelling pad", "drawing"],
                                                               "a mesh check failed"))
    run = CliRunner().invoke(main, ["build", "--out", str(tmp_path / "b"), *(["--quiet"] if quiet else [])])
    lines = run.output.strip().splitlines()
    assert run.exit_code == 2 and lines[-1] == "magfab: error: a mesh check failed"
    if quiet:
        assert lines == lines[-1:]
    else:
        assert all(cli_progress.PROGRESS_LINE.fullmatch(line) for line in lines[:-1]), lines
        assert [re.sub(r"done in [0-9.]+ s$", "done", line) for line in lines[:-1]] == [
            "magfab: deriving the design: done", "magfab: modelling pad: done"]
