"""Progress of long work on stderr: a build's stages, a study's trials.

Three ways, one per output (:func:`way`):

- a terminal: one line redrawn in place (rich), the stage with the time since the work began, or a bar per phase of
  a study with its count and the time left; gone when the work ends;
- anything else (a CI log, a notebook's cell, a pipe): plain lines that a log keeps. A build's stage is written when
  it is done, with the time it took, so that a refusal by the build's preflight (in its first stage) is still the
  command's one line; a study's phase is written at every tenth of it, with the time left;
- ``--quiet`` (or ``--json`` for a build, whose stdout is read by a program): nothing.
"""

from __future__ import annotations

import re
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import TYPE_CHECKING

import click

if TYPE_CHECKING:
    from rich.progress import TaskID

__all__ = ["QUIET", "PROGRESS_LINE", "way", "stages", "phases", "duration"]

#: The option every long command takes.
QUIET = click.option("--quiet", "-q", is_flag=True, help="No progress on stderr (the results are printed as before).")
#: A line of progress as "lines" writes it (a stage done, a share of a phase): what a reader of the command's stderr
#: (bench/adversarial.py's judge of the one-line rule) sets apart from the line that says what went wrong.
PROGRESS_LINE = re.compile(r"magfab: (?:[^:]+: done in (?:\d+ min )?[0-9.]+ s"
                           r"|[a-z ()]+ \d+/\d+ \(\d+ %\) in (?:\d+ min )?[0-9.]+ s(?:, about .+ left)?)")
#: A study's phase is written as a line at each of these shares of it (when the output is not a terminal).
STEPS = 10


def way(quiet: bool) -> str:
    """"off" (quiet), "live" (stderr is a terminal) or "lines" (stderr is a file, a pipe or a notebook's cell)."""
    if quiet:
        return "off"
    return "live" if sys.stderr.isatty() else "lines"


def duration(seconds: float) -> str:
    """A time as a person reads it: 4.2 s, 3 min 05 s."""
    if seconds < 60:
        return f"{seconds:.1f} s"
    minutes, s = divmod(round(seconds), 60)
    return f"{minutes} min {s:02d} s"


@contextmanager
def stages(how: str) -> Iterator[Callable[[str], None] | None]:
    """A build's stage callback (the pipeline calls it as each stage starts). "live": the current stage and the time
    since the build began, redrawn only when the stage changes (no refresh thread runs while the build forks its
    worker process); "lines": each stage as a line when the next one starts (and the last when the build ends), with
    the time it took; "off": None."""
    if how == "off":
        yield None
        return
    if how == "lines":
        current: tuple[str, float] | None = None  # the stage under way and when it began

        def done() -> None:
            if current is not None:
                click.echo(f"magfab: {current[0]}: done in {duration(time.perf_counter() - current[1])}", err=True)

        def say(stage: str) -> None:
            nonlocal current
            done()
            current = (stage, time.perf_counter())

        yield say  # a refusal or an interrupt raises here: the stage under way is not written
        done()
        return
    began = time.perf_counter()
    from rich.console import Console  # lazy: rich draws only on a terminal
    from rich.live import Live
    from rich.text import Text

    with Live(Text("starting"), console=Console(stderr=True), auto_refresh=False, transient=True) as live:
        yield lambda stage: live.update(
            Text(f"magfab: {stage}... ({duration(time.perf_counter() - began)})"), refresh=True)


@contextmanager
def phases(how: str) -> Iterator[Callable[[str, int, int], None] | None]:
    """A study's progress callback (phase, done, total) for each of its phases (search, verify, sweep). "live": a bar
    per phase with its count, the time it has taken and the time left; "lines": a line at each tenth of a phase (and
    its end) with the time left, estimated from the phase's rate so far; "off": None."""
    if how == "off":
        yield None
        return
    if how == "lines":
        began: dict[str, tuple[float, int]] = {}  # when each phase was first heard of, and how far it was then
        written: dict[str, int] = {}

        def line(phase: str, done: int, total: int) -> None:
            now = time.perf_counter()
            since, first = began.setdefault(phase, (now, done))  # a resumed study starts part way
            whole = max(total, 1)
            step = STEPS * done // whole
            if done <= first or step <= written.get(phase, STEPS * first // whole):
                return
            written[phase] = step
            took = now - since
            left = "" if done >= total else f", about {duration(took * (total - done) / (done - first))} left"
            click.echo(f"magfab: {phase} {done}/{total} ({100 * done // whole} %) in {duration(took)}{left}", err=True)

        yield line
        return
    from rich.console import Console  # lazy: rich draws only on a terminal
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    tasks: dict[str, TaskID] = {}
    with Progress(TextColumn("magfab: {task.description}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
                  TimeRemainingColumn(), console=Console(stderr=True), transient=True) as bar:
        def update(phase: str, done: int, total: int) -> None:
            if phase not in tasks:
                tasks[phase] = bar.add_task(phase, total=total)
            bar.update(tasks[phase], completed=done, total=total)

        yield update
