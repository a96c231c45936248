"""The second adversarial pass, run as a user would: generated hostile inputs through both CLIs, each in a child
process held to the budget, every outcome classified and counted per class.

Run from anywhere::

    python bench/adversarial.py [--quick] [--seed N] [--json out.json] [--only CLASS ...] [--keep-failures DIR]

``--quick`` draws fewer cases per class and skips the real builds near the budget (about 5 minutes on two cores);
the full run draws more and builds the most expensive specs the limits allow (about 20-30 minutes). The cases are
drawn from seeded generators (``--seed``, default 0): the same seed draws the same cases.

The classes (the project's adversarial pass):

1. inputs without a size or shape bound: TOML and JSON nested past the readers' depth, tables of many unknown keys,
   FIFOs, /dev/zero, directories and files over their kind's limit, in every reader of both CLIs;
2. limits that leave work out: tessellation tolerances, scan steps and arrays near and past the estimate's edge,
   ``sweep --grid/--lhs/--workers``, a study's trials; refused before the work, or finished within the budget
   (the most expensive specs the limits allow are built for real in the full run);
3. crashes where a one-line error belongs: malformed ``--scheduler`` addresses, calibrations the EEPROM record
   cannot hold, ``--out`` paths too long for the file system, storage URLs a study refuses;
4. values the validator accepts that the device cannot survive: generated calibration.json documents
   (tests/calibration_strategies.py) uploaded to the simulated board; an accepted one is evaluated over its valid
   region and the chip's temperature range by the host's model and, when gcc is found, by the firmware's record
   check and evaluation compiled for the host (tests/export/test_firmware_bounds.py's harness) on the EEPROM bytes
   the upload wrote;
5. guards a wrong input slips past: a reference log that is the recording's own forces resampled, shifted, scaled,
   tared, bent, rounded or noised; a dead, constant or one-dead-channel reference; a scan whose force columns are
   the sensor's own; an independent reference as the control (it must pass);
6. data loss: names like magfab's temporaries beside the build, the user's files in it, Ctrl-C and SIGKILL at
   every step of the build's swap and during the work, refusals that must leave a folder alone;
7. decoder speed: large adversarial byte strings into the readout's frame decoder, fed at once and in chunks: the
   time per byte at 8 times the size must stay flat (linear time);
8. exit codes: usage and input errors of both CLIs: exit 2 and one line, exit 1 only for a bug.

Each case runs in a fresh folder, in a child process with its address space limited (``RLIMIT_AS``, 4.5 GB) and
killed after 90 s; its wall time, CPU time and peak memory (the larger of its ``wait4`` ``ru_maxrss`` and the
resident memory of its whole session sampled from /proc every 0.1 s; the CPU time likewise, the larger of the two)
are measured. Outcomes:

* **refused**: exit 2, exactly one non-empty line on stderr, no traceback, the folder byte for byte as before (the
  argument parsers' own usage block, click's three lines and argparse's two, is counted here and reported apart);
* **ok**: exit 0 for a case that is legitimately valid (or a refusal-or-success case that finished; `magfab design`'s
  exit 3, no design met the targets, in one line, is a result too);
* **stopped**: an interrupted case that ended as it must (exit 130 in one line, or killed), the folder as required;
* **unclean**: exit 2 but more than one line or something written, or an exit code neither 0, 1, 2 nor 130;
* **other reason**: a clean refusal whose line does not name what the case is about (the guard under test did not
  fire: something else refused first);
* **wrongly refused**: a clean refusal of a valid case;
* **accepted bad**: exit 0 for a case that must be refused, or whose result fails the case's own check (a
  calibration the device cannot evaluate, an incomplete build);
* **traceback**: a traceback, exit 1, or a signal the runner did not send;
* **over budget**: killed at the timeout, out of memory, over 4 GB, or (the decoder) superlinear;
* **lost** (counted beside the rest): a file or folder the case must not touch changed or vanished;
* **>60s** (counted beside the rest, listed as SLOW): finished before the kill but past the budget's minute of wall
  time (on a loaded machine wall time grows: its CPU time is listed too).

Some class 6 cases replay the plan of the reference build (``pipeline.plan`` returns the reference build's result,
as tests/test_output.py does in-process) so the swap is exercised at every step in seconds; they say so in their
name. Nothing here fixes anything: a failing case is listed with its command and input for whoever owns the code.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import math
import os
import random
import resource
import shlex
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
TESTS = ROOT / "tests"
BENCH = ROOT / "bench"
EXAMPLES = ROOT / "magfab" / "examples"
PY = sys.executable

#: The budget every valid input is held to (magfab.limits.BUDGET_S; "about a minute or 4 GB" on two cores).
BUDGET_S = 60.0
BUDGET_MB = 4096.0
#: Each child: its address space (a little over the budget, so the budget is what is measured) and its wall time.
CHILD_AS_BYTES = int(4.5 * 1024**3)
TIMEOUT_S = 90.0
#: The decoder: the time per byte at 8 times the size may grow by at most this factor (noise on a shared machine).
LINEAR_FACTOR = 3.0

CLASSES = {1: "unbounded inputs", 2: "limits", 3: "one-line errors", 4: "accepted, not survivable",
           5: "guards", 6: "data loss", 7: "decoder speed", 8: "exit codes"}
LABELS = ("refused", "ok", "stopped", "unclean", "other reason", "wrongly refused", "accepted bad", "traceback",
          "over budget")
#: The labels that are failures (with lost data): listed case by case at the end.
FAILURES = ("unclean", "other reason", "wrongly refused", "accepted bad", "traceback", "over budget")
MEMORY_WORDS = ("MemoryError", "Cannot allocate memory", "std::bad_alloc", "out of memory")

MAGFAB_MAIN = "import sys; from magfab.cli import main; sys.argv[0] = 'magfab'; main()"

#: ``magfab`` with the build's output steps hooked (argv: MODE ARG REPLAY, then magfab's arguments). MODE "count"
#: appends each step's name to the file ARG; "SIGINT" or "SIGKILL" sends that signal to itself at step ARG (1-based);
#: "none" does neither. REPLAY, unless "-", is a pickled BuildResult that ``pipeline.plan`` returns instead of
#: computing one ("ctrl-c-in-plan" as MODE: plan sends SIGINT to itself, a user's Ctrl-C during the work).
WRAPPED = """
import dataclasses, os, pickle, signal, sys, time
sys.path.insert(0, {tests!r})
mode, arg, replay = sys.argv[1:4]
from magfab import output, pipeline
if replay != "-":
    with open(replay, "rb") as f:
        saved = pickle.load(f)

    def plan(spec, progress=None, scan=None):
        if mode == "ctrl-c-in-plan":
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(5)
        return dataclasses.replace(saved, out_dir=None, timings_s=dict(saved.timings_s))

    pipeline.plan = plan
steps = []

def hook(what):
    steps.append(what)
    if mode == "count":
        with open(arg, "a") as f:
            f.write(what + "\\n")
    elif mode in ("SIGINT", "SIGKILL") and len(steps) == int(arg):
        os.kill(os.getpid(), getattr(signal, mode))

output._step_hook = hook
sys.argv = ["magfab", *sys.argv[4:]]
from magfab.cli import main
main()
"""

#: The reference build, written by the pipeline and its result pickled for the replayed plans (argv: spec, folder,
#: pickle). tests/conftest.py's pickler takes the recipes' read-only tables.
GOLDEN = """
import sys
from pathlib import Path
sys.path.insert(0, {tests!r})
from conftest import _dumps
from magfab import build, load_spec
result = build(load_spec(sys.argv[1]), Path(sys.argv[2]))
Path(sys.argv[3]).write_bytes(_dumps(result))
"""

#: The frame decoder's CPU time per byte at two sizes, best of three interleaved (argv: kind, seed, chunk, small,
#: large); prints JSON.
DECODE = """
import json, random, sys, time
sys.path.insert(0, {bench!r})
kind, seed, chunk, small, large = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
from magfab_readout import frames
import decode

def frame(k):
    return frames.encode_frame(k, 1840 * k, 0, (120, -40, 21000 + k % 50), 46000, (0.01, -0.02, 0.5 + k % 7 / 10))

def data(size):
    rng = random.Random(seed)
    if kind in decode.KINDS:
        return decode.flood(frames, kind, size)
    out = bytearray()
    while len(out) < size:
        if kind == "crc-bad":
            f = bytearray(frame(len(out)))
            f[rng.randrange(2, len(f))] ^= 1 << rng.randrange(8)
            out += f
        elif kind == "truncated":
            out += frame(len(out))[:rng.randrange(1, frames.FRAME_LENGTH)]
        elif kind == "sync+random":
            out += rng.randbytes(rng.randrange(0, 40)) + frames.SYNC
        elif kind == "long line":
            out += b"F," + b"1" * size
        elif kind == "lines":
            head = rng.choice([b"F,", b"I,", b"W,", b"R,", b"B,", b"X,"])
            out += head + bytes(rng.randrange(32, 127) for _ in range(rng.randrange(0, 400))) + b"\\n"
        else:  # mixed
            part = rng.randrange(5)
            out += [frame(len(out)), frame(len(out))[:rng.randrange(1, 31)], frames.SYNC + rng.randbytes(5),
                    b"F," + b"9" * rng.randrange(300), rng.randbytes(rng.randrange(64))][part]
    return bytes(out[:size])

def seconds(d):
    # CPU time (a loaded machine's waits left out), the small input fed over again to take as long as the large one
    rounds = max(1, large // len(d))
    start = time.process_time()
    for _ in range(rounds):
        decoder = frames.Decoder()
        for i in range(0, len(d), chunk):
            decoder.feed(d[i:i + chunk])
    return (time.process_time() - start) / rounds / len(d)

inputs = {{"small": data(small), "large": data(large)}}
best = {{"small": float("inf"), "large": float("inf")}}
for _ in range(3):  # interleaved, the best of each kept
    for name, d in inputs.items():
        best[name] = min(best[name], seconds(d))
print(json.dumps(best))
"""


# ---- running one child ----------------------------------------------------------------------------------------


@dataclass
class Result:
    """One child's run: exit code (negative: the signal that ended it), output, wall and CPU seconds, peak MB."""

    code: int
    stdout: str
    stderr: str
    wall_s: float
    cpu_s: float
    peak_mb: float
    timed_out: bool = False
    sent: int | None = None  # the signal the runner sent it, if any


def _limit_child() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (CHILD_AS_BYTES, CHILD_AS_BYTES))


_PAGE_MB = os.sysconf("SC_PAGE_SIZE") / 2**20


_TICK_S = 1.0 / os.sysconf("SC_CLK_TCK")


def session_usage(session: int, cpu: dict[int, float] | None = None) -> float:
    """Resident memory, MB, of every process of ``session`` (the child and what it started), from /proc; ``cpu``
    gets each one's CPU seconds so far by pid (what wait4 cannot count: a killed child's own children)."""
    total = 0
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            with open(f"/proc/{entry.name}/stat", "rb") as f:
                data = f.read()
        except OSError:
            continue
        fields = data[data.rfind(b")") + 2:].split()  # from field 3 (state) on: session 6, utime 14, stime 15, rss 24
        if len(fields) > 21 and int(fields[3]) == session:
            total += int(fields[21])
            if cpu is not None:
                cpu[int(entry.name)] = (int(fields[11]) + int(fields[12])) * _TICK_S
    return total * _PAGE_MB


def _killpg(pgid: int, sig: int) -> None:
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(pgid, sig)


def run_child(argv: Sequence[str], cwd: Path, env: dict[str, str], timeout_s: float = TIMEOUT_S,
              signal_at: tuple[float, int] | None = None) -> Result:
    """``argv`` in ``cwd`` in its own session, its address space limited; killed (the whole session) after
    ``timeout_s``; ``signal_at`` (seconds, signal) sends a signal to the session, as a user's Ctrl-C."""
    # A child's ru_maxrss starts at this process's resident size when it forked (Linux keeps the high-water mark
    # across exec): it is the child's own only when above that; below, the samples of /proc are the measure.
    floor_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with tempfile.TemporaryFile() as out, tempfile.TemporaryFile() as err:
        start = time.perf_counter()
        proc = subprocess.Popen(list(argv), cwd=cwd, env=env, stdin=subprocess.DEVNULL, stdout=out, stderr=err,
                                preexec_fn=_limit_child, start_new_session=True)
        state: dict[str, Any] = {"peak": 0.0, "timed_out": False, "sent": None}
        cpu: dict[int, float] = {}
        done = threading.Event()

        def watch() -> None:
            while not done.wait(0.1):
                elapsed = time.perf_counter() - start
                state["peak"] = max(state["peak"], session_usage(proc.pid, cpu))
                if signal_at is not None and state["sent"] is None and elapsed >= signal_at[0]:
                    state["sent"] = signal_at[1]
                    _killpg(proc.pid, signal_at[1])
                if elapsed > timeout_s:
                    state["timed_out"] = True
                    _killpg(proc.pid, signal.SIGKILL)
                    return

        watcher = threading.Thread(target=watch, daemon=True)
        watcher.start()
        try:
            _, status, usage = os.wait4(proc.pid, 0)
        except BaseException:  # the runner interrupted: its child's session goes with it
            _killpg(proc.pid, signal.SIGKILL)
            proc.wait()
            raise
        wall = time.perf_counter() - start
        done.set()
        watcher.join()
        proc.returncode = code = os.waitstatus_to_exitcode(status)
        _killpg(proc.pid, signal.SIGKILL)  # whatever it left running (a local cluster's workers)
        out.seek(0)
        err.seek(0)
        return Result(code, out.read().decode("utf-8", "replace"), err.read().decode("utf-8", "replace"), wall,
                      max(usage.ru_utime + usage.ru_stime, sum(cpu.values())),
                      max(usage.ru_maxrss / 1024.0 if usage.ru_maxrss > floor_kb else 0.0, state["peak"]),
                      state["timed_out"], state["sent"])


# ---- a folder's contents ---------------------------------------------------------------------------------------

def _digest(path: str, st: os.stat_result) -> str:
    if st.st_size > 16 * 2**20:  # a sparse or huge input: its size and time, not its bytes
        return f"{st.st_size} bytes, mtime {st.st_mtime_ns}"
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def tree(folder: Path) -> dict[str, tuple]:
    """Everything under ``folder`` (never following links, never reading a FIFO or a device): files by hash,
    links by target, folders and special files by kind."""
    found: dict[str, tuple] = {}
    if not folder.exists() and not folder.is_symlink():
        return found
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            path = os.path.join(root, name)
            rel = os.path.relpath(path, folder)
            st = os.lstat(path)
            if stat.S_ISLNK(st.st_mode):
                found[rel] = ("link", os.readlink(path))
            elif stat.S_ISREG(st.st_mode):
                found[rel] = ("file", _digest(path, st))
            elif stat.S_ISDIR(st.st_mode):
                found[rel] = ("dir",)
            else:
                found[rel] = ("special", stat.S_IFMT(st.st_mode))
    return found


def entry(path: Path) -> Any:
    """One path's content for a before/after comparison: a file's hash, a link's target, a folder's tree."""
    if path.is_symlink():
        return ("link", os.readlink(path))
    if path.is_dir():
        return ("dir", tree(path))
    if path.is_file():
        return ("file", _digest(str(path), path.stat()))
    return None if not path.exists() else ("special",)


def changes(before: dict, after: dict) -> list[str]:
    added = sorted(set(after) - set(before))
    gone = sorted(set(before) - set(after))
    changed = sorted(k for k in set(before) & set(after) if before[k] != after[k])
    return [f"+{k}" for k in added] + [f"-{k}" for k in gone] + [f"~{k}" for k in changed]


# ---- cases and their outcomes ---------------------------------------------------------------------------------

Check = Callable[[Path, "list[Result]"], "tuple[str, str] | None"]


@dataclass
class Case:
    """One input run as a user would. ``args`` may hold ``{here}`` (the case's folder, absolute). ``expect``:
    "refuse", "ok", "either" (refused cleanly or finished) or "stop" (interrupted: exit 130 or the runner's
    signal). ``words``: what a refusal's line must name (all, case-insensitive). ``keep``: paths (relative to the
    folder) that must be byte for byte the same afterwards whatever the outcome. ``check``: run after the case on
    its folder and results, returns (label, why) when the result is wrong. ``then``: commands the user runs next
    (after a kill), judged too."""

    cls: int
    name: str
    prog: str  # "magfab", "readout", "wrapped" (WRAPPED; args: mode arg replay, then magfab's) or "python"
    args: list[str]
    setup: Callable[[Path], None] | None = None
    expect: str = "refuse"
    words: tuple[str, ...] = ()
    keep: tuple[str, ...] = ()
    check: Check | None = None
    then: list[tuple[str, list[str]]] = field(default_factory=list)
    signal_at: tuple[float, int] | None = None
    code: str = ""  # the program of prog "python"
    cwd: str = ""  # where it runs, relative to the case's folder (default: the folder)
    detail: str = ""  # the generator's parameters, for the report
    timeout_s: float = TIMEOUT_S
    allowed_s: float = BUDGET_S  # past this wall time a finished case is listed as SLOW (a study: its estimate)
    result_codes: tuple[int, ...] = ()  # exit codes beside 0 that are a result, not an error (design's 3: none met)

    def command(self, prog: str | None = None, args: Sequence[str] | None = None) -> str:
        prog = prog or self.prog
        args = list(self.args if args is None else args)
        shown = "magfab" if prog in ("magfab", "wrapped") else "magfab-readout" if prog == "readout" else "python"
        if prog == "wrapped":
            mode, arg, replay, *args = args
            note = {"none": "", "count": " (steps counted)", "ctrl-c-in-plan": " (Ctrl-C during the work)"}.get(
                mode, f" ({mode} at swap step {arg})")
            shown_args = " ".join(_short(a) for a in args)
            return f"magfab {shown_args}{note}" + (" [plan replayed]" if replay != "-" else "")
        return shown + (" " + " ".join(_short(a) for a in args) if args else "")


def _short(arg: str) -> str:
    text = shlex.quote(arg)
    return text if len(text) <= 100 else f"{text[:60]}...({len(arg)} chars)"


@dataclass
class Outcome:
    cls: int
    name: str
    command: str
    label: str
    lost: bool
    why: str
    code: int
    wall_s: float
    cpu_s: float
    peak_mb: float
    usage_block: bool = False
    slow: bool = False  # finished, but past its allowance (the budget's minute; a study's own estimate)
    detail: str = ""
    stderr_tail: str = ""
    folder: str = ""
    allowed_s: float = BUDGET_S


def _lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


def _said(stderr: str) -> list[str]:
    """The lines of a run's stderr that say something: its progress lines (a build's stages done, a study's share of
    a phase, written where stderr is not a terminal) apart."""
    from magfab.cli_progress import PROGRESS_LINE

    return [line for line in _lines(stderr) if not PROGRESS_LINE.fullmatch(line)]


def usage_block(lines: list[str]) -> bool:
    """The argument parser's own refusal: click's "Usage: ..." / "Try ..." / "Error: ...", argparse's "usage: ..." /
    "PROG: error: ..." (a usage line may wrap)."""
    if not lines:
        return False
    click = lines[0].startswith("Usage:") and lines[-1].startswith("Error:")
    argparse_ = lines[0].startswith("usage:") and ": error: " in lines[-1]
    return (click or argparse_) and len(lines) <= 12


def judge(case: Case, res: Result, before: dict, after: dict) -> tuple[str, str, bool]:
    """(label, why, usage block) of one run, by the rules in the module's docstring (lost data apart)."""
    text = res.stdout + "\n" + res.stderr
    lines = _said(res.stderr)
    last = lines[-1][:300] if lines else ""
    if res.timed_out:
        return "over budget", f"killed after {case.timeout_s:.0f} s of wall time, {res.cpu_s:.0f} s of CPU", False
    if any(w in text for w in MEMORY_WORDS) or res.peak_mb > BUDGET_MB:
        return "over budget", f"out of memory or over {BUDGET_MB:.0f} MB ({res.peak_mb:.0f} MB): {last}", False
    if "Traceback (most recent call last)" in text:
        return "traceback", "a traceback: " + last, False
    if res.code < 0:
        ours = res.sent == -res.code or (case.expect == "stop" and res.code == -signal.SIGKILL)  # SIGKILL: the hook's
        if not ours:
            return "traceback", f"died of signal {-res.code}: {last}", False
        if case.expect != "stop":
            return "unclean", f"killed by the runner's signal {-res.code}", False
        return "stopped", f"killed by signal {-res.code}", False
    if res.code == 1:
        return "traceback", "exit 1: " + last, False
    written = changes(before, after)
    if res.code == 2:
        usage = usage_block(lines)
        if not (len(lines) == 1 or usage):
            return "unclean", f"exit 2 with {len(lines)} lines on stderr: {' | '.join(lines[:3])[:300]}", usage
        if written:
            return "unclean", f"refused but wrote {', '.join(written[:5])}: {last}", usage
        if case.expect == "ok":
            return "wrongly refused", last, usage
        if case.expect == "stop":
            return "unclean", f"refused instead of stopped: {last}", usage
        missing = [w for w in case.words if w.lower() not in last.lower()]
        if missing and not usage:
            return "other reason", f"does not name {missing}: {last}", usage
        return "refused", last, usage
    if res.code == 130:
        if case.expect != "stop":
            return "unclean", "exit 130 without an interrupt: " + last, False
        if len(lines) != 1:
            return "unclean", f"exit 130 with {len(lines)} lines on stderr: {' | '.join(lines[:3])[:300]}", False
        return "stopped", last, False
    if res.code in case.result_codes and len(lines) == 1 and case.expect in ("ok", "either"):
        return "ok", f"exit {res.code} (a result): {last}", False
    if res.code == 0:
        if case.expect == "refuse":
            return "accepted bad", "exit 0: " + (_lines(res.stdout) or [""])[-1][:300], False
        if case.expect == "stop":
            return "unclean", "ran to the end though interrupted", False
        return "ok", (_lines(res.stdout) or [""])[-1][:300], False
    return "unclean", f"exit {res.code}: {last}", False


class Runner:
    def __init__(self, env: Env, keep_failures: Path | None) -> None:
        self.env = env
        self.keep_failures = keep_failures
        self.outcomes: list[Outcome] = []

    def argv(self, prog: str, args: Sequence[str], code: str) -> tuple[list[str], dict[str, str]]:
        e = self.env
        if prog == "magfab":
            return [PY, "-c", MAGFAB_MAIN, *args], e.magfab_env
        if prog == "wrapped":
            return [PY, "-c", WRAPPED.format(tests=str(TESTS)), *args], e.magfab_env
        if prog == "readout":
            return [PY, "-m", "magfab_readout", *args], e.readout_env
        return [PY, "-c", code, *args], e.decode_env

    def run(self, case: Case, number: int, total: int) -> Outcome:
        folder = self.env.work / "cases" / f"{number:03d}"
        folder.mkdir(parents=True)
        if case.setup is not None:
            case.setup(folder)
        keep = {k: entry(folder / k) for k in case.keep}
        before = tree(folder)
        subst = [a.replace("{here}", str(folder)) for a in case.args]
        argv, env = self.argv(case.prog, subst, case.code)
        results = [run_child(argv, folder / case.cwd, env, case.timeout_s, case.signal_at)]
        label, why, usage = judge(case, results[0], before, tree(folder))
        for prog, args in case.then if label in ("stopped", "ok") else []:
            argv, env = self.argv(prog, [a.replace("{here}", str(folder)) for a in args], "")
            results.append(run_child(argv, folder / case.cwd, env))
            nxt = Case(case.cls, case.name, prog, args, expect="ok")
            label2, why2, _ = judge(nxt, results[-1], {}, {})
            if label2 != "ok":
                label, why = label2, f"the next run ({nxt.command()}): {why2}"
                break
        lost_why = [k for k, v in keep.items() if entry(folder / k) != v]
        lost = bool(lost_why)
        why = why if not lost else f"{why}; changed or gone: {', '.join(lost_why)}"
        if case.check is not None and label in ("ok", "stopped", "refused"):
            verdict = case.check(folder, results)
            if verdict is not None:
                if verdict[0] == "lost":
                    lost, why = True, f"{why}; {verdict[1]}"
                else:
                    label, why = verdict
        worst = max(results, key=lambda r: r.wall_s)
        out = Outcome(case.cls, case.name, case.command(), label, lost, why, results[0].code, worst.wall_s,
                      max(r.cpu_s for r in results), max(r.peak_mb for r in results), usage,
                      worst.wall_s > case.allowed_s and label != "over budget", case.detail,
                      "\n".join(_lines(results[0].stderr)[-3:])[-600:], allowed_s=case.allowed_s)
        bad = label in FAILURES or lost
        if bad and self.keep_failures is not None:
            kept = self.keep_failures / f"{number:03d}"
            shutil.copytree(folder, kept, symlinks=True, ignore_dangling_symlinks=True,
                            ignore=lambda d, names: [n for n in names if _special(os.path.join(d, n))])
            out.folder = str(kept)
        _remove(folder)
        self.outcomes.append(out)
        flag = " LOST" if lost else ""
        print(f"[{number:3d}/{total}] class {case.cls} {label:<15}{flag} {out.wall_s:6.1f} s {out.peak_mb:6.0f} MB  "
              f"{case.name}", flush=True)
        if bad:
            print(f"          {out.command}\n          {why[:400]}", flush=True)
        return out


def _special(path: str) -> bool:
    try:
        mode = os.lstat(path).st_mode
    except OSError:
        return True
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode) or stat.S_ISLNK(mode)) or \
        (stat.S_ISREG(mode) and os.lstat(path).st_size > 64 * 2**20)


def _remove(folder: Path) -> None:
    for root, dirs, _files in os.walk(folder):  # a case may leave a folder without write permission
        for d in dirs:
            path = os.path.join(root, d)
            if not os.path.islink(path):
                os.chmod(path, 0o755)
    shutil.rmtree(folder, ignore_errors=True)


# ---- what the cases share: the reference build and its files ---------------------------------------------------

@dataclass
class Env:
    work: Path
    quick: bool
    seed: int
    golden: Path  # the reference build (MagOne), read only
    replay: Path  # its BuildResult, pickled
    golden_tree: dict
    steps: list[str]  # the output steps of a rebuild over it
    in_place: list[str]  # the output steps of `magfab calibrate SCAN` run inside it (an update in place)
    magfab_env: dict[str, str]
    readout_env: dict[str, str]
    decode_env: dict[str, str]
    harness: Path | None  # the firmware's record check compiled for the host (None without gcc)

    def n(self, quick: int, full: int) -> int:
        return quick if self.quick else full

    def copy_build(self, to: Path) -> Path:
        shutil.copytree(self.golden, to, symlinks=True, ignore=shutil.ignore_patterns("__pycache__"))
        return to

    @property
    def calibration(self) -> dict:
        return json.loads((self.golden / "calibration" / "calibration.json").read_text())


def _environment(pythonpath: Sequence[Path]) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("MAGFAB_DEBUG", "PYTHONPATH", "MAGFAB_JOBS")}
    env["PYTHONPATH"] = os.pathsep.join(str(p) for p in pythonpath)
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


def prepare(work: Path, quick: bool, seed: int) -> Env:
    """The reference build (the default spec, through the pipeline, its result pickled), the readout package it
    holds, the steps of a rebuild's swap and, with gcc, the firmware's calibration harness."""
    magfab_env = _environment([ROOT])
    golden = work / "reference" / "magone"
    replay = work / "reference" / "magone.pickle"
    if not replay.is_file():  # (--work: a folder of an earlier run holds it)
        print("building the reference build (the default spec)...", flush=True)
        shutil.rmtree(work / "reference", ignore_errors=True)
        t = time.perf_counter()
        res = run_child([PY, "-c", GOLDEN.format(tests=str(TESTS)), str(EXAMPLES / "magone.toml"), str(golden),
                         str(replay)], work, magfab_env, timeout_s=600)
        if res.code != 0:
            raise SystemExit(f"the reference build failed (exit {res.code}): {res.stderr[-2000:]}")
        print(f"  {time.perf_counter() - t:.0f} s, {res.peak_mb:.0f} MB", flush=True)
    readout = work / "reference" / "readout-src"
    shutil.rmtree(readout, ignore_errors=True)
    shutil.copytree(golden / "readout" / "src", readout)
    env = Env(work, quick, seed, golden, replay, tree(golden), [], [], magfab_env, _environment([readout]),
              _environment([ROOT, readout]), None)
    for inside in (False, True):
        counting = work / "reference" / "count"
        out = env.copy_build(counting / "magone")
        shutil.copy(golden / "calibration" / "scan_simulated.csv", out / SCAN)
        args = ["calibrate", SCAN] if inside else ["build", str(EXAMPLES / "magone.toml"), "--out", str(out)]
        res = run_child([PY, "-c", WRAPPED.format(tests=str(TESTS)), "count", str(counting / "steps.txt"),
                         str(replay), *args], out if inside else counting, magfab_env)
        steps = (counting / "steps.txt").read_text().splitlines() if res.code == 0 else []
        if not steps:
            raise SystemExit(f"counting the output's steps failed (exit {res.code}): {res.stderr[-2000:]}")
        if inside:
            env.in_place = steps
        else:
            env.steps = steps
        shutil.rmtree(counting)
    shutil.rmtree(work / "reference" / "harness", ignore_errors=True)
    shutil.rmtree(work / "cases", ignore_errors=True)
    env.harness = _firmware_harness(work / "reference" / "harness")
    return env


def _firmware_harness(folder: Path) -> Path | None:
    """tests/export/test_firmware_bounds.py's harness (mf_calib.c against an EEPROM in a buffer), built with the
    firmware tests' host flags; None without gcc."""
    if shutil.which("gcc") is None:
        return None
    _tests_path("export")
    from test_firmware_bounds import HARNESS

    from magfab.export import firmware, toolchain

    folder.mkdir(parents=True)
    toolchain.write_tree(firmware.generic_sources(), folder)
    core = folder / firmware.CORE_DIR
    (folder / "harness.c").write_text(HARNESS)
    exe = folder / "harness"
    subprocess.run(["gcc", *firmware.HOST_CFLAGS, "-I", str(core), "-o", str(exe), str(folder / "harness.c"),
                    str(core / "mf_calib.c"), "-lm"], check=True, capture_output=True)
    return exe


def _tests_path(*sub: str) -> None:
    for p in (ROOT, TESTS, *(TESTS / s for s in sub)):
        if str(p) not in sys.path:
            sys.path.insert(0, str(p))


def drawn(strategy: Any, n: int, seed: int) -> list:
    """``n`` values of a Hypothesis strategy, reproducibly (``seed``): ten times as many drawn, ``n`` of them
    picked at random (a strategy's first draws are its simplest, and alike)."""
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import seed as seeded

    found: list = []

    @settings(max_examples=max(10 * n, 30), database=None, deadline=None, phases=[Phase.generate],
              suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much, HealthCheck.data_too_large,
                                     HealthCheck.large_base_example])
    @seeded(seed)
    @given(strategy)
    def collect(value: Any) -> None:
        found.append(value)

    collect()
    unique = list({repr(v): v for v in found}.values())  # a strategy repeats itself
    return random.Random(seed).sample(unique, min(n, len(unique)))


def _write(path: Path, data: str | bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(data, bytes):
        path.write_bytes(data)
    else:
        path.write_text(data)


def writes(files: dict[str, str | bytes]) -> Callable[[Path], None]:
    def setup(folder: Path) -> None:
        for name, data in files.items():
            _write(folder / name, data)
    return setup


def _log_uniform(rng: random.Random, lo: float, hi: float) -> float:
    return 10 ** rng.uniform(math.log10(lo), math.log10(hi))


# ---- class 1: inputs without a size or shape bound ---------------------------------------------------------------

def class1(env: Env, rng: random.Random) -> list[Case]:
    from adversarial_support import KEYS, KINDS, deep_json_document, deep_toml_document, special

    from magfab.formats.bounded import LIMITS

    spec_text = (EXAMPLES / "magone.toml").read_text()
    targets_text = (EXAMPLES / "targets.toml").read_text()
    cases: list[Case] = []
    for k, doc in enumerate(drawn(deep_toml_document(spec_text), env.n(2, 6), rng.randrange(2**32))):
        cases.append(Case(1, f"deep spec #{k} ({doc.count(chr(10))} lines) through check", "magfab",
                          ["check", "deep.toml"], writes({"deep.toml": doc}), words=("deep",),
                          detail=_nesting(doc)))
    for k, doc in enumerate(drawn(deep_toml_document(spec_text), env.n(1, 2), rng.randrange(2**32))):
        cases.append(Case(1, f"deep spec #{k} through build", "magfab", ["build", "deep.toml", "--out", "out"],
                          writes({"deep.toml": doc}), words=("deep",), detail=_nesting(doc)))
    for k, doc in enumerate(drawn(deep_toml_document(targets_text), env.n(1, 3), rng.randrange(2**32))):
        base = k % 2 == 1  # the deep file is the targets, or the spec their `base` names
        files = {"t.toml": 'base = "base.toml"\n' + targets_text, "base.toml": doc} if base else {"t.toml": doc}
        cases.append(Case(1, f"deep {'base spec of the targets' if base else 'targets'} #{k} through design", "magfab",
                          ["design", "t.toml", "--out", "out", "--workers", "1"], writes(files), words=("deep",),
                          detail=_nesting(doc)))
    for k, doc in enumerate(drawn(deep_json_document(env.calibration), env.n(1, 3), rng.randrange(2**32))):
        cases.append(Case(1, f"deep calibration.json #{k} through upload", "readout",
                          ["upload", "deep.json", "--simulate", "--simulate-eeprom", "board.eeprom"],
                          writes({"deep.json": doc}), words=("deep",), detail=_nesting(doc)))
    # the JSON files of a build folder that calibrate reads (the folder a scan is recorded into)
    inside = ["calibration/calibration.json", "calibration/acceptance.json", "spec.json", "manifest.json"]
    for k in range(env.n(1, 5)):
        name = inside[k % len(inside)] if not env.quick else rng.choice(inside[:2])
        base = json.loads((env.golden / name).read_text())
        docs = drawn(deep_json_document(base), 12, rng.randrange(2**32))
        # past Python's own recursion limit (~1,000) half the time: a reader that does not bound the depth crashes
        deeper = [d for d in docs if _depth(d) > 1100] if k % 2 == 0 or name == "manifest.json" else docs
        doc = (deeper or docs)[0]
        # magfab's own files, which calibrate writes anew: refused, or replaced by a complete build, never a crash
        # (a calibration.json that cannot be read holds no measured calibration to keep: calibrate writes its own)
        replaced = name in ("manifest.json", "calibration/calibration.json")
        cases.append(Case(1, f"deep {name} in the build folder through calibrate", "wrapped",
                          ["none", "-", str(env.replay), "calibrate", "build/calibration/scan_simulated.csv", "--out",
                           "build"], _in_build(env, {name: doc}), expect="either" if replaced else "refuse",
                          words=() if name == "manifest.json" else ("deep",),  # a manifest unread: not a build
                          check=_refused_or_built(env) if replaced else None,
                          detail=_nesting(doc)))
    for _ in range(env.n(1, 3)):
        n = rng.choice([KEYS + 1, rng.randrange(KEYS + 1, 60_001), 60_000])
        where = rng.choice(["top", "table", "inline", "array"])
        keys = [f"u{i} = {i}" for i in range(n)]
        text = {"top": "\n".join(keys) + "\n" + spec_text, "table": spec_text + "\n[extra]\n" + "\n".join(keys) + "\n",
                "inline": "extra = {" + ", ".join(keys) + "}\n" + spec_text,
                "array": "extra = [" + ", ".join(str(i) for i in range(n)) + "]\n" + spec_text}[where]
        cases.append(Case(1, f"{n:,} unknown keys ({where}) in a spec through check", "magfab", ["check", "keys.toml"],
                          writes({"keys.toml": text}), words=(f"{KEYS:,}",), detail=f"{n} keys, {where}"))
    if not env.quick:
        cal = env.calibration
        cal["errors"].update({f"u{i}": 1 for i in range(KEYS + 1 + rng.randrange(5000))})
        cases.append(Case(1, "a calibration.json object of many keys through upload", "readout",
                          ["upload", "keys.json", "--simulate", "--simulate-eeprom", "board.eeprom"],
                          writes({"keys.json": json.dumps(cal)}), words=("keys",)))
        n = rng.randrange(KEYS + 1, 20_000)
        cases.append(Case(1, f"targets with {n:,} unknown keys through sweep", "magfab",
                          ["sweep", "t.toml", "--lhs", "2", "--out", "out"],
                          writes({"t.toml": targets_text + "\n[junk]\n" + "".join(f"k{i} = 1\n" for i in range(n))}),
                          words=("keys",)))
    # files that are not regular files, or over their kind's limit, in every reader
    readers = {
        "spec": ("magfab", ["check", "{}"], LIMITS["spec"]),
        "targets": ("magfab", ["design", "{}", "--out", "out"], LIMITS["targets"]),
        "scan CSV": ("magfab", ["calibrate", "{}", "--out", "out"], LIMITS["scan CSV"]),
        "reference log": ("magfab", ["calibrate", "rec.csv", "--reference", "{}", "--out", "out"],
                          LIMITS["reference log"]),
        "calibration.json": ("readout", ["upload", "{}", "--simulate", "--simulate-eeprom", "board.eeprom"],
                             LIMITS["calibration.json"]),
    }
    combos = [(r, k) for r in readers for k in KINDS]
    for reader, kind in rng.sample(combos, env.n(4, 14)):
        prog, args, limit = readers[reader]
        size = limit + 1 + (0 if rng.random() < 0.5 else rng.randrange(limit))
        path_of = {"dev-zero": "/dev/zero", "fifo": "input-fifo", "symlink": "input-symlink",
                   "directory": "input-directory", "oversize": "input-oversize"}[kind]

        def setup(folder: Path, kind: str = kind, size: int = size) -> None:
            special(kind, folder, size)
            _write(folder / "rec.csv", _recording_csv())

        words = () if kind == "directory" and prog == "magfab" else ("regular file",)  # click's own refusal
        cases.append(Case(1, f"{reader}: {kind}{f' of {size:,} bytes' if kind == 'oversize' else ''}", prog,
                          [a.replace("{}", path_of) for a in args], setup, words=words))
    # the same files of the build folder as a FIFO, /dev/zero or a file far over its kind's limit (sparse): refused, or
    # skipped (the rebuild replaces them), never read until the memory or the time runs out
    kinds = {"calibration/calibration.json": "calibration.json", "calibration/acceptance.json": "acceptance.json",
             "spec.json": "spec.json", "manifest.json": "JSON"}
    for name, shape in rng.sample([(n, k) for n in kinds for k in ("fifo", "symlink", "oversize")], env.n(2, 6)):
        size = rng.choice([LIMITS[kinds[name]] + 1, rng.randrange(1 << 30, 3 << 30)])

        def replace(folder: Path, name: str = name, shape: str = shape, size: int = size) -> None:
            env.copy_build(folder / "build")
            path = folder / "build" / name
            path.unlink()
            if shape == "fifo":
                os.mkfifo(path)
            elif shape == "symlink":
                path.symlink_to("/dev/zero")
            else:
                with open(path, "wb") as f:
                    f.truncate(size)

        what = {"fifo": "a FIFO", "symlink": "a link to /dev/zero", "oversize": f"{size:,} bytes (sparse)"}[shape]
        cases.append(Case(1, f"{name} in the build folder as {what} through calibrate", "wrapped",
                          ["none", "-", str(env.replay), "calibrate", "build/calibration/scan_simulated.csv", "--out",
                           "build"], replace, expect="either", check=_refused_or_built(env), detail=what))
    from magfab.formats.scan_csv import MAX_ROWS

    if not env.quick:  # scans of valid rows at the readers' row limit and past it: in the budget, or refused
        for rows in (MAX_ROWS, MAX_ROWS + 1):
            cases.append(Case(1, f"a scan CSV of {rows:,} valid rows (the row limit is {MAX_ROWS:,}) through "
                              "calibrate", "magfab", ["calibrate", "big.csv", "--out", "build"],
                              _big_scan(env, rows), expect="either", detail=f"{rows:,} rows"))
        cases.append(Case(1, "a scan CSV of valid rows just under the 256 MiB file limit through calibrate", "magfab",
                          ["calibrate", "big.csv", "--out", "build"], _big_scan(env, None, LIMITS["scan CSV"] - 4096),
                          expect="either", detail=f"{LIMITS['scan CSV'] - 4096:,} bytes"))
    return cases


def _depth(doc: str) -> int:
    """How deep brackets nest in ``doc`` (a rough count: brackets inside strings count too)."""
    depth = best = 0
    for ch in doc:
        if ch in "[{":
            depth += 1
            best = max(best, depth)
        elif ch in "]}":
            depth -= 1
    return best


def _nesting(doc: str) -> str:
    return f"{len(doc):,} bytes, brackets nested {_depth(doc)} deep"


def _in_build(env: Env, files: dict[str, str | bytes]) -> Callable[[Path], None]:
    def setup(folder: Path) -> None:
        env.copy_build(folder / "build")
        for name, data in files.items():
            _write(folder / "build" / name, data)
    return setup


def _refused_or_built(env: Env) -> Check:
    """After a refusal nothing changed (judged already); after success the folder holds a complete build."""
    def check(folder: Path, results: list[Result]) -> tuple[str, str] | None:
        if results[0].code == 0:
            return _complete_build(folder / "build")
        return None
    return check


def _complete_build(out: Path) -> tuple[str, str] | None:
    try:
        manifest = json.loads((out / "manifest.json").read_text())
    except (OSError, ValueError) as exc:
        return "accepted bad", f"no readable manifest.json in {out.name}: {exc}"
    for a in manifest.get("artifacts", []):
        path = out / a["path"]
        if not path.is_file() or hashlib.sha256(path.read_bytes()).hexdigest() != a["sha256"]:
            return "accepted bad", f"{a['path']} is missing or differs from the manifest"
    return None


def _recording_csv(seed: int = 0) -> str:
    """A recording of the simulated MagOne pressed (tests/models/test_reference_guards.py's), as `record` writes."""
    _tests_path("models")
    from test_reference_guards import REC, recording

    rec = REC if seed == 0 else recording(seed)
    s = rec.scan
    rows = ["time_s,host_time_s,Bx_uT,By_uT,Bz_uT,Fx_sensor_N,Fy_sensor_N,Fz_sensor_N"]
    rows += [",".join(repr(x) for x in (t, h, *b, *f))
             for t, h, b, f in zip(s.time_s.tolist(), rec.host_time_s.tolist(), s.B_uT.tolist(), s.F_N.tolist())]
    return "\n".join(rows) + "\n"


def _big_scan(env: Env, rows: int | None, size: int | None = None) -> Callable[[Path], None]:
    """The build's simulated scan repeated (its time running on) to ``rows`` data rows, or to ``size`` bytes."""
    def setup(folder: Path) -> None:
        env.copy_build(folder / "build")
        lines = (env.golden / "calibration" / "scan_simulated.csv").read_text().splitlines()
        lines = [line for line in lines if not line.startswith("#")]
        head, body = lines[0], [r.split(",", 1) for r in lines[1:]]
        period = 0.00184
        with open(folder / "big.csv", "w") as f:
            f.write(head + "\n")
            written, k = len(head) + 1, 0
            while rows is None or k < rows:
                take = body if rows is None else body[:rows - k]
                block = "".join(f"{(k + i) * period!r},{rest}\n" for i, (_t, rest) in enumerate(take))
                if size is not None and written + len(block) > size:
                    break
                f.write(block)
                written += len(block)
                k += len(take)
    return setup


# ---- class 2: limits that leave work out ---------------------------------------------------------------------------

def class2(env: Env, rng: random.Random) -> list[Case]:
    _tests_path()
    from test_limits import _COST_KEYS, MOST_EXPENSIVE, _toml

    from magfab import SpecError, derive, parse_spec
    from magfab.check import preflight
    from magfab.limits import BUDGET_S as LIMIT_S
    from magfab.limits import estimate

    cases: list[Case] = []
    tolerances = [1e-300, 5e-324, 1e-16, 1e-17] + [_log_uniform(rng, 1e-12, 1e-3) for _ in range(4)]
    for tol in rng.sample(tolerances, env.n(2, 5)):
        cases.append(Case(2, f"tessellation_tolerance_mm = {tol!r} through check", "magfab", ["check", "t.toml"],
                          writes({"t.toml": f"[mould]\ntessellation_tolerance_mm = {tol!r}\n"}), expect="either",
                          words=("mould.tessellation_tolerance_mm",)))
    for step in [rng.choice([1e-4, 1e-3, 0.01]) for _ in range(env.n(1, 2))]:
        method = rng.choice(["poly", "mls", "auto"])
        cases.append(Case(2, f"calibration.scan_step_mm = {step:g}, method {method} through build", "magfab",
                          ["build", "t.toml", "--out", "out"],
                          writes({"t.toml": f'[calibration]\nmethod = "{method}"\nscan_step_mm = {step!r}\n'}),
                          expect="either", words=("calibration.scan_step_mm",)))
    # generated specs over the cost keys: the refused ones through check, the costliest accepted one built
    accepted: list[tuple[float, str]] = []
    refused: list[tuple[str, str]] = []
    for values in drawn(_COST_KEYS, env.n(20, 60), rng.randrange(2**32)):
        text = _toml(values) if values else "\n"
        try:
            cost = estimate(preflight(derive(parse_spec(text))))
        except SpecError as exc:
            refused.append((text, exc.key or ""))
            continue
        except Exception:  # derive refused it some other way: the child's refusal is what is judged
            refused.append((text, ""))
            continue
        accepted.append((cost.seconds, text))
    for text, key in rng.sample(refused, min(len(refused), env.n(2, 4))):
        cases.append(Case(2, f"a generated cost-key spec refused ({key or 'derive'}) through check", "magfab",
                          ["check", "t.toml"], writes({"t.toml": text}), words=(key,) if key else (),
                          detail=text.replace("\n", "; ")))
    if not env.quick:
        builds = [(estimate(preflight(derive(parse_spec(MOST_EXPENSIVE)))).seconds, MOST_EXPENSIVE)]
        builds += [top for top in sorted(accepted, reverse=True)[:2] if top[0] > 0.7 * LIMIT_S]
        folds = rng.randint(12, 20)  # the most expensive spec again, its MLS cross-validated over more folds
        costly = MOST_EXPENSIVE.replace('method = "auto"', f'method = "auto"\nfolds = {folds}')
        builds.append((estimate(preflight(derive(parse_spec(costly)))).seconds, costly))
        for seconds, text in builds:
            cases.append(Case(2, f"the costliest allowed spec built (estimated {seconds:.0f} s)", "magfab",
                              ["build", "t.toml", "--out", "out"], writes({"t.toml": 'name = "costly"\n' + text}),
                              expect="either", detail=text.replace("\n", "; ")))
    # arrays near the board's routing limit
    def array(rows: int, cols: int) -> str:
        return f"[array]\nrows = {rows}\ncols = {cols}\npitch_mm = 14\n[mould]\nangular_tolerance_deg = 15\n"

    edge = max(n for n in range(1, 17) if estimate(derive(parse_spec(array(1, n)))).seconds <= LIMIT_S)
    shapes = [(1, edge + 1), (2, (edge + 2) // 2), (4, 4), (rng.randint(2, 4), rng.randint(3, 4))]
    for rows, cols in rng.sample(shapes, env.n(1, 3)):
        cases.append(Case(2, f"a {rows} x {cols} array (the edge is 1 x {edge}) through check", "magfab",
                          ["check", "a.toml"], writes({"a.toml": array(rows, cols)}), expect="either",
                          words=("array.",)))
    if not env.quick:
        cases.append(Case(2, f"the 1 x {edge} array at the routing edge built", "magfab",
                          ["build", "a.toml", "--out", "out"], writes({"a.toml": 'name = "edge"\n' + array(1, edge)}),
                          expect="either"))
    # studies: grids, hypercubes, workers, trials
    cores = os.cpu_count() or 1
    for levels in rng.sample(range(2, 51), env.n(1, 2)):
        cases.append(Case(2, f"sweep --grid {levels} (the example's variables)", "magfab",
                          ["sweep", "t.toml", "--grid", str(levels), "--out", "s"], _targets(), expect="either",
                          words=("--grid",), check=_sweep_written))
    trials = rng.choice([300, 1000, 5000])
    cases.append(Case(2, f"sweep --lhs above study.trials = {trials}", "magfab",
                      ["sweep", "t.toml", "--lhs", str(trials + rng.randrange(1, 10**6 - trials)), "--out", "s"],
                      _targets(trials), words=("study.trials",)))
    cases.append(Case(2, f"sweep --workers above the {cores} cores", "magfab",
                      ["sweep", "t.toml", "--lhs", "2", "--workers", str(rng.randint(cores + 1, 256)), "--out", "s"],
                      _targets(), words=("--workers",)))
    if not env.quick:
        big = rng.choice([10**7, 10**9, 2**63])
        cases.append(Case(2, f"a search of study.trials = {big:,}", "magfab",
                          ["design", "t.toml", "--out", "d", "--workers", "1"], _targets(big), words=("study.trials",)))
        cases.append(Case(2, "design --workers above the cores", "magfab",
                          ["design", "t.toml", "--out", "d", "--workers", str(cores + 1)], _targets(),
                          words=("--workers",)))
    small = rng.randint(1, 3)
    cases.append(_study(2, f"a small sweep: --lhs {small} --workers 1",
                        ["sweep", "--lhs", str(small), "--workers", "1", "--out", "s"], _targets_text(),
                        expect="ok", check=_sweep_written))
    w = str(min(2, cores))
    if not env.quick:  # what the limits let through: as many designs as study.trials allows
        n = int(_log_uniform(rng, 30, 300))
        cases.append(_study(2, f"a sweep the limits allow: --lhs {n} of study.trials = 300, --workers {w}",
                            ["sweep", "--lhs", str(n), "--workers", w, "--out", "s"], _targets_text(300),
                            expect="either", check=_sweep_written))
        n = int(_log_uniform(rng, 30, 300))  # the default variables (no [variables]): the FE where the surrogate ends
        cases.append(_study(2, f"a sweep of the default variables: --lhs {n}, --workers {w}",
                            ["sweep", "--lhs", str(n), "--workers", w, "--out", "s"], "[study]\ntrials = 300\n",
                            expect="either", check=_sweep_written))
        n = rng.randint(5, 40)  # the full chain (FE) per design
        cases.append(_study(2, f"sweep --models fe --lhs {n} --workers {w}",
                            ["sweep", "--models", "fe", "--lhs", str(n), "--workers", w, "--out", "s"],
                            _targets_text(300), expect="either", check=_sweep_written))
        t = rng.randint(4, 12)
        cases.append(_study(2, f"a search of study.trials = {t}, verify 1, --workers {w}",
                            ["design", "--out", "d", "--workers", w], _targets_text(t, verify=1), expect="either",
                            result_codes=(3,)))
    # a measured scan too large for MLS
    cases.append(Case(2, "a measured scan over the MLS row limit through calibrate", "magfab",
                      ["calibrate", "scan.csv", "--spec", "mls.toml", "--out", "out"], _mls_scan(rng),
                      words=("rows",)))
    return cases


def _targets_text(trials: int | None = None, verify: int | None = None) -> str:
    text = (EXAMPLES / "targets.toml").read_text()
    if trials is not None:
        text = text.replace("trials = 250", f"trials = {trials}")
    if verify is not None:
        text = text.replace("verify = 6", f"verify = {verify}")
    return text


def _targets(trials: int | None = None, verify: int | None = None) -> Callable[[Path], None]:
    return writes({"t.toml": _targets_text(trials, verify)})


def _study(cls: int, name: str, args: list[str], text: str, **kw: Any) -> Case:
    """A study that runs: held to the estimate it prints before the work (bench/study_time.py computes it as the
    command does), killed at 1.5 times that or TIMEOUT_S, whichever is later."""
    from study_time import estimated_s

    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "t.toml").write_text(text)
        estimate = estimated_s(Path(tmp) / "t.toml", args)
    return Case(cls, f"{name} (estimated {estimate:.0f} s)", "magfab", [*args[:1], "t.toml", *args[1:]],
                writes({"t.toml": text}), timeout_s=max(TIMEOUT_S, 1.5 * estimate), allowed_s=estimate, **kw)


def _sweep_written(folder: Path, results: list[Result]) -> tuple[str, str] | None:
    if results[0].code == 0 and not (folder / "s" / "sweep.csv").is_file():
        return "accepted bad", "exit 0 but no s/sweep.csv"
    return None


def _mls_scan(rng: random.Random) -> Callable[[Path], None]:
    def setup(folder: Path) -> None:
        import numpy as np

        from magfab.formats.scan_csv import Scan, scan_csv
        from magfab.limits import MAX_MLS_ROWS

        n = MAX_MLS_ROWS + rng.randrange(1, 20_000)
        t = np.arange(n) * 1e-3
        k = np.arange(n)  # a 2-D scan around this design's rest field (18.8 mT): only its size is wrong
        B = np.column_stack([300.0 + 200.0 * np.sin(0.0037 * k), np.zeros(n), 18763.0 + 600.0 * np.sin(0.0051 * k)])
        F = np.column_stack([np.zeros(n), np.zeros(n), 0.1 + 0.05 * np.sin(0.0051 * k)])
        scan = Scan(t, B, F)
        _write(folder / "scan.csv", scan_csv(scan))
        _write(folder / "mls.toml", 'name = "mls"\n[calibration]\nmethod = "mls"\n')
    return setup


# ---- class 3: crashes where a one-line error belongs ---------------------------------------------------------------

def class3(env: Env, rng: random.Random) -> list[Case]:
    cases: list[Case] = []
    printable = "".join(chr(c) for c in range(32, 127))
    addresses = [
        "".join(rng.choice(printable) for _ in range(rng.randint(1, 40))),
        f"tcp://localhost:{rng.choice([0, 65536, 99999, -1, 10**20])}",
        f"tcp://127.0.0.1:{rng.choice(['notaport', '', '8786x', '1e3', ' 1'])}",
        rng.choice(["tcp://:", "://", "tcp://", "tcp://[::1", "tls://h", ":", "tcp://host:1:2"]),
        "tcp://" + "h" * rng.randint(300, 5000) + ":8786",
        "tcp://h\u00e9\u2603st:8786",
        "tcp://127.0.0.1:8786\nsecond line",
        "inproc://" + "".join(rng.choice(printable) for _ in range(8)),
        "ucx://127.0.0.1:" + str(rng.randint(1, 9)),
    ]
    for address in rng.sample(addresses, env.n(3, len(addresses))):
        cases.append(Case(3, f"--scheduler {address[:40]!r}", "magfab",
                          ["design", "t.toml", "--scheduler", address], writes({"t.toml": "[study]\ntrials = 2\n"}),
                          words=("--scheduler",)))
    # calibrations the EEPROM record cannot hold
    for k in range(env.n(2, 5)):
        doc, what = _unholdable(env, rng, k)
        cases.append(Case(3, f"upload of {what}", "readout",
                          ["upload", "cal.json", "--simulate", "--simulate-eeprom", "board.eeprom"],
                          writes({"cal.json": json.dumps(doc)}), expect="either", check=_device_check(env, doc),
                          detail=what))
    # --out paths too long for the file system
    commands = {"build": [], "design": ["t.toml", "--workers", "1"], "sweep": ["t.toml", "--lhs", "2"],
                "calibrate": ["scan.csv"]}
    shapes = ["name", "beside", "path"]
    for command, shape in rng.sample([(c, s) for c in commands for s in shapes], env.n(2, 6)):
        part = rng.randint(150, 255)  # a path over PATH_MAX (4,096) in names of this length
        out = {"name": "{here}/" + "x" * rng.randint(256, 600), "beside": "{here}/" + "x" * rng.randint(234, 255),
               "path": "{here}/" + "/".join(["y" * part] * (4096 // (part + 1) + rng.randint(0, 8)))}[shape]
        files = {"t.toml": "[study]\ntrials = 2\n"} if command in ("design", "sweep") else {}
        setup = writes(files) if command != "calibrate" else _with_scan(env)
        cases.append(Case(3, f"{command} --out with a {shape} too long", "magfab",
                          [command, *commands[command], "--out", out], setup, words=("--out",),
                          detail=f"{len(out)} bytes"))
    # storage URLs a study refuses, with --out in folders that do not exist yet
    urls = [f"{''.join(rng.choice('abcdefgh') for _ in range(5))}://nowhere/x", "sqlite:////nonexistent-dir/sub/x.db",
            ".", "mysql://127.0.0.1:1/x", "postgresql://127.0.0.1:1/x", "file:///tmp/x",
            "sqlite:///" + "z" * 300 + "/x.db", "redis://localhost:1"]
    for url in rng.sample(urls, env.n(2, 5)):
        cases.append(Case(3, f"study.storage = {url[:40]!r}", "magfab",
                          ["design", "t.toml", "--workers", "1", "--out", "a/b/study"],
                          writes({"t.toml": f"[study]\ntrials = 2\nstorage = {json.dumps(url)}\n"}),
                          words=("study.storage",)))
    return cases


def _with_scan(env: Env) -> Callable[[Path], None]:
    def setup(folder: Path) -> None:
        shutil.copy(env.golden / "calibration" / "scan_simulated.csv", folder / "scan.csv")
    return setup


def _unholdable(env: Env, rng: random.Random, k: int) -> tuple[dict, str]:
    """A calibration.json of the build's kind whose record the EEPROM may not hold: a high order with a long hull,
    a long hull, values past float32, a tiny or huge scale."""
    from magfab.readout.src.magfab_readout.calibration_json import monomials

    doc = env.calibration
    order = doc["order"]
    kind = ["order and hull", "hull", "float32", "scale", "name"][k % 5] if not env.quick else \
        rng.choice(["order and hull", "hull"])
    if kind in ("order and hull", "hull"):
        if kind == "order and hull":
            order = rng.randint(6, 9)
            doc["order"] = order
            doc["monomials"] = monomials(order)
            for force in ("Fz_N", "Fr_N"):
                doc["coefficients"][force] = [rng.uniform(-1, 1) * 0.01 for _ in doc["monomials"]]
        n = rng.randint(17, 400)
        (zlo, zhi), (rlo, rhi) = doc["valid_region"]["Bz_uT"], doc["valid_region"]["Br_uT"]
        cz, cr, hz, hr = (zlo + zhi) / 2, (rlo + rhi) / 2, (zhi - zlo) / 2, (rhi - rlo) / 2
        angles = [2 * math.pi * j / n for j in range(n)]
        doc["valid_region"]["hull"] = [[cz + hz * math.cos(a), cr + hr * math.sin(a)] for a in angles]
        return doc, f"order {order} with a hull of {n} points"
    if kind == "float32":
        force = rng.choice(["Fz_N", "Fr_N"])
        j = rng.randrange(len(doc["coefficients"][force]))
        value = rng.choice([3.5e38, -1e39, 1e300, 1e-46])
        doc["coefficients"][force][j] = value
        return doc, f"coefficients.{force}[{j}] = {value!r}"
    if kind == "scale":
        name = rng.choice(["Bz_uT", "Br_uT"])
        value = rng.choice([1e-31, 1e-30, 1e30, 1e31, 1e-45])
        doc["scaling"][name]["scale"] = value
        return doc, f"scaling.{name}.scale = {value!r}"
    doc["tare_N"]["Fz_N"] = rng.choice([3.5e38, 1e39])
    return doc, f"tare_N.Fz_N = {doc['tare_N']['Fz_N']!r}"


def _device_check(env: Env, doc: dict) -> Check:
    """After an upload that succeeded: the host's model finite over the valid region and the temperature range
    (tests/formats/test_calibration_formula.py's check) and, with the firmware harness, the record the upload left in
    the simulated EEPROM loaded by the firmware's check and evaluated finite there."""
    def check(folder: Path, results: list[Result]) -> tuple[str, str] | None:
        if results[0].code != 0:
            return None  # a refusal: judged already (one line, nothing written)
        _tests_path("formats", "export")
        from test_calibration_formula import _check_finite

        from magfab.readout.src.magfab_readout.calibration import Calibration

        try:
            _check_finite(Calibration(doc), doc)
        except AssertionError as exc:
            return "accepted bad", f"the host's model is not finite over the valid region: {str(exc)[:300]}"
        except Exception as exc:  # any failure to evaluate an accepted file is the finding
            return "accepted bad", f"the host's model raised {type(exc).__name__}: {str(exc)[:200]}"
        if env.harness is None or not (folder / "board.eeprom").is_file():
            return None
        from test_firmware_bounds import _samples

        record = (folder / "board.eeprom").read_bytes()
        script = f"R {record.hex()}\n" + "".join("E {:.9g} {:.9g} {:.9g} {}\n".format(*s) for s in _samples(doc))
        lines = subprocess.run([str(env.harness)], input=script, capture_output=True, text=True, timeout=60,
                               check=True).stdout.splitlines()
        if not lines or lines[0] != "L 0":
            return "accepted bad", f"uploaded, but the firmware's record check gives {lines[:1]} (not L 0)"
        for line, s in zip(lines[1:], _samples(doc)):
            forces = [float(v) for v in line.split()[1:4]]
            if not all(math.isfinite(v) for v in forces):
                return "accepted bad", f"the firmware's forces at (Bx, By, Bz, T) = {s} are {forces}"
        return None
    return check


# ---- class 4: values the validator accepts that the device cannot survive -----------------------------------------

def class4(env: Env, rng: random.Random) -> list[Case]:
    _tests_path()
    from calibration_strategies import calibration

    cases: list[Case] = []
    docs = drawn(calibration(max_order=8), env.n(5, 18), rng.randrange(2**32))
    for k, doc in enumerate(docs):
        spoil = _spoil(doc)
        cases.append(Case(4, f"generated calibration #{k} ({spoil}) through upload", "readout",
                          ["upload", "cal.json", "--simulate", "--simulate-eeprom", "board.eeprom"],
                          writes({"cal.json": json.dumps(doc)}), expect="either", check=_device_check(env, doc),
                          detail=spoil))
    for k, doc in enumerate(rng.sample(docs, env.n(1, 3))):  # in a build, where calibrate's guard evaluates it
        cases.append(Case(4, f"generated calibration #{k} ({_spoil(doc)}) in the build folder through calibrate",
                          "wrapped", ["none", "-", str(env.replay), "calibrate", "build/calibration/scan_simulated.csv",
                                      "--out", "build"],
                          _in_build(env, {"calibration/calibration.json": json.dumps(doc)}), expect="either",
                          check=_refused_or_built(env), detail=_spoil(doc)))
    return cases


def _spoil(doc: dict) -> str:
    parts = [f"{doc['method']} order {doc['order']}"]
    if "thermal" in doc:
        t = doc["thermal"]
        parts.append(f"thermal T0 {t['reference_C']:.3g} C, a {[round(v, 5) for v in t['coefficient_per_C'].values()]}")
    s = doc["scaling"]
    parts.append(f"scale {s['Bz_uT']['scale']:.3g}/{s['Br_uT']['scale']:.3g}, centre {s['Bz_uT']['center']:.3g}/"
                 f"{s['Br_uT']['center']:.3g}")
    biggest = max(abs(c) for cs in doc["coefficients"].values() for c in cs) if doc["coefficients"]["Fz_N"] else 0
    parts.append(f"|c| up to {biggest:.3g}")
    if "mls" in doc:
        parts.append(f"mls bandwidth {doc['mls']['bandwidth']:.3g}")
    return ", ".join(parts)


# ---- class 5: guards a wrong input slips past -----------------------------------------------------------------------

def class5(env: Env, rng: random.Random) -> list[Case]:
    _tests_path("models")
    import numpy as np
    from test_reference_guards import REC, at, log_times, rounded, true_force

    def reference_csv(times: np.ndarray, F: np.ndarray) -> str:
        F = np.round(F, 6)
        return "time_s,Fx_N,Fy_N,Fz_N\n" + "".join(f"{t!r},{f[0]!r},{f[1]!r},{f[2]!r}\n"
                                                   for t, f in zip(times.tolist(), F.tolist()))

    recording = _recording_csv()
    cases: list[Case] = []

    def guarded(name: str, ref: str, words: tuple[str, ...], detail: str, expect: str = "refuse") -> None:
        files = {"rec.csv": recording, "ref.csv": ref}
        cases.append(Case(5, name, "wrapped", ["none", "-", str(env.replay), "calibrate", "rec.csv", "--reference",
                                               "ref.csv", "--out", "build"],
                          _build_and(env, files), expect=expect, words=words,
                          detail=detail, keep=("rec.csv", "ref.csv")))

    for k in range(env.n(3, 8)):
        p = np.random.default_rng(rng.randrange(2**32))
        form = ["resampled", "shifted", "scaled", "tared", "rounded", "bent", "noised", "all disguises"][k % 8] if \
            not env.quick else ["all disguises", "scaled", "rounded"][k % 3]
        rate = rng.uniform(200.0, 2000.0)
        lag = rng.uniform(-0.5, 0.5) if form in ("shifted", "all disguises") else 0.0
        gain = rng.uniform(0.9, 1.1) if form in ("scaled", "all disguises") else 1.0
        tare = [rng.uniform(-0.5, 0.5) for _ in range(3)] if form in ("tared", "all disguises") else [0.0] * 3
        step = rng.uniform(0.1, 2.0) if form in ("rounded", "all disguises") else 0.0
        bend = rng.uniform(-0.05, 0.05) if form in ("bent", "all disguises") else 0.0
        noise = rng.uniform(0.0, 0.05) if form in ("noised", "all disguises") else 0.0
        times = log_times(rate)
        own = at(times, REC.scan.F_N, lag)
        F = gain * (own + bend * own**2) + np.array(tare) + p.normal(0.0, noise / 1000.0, own.shape)
        if step:
            F = rounded(F, step / 1000.0)
        detail = (f"rate {rate:.0f} Hz, lag {lag:+.3f} s, gain {gain:.4f}, tare {[round(x, 3) for x in tare]} N, "
                  f"bend {bend:+.4f}/N, noise {noise:.3f} mN, rounded to {step:.3f} mN")
        guarded(f"the recording's own forces as the reference, {form}", reference_csv(times, F),
                ("copy of",), detail)
    dead = ["zero", "constant", "dead channel"]
    for form in rng.sample(dead, env.n(1, 3)):
        times = log_times(rng.uniform(200.0, 2000.0))
        p = np.random.default_rng(rng.randrange(2**32))
        if form == "zero":
            F = np.zeros((len(times), 3))
        elif form == "constant":
            level = np.array([rng.uniform(-5, 5) for _ in range(3)])
            F = level + p.uniform(-0.5, 0.5, (len(times), 3)) * rng.uniform(0.0, 10.0) / 1000.0
        else:
            F = at(times, true_force(REC.scan.time_s))
            F[:, rng.randrange(3) if rng.random() < 0.3 else 2] = 0.0
        guarded(f"a {form} reference", reference_csv(times, F), ("never moves",), form)
    for k in range(env.n(1, 2)):  # the control: an independent reference of the spec's resolution
        q = 6.25 / 1000.0  # calibration.reference_resolution_mN of MagOne's spec
        p = np.random.default_rng(rng.randrange(2**32))
        rate, offset = rng.uniform(200.0, 2000.0), rng.uniform(-0.2, 0.2)
        tare = np.array([rng.uniform(-0.5, 0.5) for _ in range(3)])
        times = log_times(rate)
        F = at(times, true_force(REC.scan.time_s), offset) + tare
        F = rounded(F + p.normal(0.0, q / math.sqrt(12.0), F.shape), q)
        guarded(f"an independent reference #{k} (the control: it must pass)", reference_csv(times, F), (),
                f"rate {rate:.0f} Hz, clock offset {offset:+.3f} s, tare {np.round(tare, 3).tolist()} N",
                expect="ok")
    # guards A and B: a scan whose force columns are the sensor's own
    for form in rng.sample(["renamed", "repeated", "own calibration", "own calibration, tared"], env.n(1, 4)):
        cases.append(Case(5, f"a scan whose forces are the sensor's own ({form})", "wrapped",
                          ["none", "-", str(env.replay), "calibrate", "own.csv", "--out", "build"],
                          _own_scan(env, form, rng.randrange(2**32)), words=("own",), detail=form))
    return cases


def _build_and(env: Env, files: dict[str, str | bytes]) -> Callable[[Path], None]:
    def setup(folder: Path) -> None:
        env.copy_build(folder / "build")
        for name, data in files.items():
            _write(folder / name, data)
    return setup


def _own_scan(env: Env, form: str, seed: int) -> Callable[[Path], None]:
    def setup(folder: Path) -> None:
        import numpy as np

        from magfab.formats.scan_csv import read_scan_csv
        from magfab.models.calibration import Calibration

        env.copy_build(folder / "build")
        scan = read_scan_csv((env.golden / "calibration" / "scan_simulated.csv").read_bytes())
        B = scan.B_uT
        if form in ("renamed", "repeated"):
            own = np.round(scan.F_N + np.random.default_rng(seed).normal(0, 3e-4, scan.F_N.shape), 6)
        else:
            cal = Calibration.from_json(env.calibration)
            own, _ = cal.evaluate(B, "poly", temperature_C=None)
            if form.endswith("tared"):
                own = own + np.random.default_rng(seed).uniform(-0.5, 0.5, 3)
            own = np.round(own, 6)
        head = "time_s,Bx_uT,By_uT,Bz_uT," + {"renamed": "Fx_sensor_N,Fy_sensor_N,Fz_sensor_N",
                                             "repeated": "Fx_N,Fy_N,Fz_N,Fx_sensor_N,Fy_sensor_N,Fz_sensor_N"}.get(
            form, "Fx_N,Fy_N,Fz_N")
        rows = []
        for t, b, f in zip(scan.time_s.tolist(), B.tolist(), own.tolist()):
            values = [t, *b, *f, *(f if form == "repeated" else [])]
            rows.append(",".join(repr(v) for v in values))
        _write(folder / "own.csv", head + "\n" + "\n".join(rows) + "\n")
    return setup


# ---- class 6: data loss --------------------------------------------------------------------------------------------

USER_FILES = {"scan.csv": b"time_s,Bx_uT\n0,1\n", "notes/day1/log.txt": b"\x00\xffmy notes",
              "calibration/mine.txt": b"inside a magfab folder"}
#: The scan a user recorded into the build folder and calibrates on from inside it (the simulated scan's bytes).
SCAN = "bench_scan.csv"


def class6(env: Env, rng: random.Random) -> list[Case]:
    from adversarial_support import LOOK_ALIKES

    cases: list[Case] = []
    alikes = drawn(LOOK_ALIKES, env.n(4, 9), rng.randrange(2**32))
    spec = str(EXAMPLES / "magone.toml")
    n_steps = len(env.steps)
    names = ["magone", "out", "my.finger-2"]

    def case(name: str, mode: str, arg: str, replay: bool, expect: str, then: bool = False,
             signal_at: tuple[float, int] | None = None, inside: bool = False) -> None:
        folder_name = rng.choice(names)
        look = alikes.pop() if alikes else []
        command = ["calibrate", SCAN] if inside else ["build", spec, "--out", f"build/{folder_name}"]
        args = [mode, arg, str(env.replay) if replay else "-", *command]
        nxt = [("wrapped", ["none", "-", str(env.replay) if replay else "-", *command])] if then else []
        look_names = [f".{folder_name}.{k}-{s}" for k, s, _ in look]
        cases.append(Case(6, name, "wrapped", args, _previous_build(env, folder_name, look), expect=expect,
                          keep=tuple(f"build/{n}" for n in look_names) + tuple(f"build/{folder_name}/{u}"
                                                                             for u in [*USER_FILES, SCAN]),
                          check=_swap_check(env, folder_name, look_names, replay), then=nxt, signal_at=signal_at,
                          cwd=f"build/{folder_name}" if inside else "",
                          detail=f"folder {folder_name!r}, beside it {look_names}"))

    for _ in range(env.n(1, 2)):
        case("a rebuild with look-alike names beside it and the user's files in it [plan replayed]", "none", "0",
             True, "ok")
    for k in rng.sample(range(1, n_steps + 1), env.n(1, min(4, n_steps))):
        case(f"Ctrl-C at swap step {k} of {n_steps} ({env.steps[k - 1]}) [plan replayed]", "SIGINT", str(k), True,
             "stop")
    for k in rng.sample(range(1, n_steps + 1), env.n(1, min(3, n_steps))):
        case(f"SIGKILL at swap step {k} of {n_steps} ({env.steps[k - 1]}), then a rebuild [plan replayed]",
             "SIGKILL", str(k), True, "stop", then=True)
    case("Ctrl-C during the work of a rebuild", "ctrl-c-in-plan", "0", True, "stop")
    n_in = len(env.in_place)  # `magfab calibrate SCAN` inside the build folder: updated file by file, journalled
    for k in rng.sample(range(1, n_in + 1), env.n(1, min(3, n_in))):
        case(f"Ctrl-C at in-place step {k} of {n_in} ({env.in_place[k - 1]}) of calibrate run inside the build "
             "[plan replayed]", "SIGINT", str(k), True, "stop", inside=True)
    for k in rng.sample(range(1, n_in + 1), env.n(0, min(2, n_in))):
        case(f"SIGKILL at in-place step {k} of {n_in} ({env.in_place[k - 1]}) of calibrate run inside the build, "
             "then calibrate again [plan replayed]", "SIGKILL", str(k), True, "stop", then=True, inside=True)
    if not env.quick:
        case("a real rebuild with look-alike names beside it and the user's files in it", "none", "0", False, "ok")
        case(f"Ctrl-C {8:.0f} s into a real rebuild", "none", "0", False, "stop", signal_at=(8.0, signal.SIGINT))
    # refusals that must leave a folder alone
    cases.append(Case(6, "--out a folder of the user's that is not a build", "magfab",
                      ["build", spec, "--out", "thesis"],
                      writes({"thesis/chapter1.tex": "do not delete", "thesis/figs/a.png": b"\x89PNG"}),
                      words=("not an earlier magfab build",), keep=("thesis",)))
    cases.append(Case(6, "a rebuild over a measured calibration", "wrapped",
                      ["none", "-", str(env.replay), "build", spec, "--out", "build/magone"],
                      _measured(env), words=("--discard-calibration",), keep=("build/magone",)))
    if not env.quick:
        cases.append(Case(6, "--out under a file", "magfab", ["build", spec, "--out", "file/out"],
                          writes({"file": "mine"}), keep=("file",)))
        cases.append(Case(6, "a user's file where the new build writes [plan replayed]", "wrapped",
                          ["none", "-", str(env.replay), "build", spec, "--out", "build/magone"], _disowned(env),
                          words=("not magfab's",), keep=("build/magone",)))
    return cases


def _previous_build(env: Env, name: str, look: list) -> Callable[[Path], None]:
    """A previous build at build/NAME that differs from the reference (its report changed, a file the new build no
    longer makes), the user's files in it, and names like magfab's temporaries beside it."""
    from adversarial_support import make_look_alike

    def setup(folder: Path) -> None:
        out = env.copy_build(folder / "build" / name)
        manifest = json.loads((out / "manifest.json").read_text())
        report = (out / "report.html").read_bytes() + b"<!-- the previous build -->"
        (out / "report.html").write_bytes(report)
        (out / "previous_only.txt").write_bytes(b"made by the previous build")
        for a in manifest["artifacts"]:
            if a["path"] == "report.html":
                a["sha256"], a["bytes"] = hashlib.sha256(report).hexdigest(), len(report)
        manifest["artifacts"].append({"path": "previous_only.txt", "sha256": hashlib.sha256(
            b"made by the previous build").hexdigest(), "bytes": 26, "description": "gone in the new build"})
        (out / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
        for rel, data in USER_FILES.items():
            _write(out / rel, data)
        shutil.copy(env.golden / "calibration" / "scan_simulated.csv", out / SCAN)
        os.symlink("scan.csv", out / "latest.csv")
        for kind, suffix, shape in look:
            make_look_alike(folder / "build", name, kind, suffix, shape)
        (folder / "old.json").write_text(json.dumps(tree(out)))  # the previous build, for the check
    return setup


def _swap_check(env: Env, name: str, look_names: list[str], replay: bool) -> Check:
    """The build's folder holds the previous build or the new one (complete, the user's files in it); nothing but the
    look-alikes beside it once the command (and the next run, after a kill) is done."""
    def check(folder: Path, results: list[Result]) -> tuple[str, str] | None:
        out = folder / "build" / name
        old = {k: tuple(v) for k, v in json.loads((folder / "old.json").read_text()).items()}
        now = tree(out)
        user = {k: v for k, v in old.items() if k.split("/")[0] in ("scan.csv", "notes", "latest.csv", SCAN)
                or k == "calibration/mine.txt"}
        if now != old:
            if replay:
                new = {**env.golden_tree, **user}
                new = {k: v for k, v in new.items() if "__pycache__" not in k}
                if now != new:
                    diff = changes(new, now)
                    return "lost", f"the folder is neither the previous build nor the new one: {diff[:6]}"
            else:
                bad = _complete_build(out)
                if bad is not None:
                    return "lost", f"the folder is neither the previous build nor a complete new one: {bad[1]}"
                missing = [k for k, v in user.items() if now.get(k) != v]
                if missing:
                    return "lost", f"the user's files changed or gone: {missing}"
        beside = sorted(os.listdir(folder / "build"))
        expected = sorted([name, *look_names])
        if beside != expected and results[-1].code != -signal.SIGKILL:
            return "lost", f"beside the build: {sorted(set(beside) - set(expected))} left, " \
                           f"{sorted(set(expected) - set(beside))} gone"
        return None
    return check


def _measured(env: Env) -> Callable[[Path], None]:
    def setup(folder: Path) -> None:
        out = env.copy_build(folder / "build" / "magone")
        path = out / "calibration" / "calibration.json"
        cal = json.loads(path.read_text())
        cal["scan"]["source"] = "scan.csv + reference.csv"
        path.write_text(json.dumps(cal, indent=2, sort_keys=True) + "\n")
    return setup


def _disowned(env: Env) -> Callable[[Path], None]:
    """The previous build's manifest no longer lists checklist.md: the file there is the user's, where the new build
    writes."""
    def setup(folder: Path) -> None:
        out = env.copy_build(folder / "build" / "magone")
        manifest = json.loads((out / "manifest.json").read_text())
        manifest["artifacts"] = [a for a in manifest["artifacts"] if a["path"] != "checklist.md"]
        (out / "manifest.json").write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    return setup


# ---- class 7: decoder speed ------------------------------------------------------------------------------------------

def class7(env: Env, rng: random.Random) -> list[Case]:
    kinds = ["sync", "a5", "line starts", "random", "valid", "crc-bad", "truncated", "sync+random", "long line",
             "lines", "mixed"]
    small, large = 1 << 17, 1 << 20  # 8x apart: a quadratic decoder is 8x slower a byte there
    cases = []
    for kind in rng.sample(kinds, env.n(5, len(kinds))):
        chunk = rng.choice([large, 65536, 4096, 31])
        if chunk == 31 and kind in ("long line", "a5", "sync"):
            chunk = 4096  # 31-byte feeds of 2 MB: interpreter overhead per call, not the decoder's growth
        seed = rng.randrange(2**32)
        cases.append(Case(7, f"decoder: {kind}, {small >> 10} KB and {large >> 10} KB fed {chunk:,} bytes at a time",
                          "python", [kind, str(seed), str(chunk), str(small), str(large)],
                          code=DECODE.format(bench=str(BENCH)), expect="ok", check=_linear,
                          detail=f"seed {seed}"))
    return cases


def _linear(folder: Path, results: list[Result]) -> tuple[str, str] | None:
    try:
        figures = json.loads(_lines(results[0].stdout)[-1])
    except (IndexError, ValueError):
        return "traceback", "no figures from the decoder's child"
    ratio = figures["large"] / max(figures["small"], 1e-12)
    if ratio > LINEAR_FACTOR:
        return "over budget", (f"superlinear: {figures['small'] * 1e9:.0f} ns/B at the small size, "
                               f"{figures['large'] * 1e9:.0f} ns/B at 8x ({ratio:.1f}x)")
    return None


# ---- class 8: exit codes ---------------------------------------------------------------------------------------------

def class8(env: Env, rng: random.Random) -> list[Case]:
    junk = "".join(rng.choice("abcdefghijklmnopqrstuvwxyz-") for _ in range(8))
    scan = (env.golden / "calibration" / "scan_simulated.csv").read_text().splitlines()
    row = rng.randrange(1, len(scan))
    bad_row = [*scan[:row], scan[row].replace(",", ",nan,", 1).rsplit(",", 1)[0], *scan[row + 1:]]
    templates: list[tuple[str, str, list[str], dict[str, str | bytes], tuple[str, ...]]] = [
        ("unknown option", "magfab", ["check", f"--{junk}"], {}, ()),
        ("unknown command", "magfab", [junk], {}, ()),
        ("a missing spec", "magfab", ["check", "missing.toml"], {}, ("missing.toml",)),
        ("a spec of binary junk", "magfab", ["check", "s.toml"], {"s.toml": bytes(rng.randrange(256)
                                                                                   for _ in range(200))}, ()),
        ("a spec whose name is a number", "magfab", ["check", "s.toml"], {"s.toml": "name = 5\n"}, ("name",)),
        ("a misspelt table", "magfab", ["check", "s.toml"], {"s.toml": "[mold]\ncavities = 2\n"}, ("mold",)),
        ("nan in a spec", "magfab", ["check", "s.toml"],
         {"s.toml": f"[elastomer]\nheight_mm = {rng.choice(['nan', 'inf', '-inf'])}\n"}, ("height_mm",)),
        ("a spec value past its bound", "magfab", ["check", "s.toml"],
         {"s.toml": f"[mould]\ncavities = {rng.choice([0, -1, 10**6, 2**64])}\n"}, ("mould.cavities",)),
        ("sweep without --grid or --lhs", "magfab", ["sweep", "t.toml", "--out", "s"], {"t.toml": ""}, ("--grid",)),
        ("sweep --grid 1", "magfab", ["sweep", "t.toml", "--grid", "1"], {"t.toml": ""}, ()),
        ("sweep --models nonsense", "magfab", ["sweep", "t.toml", "--lhs", "2", "--models", junk, "--out", "s"],
         {"t.toml": ""}, ("--models",)),
        ("calibrate --taxel -1", "magfab", ["calibrate", "scan.csv", "--taxel", "-1"], {"scan.csv": "x"}, ()),
        ("calibrate --date without --sensor", "magfab", ["calibrate", "scan.csv", "--date", "yesterday"],
         {"scan.csv": "x"}, ("--date",)),
        ("an empty scan", "magfab", ["calibrate", "scan.csv", "--out", "out"], {"scan.csv": ""}, ("scan.csv",)),
        ("a scan with a nan", "magfab", ["calibrate", "scan.csv", "--out", "out"],
         {"scan.csv": "\n".join(bad_row) + "\n"}, ("scan.csv",)),
        ("sensor show of a path", "magfab", ["sensor", "show", "../x"], {}, ()),
        ("readout: unknown command", "readout", [junk], {}, ()),
        ("readout: stream --count x", "readout", ["stream", "--simulate", "--count", "x"], {}, ()),
        ("readout: --baud abc", "readout", ["info", "--simulate", "--baud", "abc"], {}, ()),
        ("readout: upload of a missing file", "readout", ["upload", "missing.json", "--simulate"], {},
         ("missing.json",)),
        ("readout: upload of junk", "readout", ["upload", "j.json", "--simulate", "--simulate-eeprom", "e.bin"],
         {"j.json": bytes(rng.randrange(256) for _ in range(100))}, ("j.json",)),
        ("readout: stream --simulate-corrupt 2", "readout", ["stream", "--simulate", "--simulate-corrupt", "2",
                                                             "--count", "5"], {}, ()),
        ("readout: --timeout nan", "readout", ["info", "--simulate", "--timeout", "nan"], {}, ()),
        ("readout: record into a folder", "readout", ["record", "folder", "--simulate", "--seconds", "0.1"],
         {"folder/x": "x"}, ()),
        ("readout: stream --text --raw", "readout", ["stream", "--simulate", "--text", "--raw"], {}, ("--raw",)),
        ("readout: a missing port", "readout", ["info", "--port", f"/dev/{junk}"], {}, ()),
    ]
    cases = []
    for name, prog, args, files, words in rng.sample(templates, env.n(8, len(templates))):
        cases.append(Case(8, name, prog, args, writes(files), words=words))
    return cases


GENERATORS = {1: class1, 2: class2, 3: class3, 4: class4, 5: class5, 6: class6, 7: class7, 8: class8}


# ---- the table -----------------------------------------------------------------------------------------------------

def summary(outcomes: list[Outcome]) -> list[dict]:
    rows = []
    for cls, title in CLASSES.items():
        mine = [o for o in outcomes if o.cls == cls]
        if not mine:
            continue
        row: dict[str, Any] = {"class": cls, "name": title, "tried": len(mine)}
        for label in LABELS:
            row[label] = sum(o.label == label for o in mine)
        row["lost"] = sum(o.lost for o in mine)
        row["slow"] = sum(o.slow for o in mine)
        row["usage blocks"] = sum(o.usage_block for o in mine)
        worst_s = max(mine, key=lambda o: o.wall_s)
        worst_mb = max(mine, key=lambda o: o.peak_mb)
        row["worst s"], row["worst s case"] = round(worst_s.wall_s, 1), worst_s.name
        row["worst MB"], row["worst MB case"] = round(worst_mb.peak_mb), worst_mb.name
        row["worst CPU s"] = round(max(o.cpu_s for o in mine), 1)
        rows.append(row)
    return rows


COLUMNS = [("class", "class", 20), ("tried", "tried", 6), ("refused", "refused", 8), ("ok", "ok", 5),
           ("stopped", "stopped", 8), ("unclean", "unclean", 8), ("other reason", "other", 6),
           ("wrongly refused", "wrong-ref", 10), ("accepted bad", "acc-bad", 8), ("traceback", "tb", 4),
           ("over budget", "over", 5), ("lost", "lost", 5), ("slow", ">60s", 5), ("worst s", "worst s", 8),
           ("worst MB", "worst MB", 9)]


def table(rows: list[dict]) -> str:
    head = "".join(f"{title:>{w}}" if k != "class" else f"{title:<{w}}" for k, title, w in COLUMNS)
    out = [head, "-" * len(head)]
    total: dict[str, Any] = {"class": "all"}
    for row in rows:
        cells = []
        for key, _, w in COLUMNS:
            value = f"{row['class']} {row['name']}"[:w - 1] if key == "class" else row[key]
            cells.append(f"{value:<{w}}" if key == "class" else f"{value:>{w}}")
            if key not in ("class",):
                total[key] = max(total.get(key, 0), value) if key.startswith("worst") else total.get(key, 0) + value
        out.append("".join(cells))
    out.append("-" * len(head))
    out.append("".join(f"{total[k]:<{w}}" if k == "class" else f"{total.get(k, 0):>{w}}" for k, _, w in COLUMNS))
    return "\n".join(out)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer cases, no real builds near the budget (~5 min)")
    parser.add_argument("--seed", type=int, default=0, help="the generators' seed (default 0)")
    parser.add_argument("--json", type=Path, metavar="FILE", help="write the table and every case's outcome here")
    parser.add_argument("--only", type=int, nargs="+", choices=list(CLASSES), metavar="CLASS",
                        help="run only these classes (1-8)")
    parser.add_argument("--keep-failures", type=Path, metavar="DIR",
                        help="copy the folder of every failing case here (default: not kept)")
    parser.add_argument("--work", type=Path, metavar="DIR",
                        help="work in this folder and keep it (its reference build is reused by the next run given it; "
                             "default: a temporary folder, removed)")
    args = parser.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # the work folder and the running child cleaned up
    _tests_path()
    started = time.perf_counter()
    load = os.getloadavg()
    work = Path(tempfile.mkdtemp(prefix="magfab-adversarial-")) if args.work is None else args.work.resolve()
    work.mkdir(parents=True, exist_ok=True)
    try:
        env = prepare(work, args.quick, args.seed)
        cases: list[Case] = []
        for cls, make in GENERATORS.items():
            if args.only and cls not in args.only:
                continue
            made = make(env, random.Random(f"{args.seed}-{cls}"))
            print(f"class {cls} ({CLASSES[cls]}): {len(made)} cases", flush=True)
            cases += made
        if args.keep_failures is not None:
            args.keep_failures.mkdir(parents=True, exist_ok=True)
        runner = Runner(env, args.keep_failures)
        for k, case in enumerate(cases, 1):
            runner.run(case, k, len(cases))
    finally:
        if args.work is None:
            shutil.rmtree(work, ignore_errors=True)
    rows = summary(runner.outcomes)
    if max(load[0], os.getloadavg()[0]) > 1.5 * (os.cpu_count() or 1):
        print(f"\nwarning: the machine was loaded (load average {load[0]:.1f} at the start, {os.getloadavg()[0]:.1f} "
              "at the end): wall times are stretched by other processes; a case killed at the timeout with little "
              "CPU time waited for the processor, not for its input's work", flush=True)
    elapsed = time.perf_counter() - started
    print()
    print(table(rows))
    usage = sum(o.usage_block for o in runner.outcomes)
    print(f"\n{len(runner.outcomes)} cases in {elapsed / 60:.1f} min ({'quick' if args.quick else 'full'} run, seed "
          f"{args.seed}); each held to {TIMEOUT_S:.0f} s and {CHILD_AS_BYTES / 2**30:.1f} GB of address space, the "
          f"budget {BUDGET_S:.0f} s and {BUDGET_MB / 1024:.0f} GB; load average {load[0]:.1f} at the start, "
          f"{os.getloadavg()[0]:.1f} at the end on {os.cpu_count()} cores")
    if usage:
        print(f"{usage} refusal(s) were the argument parser's usage block (click: 3 lines, argparse: 2), counted as "
              "refused")
    for o in runner.outcomes:
        if o.slow:
            print(f"\nSLOW class {o.cls} [{o.label}] {o.name}: {o.wall_s:.0f} s wall, {o.cpu_s:.0f} s CPU, "
                  f"{o.peak_mb:.0f} MB (finished before the kill, past its allowance of {o.allowed_s:.0f} s)"
                  f"\n  {o.command}" + (f"\n  input: {o.detail}" if o.detail else ""))
    failing = [o for o in runner.outcomes if o.label in FAILURES or o.lost]
    for o in failing:
        print(f"\nFAIL class {o.cls} [{o.label}{', lost' if o.lost else ''}] {o.name}\n  {o.command}\n  {o.why[:600]}"
              + (f"\n  input: {o.detail}" if o.detail else "") + (f"\n  kept in {o.folder}" if o.folder else ""))
    if args.json:
        args.json.write_text(json.dumps({
            "mode": "quick" if args.quick else "full", "seed": args.seed, "minutes": round(elapsed / 60, 2),
            "bound": {"timeout_s": TIMEOUT_S, "address_space_GB": CHILD_AS_BYTES / 2**30, "budget_s": BUDGET_S,
                      "budget_MB": BUDGET_MB},
            "load_average": [load[0], os.getloadavg()[0]], "cores": os.cpu_count(),
            "classes": rows, "cases": [o.__dict__ for o in runner.outcomes]}, indent=2) + "\n")
    return 1 if failing else 0


if __name__ == "__main__":
    sys.exit(main())
