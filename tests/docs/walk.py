"""Paste a page's commands into a shell at the simulated bench, as a person would, one line at a time.

:class:`Bench` keeps the working folder (``cd`` lines move it) and runs every other line with ``bash -c`` in a
shell environment whose ``pip``/``python`` are a fresh virtual environment (what ``pip install ./readout``
installs into) and whose ``magfab`` is the one under test. Where a person would do something besides typing:

* a line whose comment says ``Ctrl-C ends it`` runs until the bench has seen enough, then gets SIGINT;
* ``magfab-readout record`` runs while :class:`Scan` moves the simulated tip along the build's scan track and
  logs the reference sensor's forces to ``reference.csv`` (host-clock time, Fx_N, Fy_N, Fz_N at 1 kHz), both on
  the board's clock (:meth:`Scan.play`); on an array, the tip of the taxel the line's comment names (``during taxel
  0's scan``);
* ``magfab-readout stream --zero N`` (Ctrl-C'd), when the test gave :attr:`Bench.press`, zeroes at rest, then the
  press comes on and goes, and the stream runs until it has printed the rest after it (:attr:`Bench.after_press`);
* ``magfab-readout view`` (Ctrl-C'd): the person opens the address it prints in a browser (the walk's headless
  Chromium; ``BROWSER=true`` in the shell makes the readout's own opening of it a no-op), watches, presses Zero;
* ``magfab-readout check`` waits for each prompt, then the known weight goes on the tip, the board is turned over or
  warmed as the prompt asks (:meth:`Bench._do`), and Enter is pressed;
* ``magfab-readout weigh`` likewise: at each step the board goes onto the stand at the step's angle with the step's
  mass on the tip. With :attr:`Bench.skin` set (a :class:`Skin`), the board's chip reads that sensor, which is not the
  nominal one, at rest, under the weight jig and under the check's weight.

The only text changed in a line is the port: ``/dev/ttyACM0`` (the pages' Linux Uno) becomes the rig's
pseudo-terminal, which ``MAGFAB_READOUT_PORT`` also names for the commands that take the default port."""

from __future__ import annotations

import bisect
import contextlib
import csv
import hashlib
import itertools
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from cdp import Chromium
from conftest import require_tool

import magfab
from magfab.units import G0 as G

#: The Earth's vertical field where the walk's bench stands, uT (0.45 G: mid-latitudes), and the magnet's
#: remanence per C (NdFeB, the recipe's -0.12 %/C), for the check's turn-over and warm-up prompts.
EARTH_Z_UT, MAGNET_PER_C = 45.0, -0.0012
PAGE_PORT = "/dev/ttyACM0"


@dataclass
class Ran:
    line: str
    cwd: Path
    returncode: int
    stdout: str
    stderr: str
    seconds: float = 0.0  # how long it ran (set as it is logged; for -s reports, never asserted)


class Scan:
    """The scan track of a build's simulated scan (``calibration/scan_simulated.csv``; an array's, one per taxel:
    ``scan_simulated_taxel_NN.csv``), subsampled to a serpentine of ``every``-th points, played on the rig: the field
    follows the tip, and the reference sensor logs the force. Between two points both move linearly (the stage
    moves), so the sensor's and the reference's timestamps need agree only to a fraction of a step. On an array the
    other chips keep their readings at rest (array.json's own field plus the other magnets'): calibrating taxel K
    reads only taxel K's rows."""

    def __init__(self, build_dir: Path, every: int = 5, dwell_s: float = 0.03, rest_s: float = 1.0) -> None:
        self.spec = json.loads((build_dir / "spec.json").read_text())
        layout = build_dir / "calibration" / "array.json"
        if layout.is_file():  # an array: every chip's reading at rest, one track per taxel
            doc = json.loads(layout.read_text())
            self.readings = [[a + b for a, b in zip(own, other)]
                             for own, other in zip(doc["rest_uT"], doc["offset_uT"])]
            names = [f"scan_simulated_taxel_{k:02d}.csv" for k in range(len(self.readings))]
        else:
            self.readings, names = None, ["scan_simulated.csv"]
        self.tracks = [self._track(build_dir / "calibration" / name, every) for name in names]
        self.dwell_s, self.rest_s = dwell_s, rest_s
        self.axis = self.tracks[0][1]
        self.rest = self.field_at(0.0)

    def _track(self, path: Path, every: int) -> tuple[list, list]:
        """(serpentine of (B, F) points, sorted on-axis (Fz, B) points) of one simulated scan file."""
        cal = self.spec["calibration"]
        n_y = round(cal["scan_y_mm"] / cal["scan_step_mm"]) + 1
        with open(path, newline="") as f:
            rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
        grid = [rows[k:k + n_y] for k in range(0, len(rows), n_y)]
        points = []
        for i, row in enumerate(grid[::every]):
            row = row[::every]
            points += row if i % 2 == 0 else row[::-1]
        centre = [row[n_y // 2] for row in grid]  # the track's points on the axis: a press straight down
        return ([([float(r[k]) for k in ("Bx_uT", "By_uT", "Bz_uT")], [float(r[k]) for k in ("Fx_N", "Fy_N", "Fz_N")])
                 for r in points],
                sorted((float(r["Fz_N"]), [float(r[k]) for k in ("Bx_uT", "By_uT", "Bz_uT")]) for r in centre))

    def field_at(self, fz_N: float) -> list[float]:
        """The field of an on-axis press of ``fz_N`` (interpolated along the track's on-axis points)."""
        below = [p for p in self.axis if p[0] <= fz_N] or self.axis[:1]
        above = [p for p in self.axis if p[0] >= fz_N] or self.axis[-1:]
        (f0, b0), (f1, b1) = below[-1], above[0]
        w = 0.0 if f1 == f0 else (fz_N - f0) / (f1 - f0)
        return [a + w * (b - a) for a, b in zip(b0, b1)]

    def at_rest(self, rig) -> None:
        """Every tip at rest."""
        if self.readings is None:
            rig.set_field(*self.rest)
        else:
            rig.set_fields(self.readings)

    def _fields(self, taxel: int, b: list[float]) -> list:
        """Every chip's field with taxel ``taxel``'s reading ``b`` (a single taxel's: ``b`` alone)."""
        if self.readings is None:
            return [b]
        return [b if k == taxel else r for k, r in enumerate(self.readings)]

    def play(self, rig, taxel: int = 0, wait_s: float = 600.0):
        """Move the tip (an array's: taxel ``taxel``'s) along the track on the board's own clock (:meth:`Rig.follow`).
        As on a bench, the motion starts and ends with the tip at rest (:attr:`rest_s` each: the rows a calibration
        reads the field at rest from), and the stage moves from rest to the track's first point and back. Returns
        ``log(reference, recording)``, which writes the reference sensor's log of that motion (:func:`_log`)."""
        rest = ((self.rest if self.readings is None else self.readings[taxel]), [0.0, 0.0, 0.0])
        points = [rest, *self.tracks[taxel][0], rest]
        moves = [(rest, rest, self.rest_s), *((p0, p1, self.dwell_s) for p0, p1 in itertools.pairwise(points)),
                 (rest, rest, self.rest_s)]
        ends = list(itertools.accumulate(seconds for _, _, seconds in moves))
        start = rig.board_s

        def stage(board_s: float) -> tuple[list[float], list[float]]:
            """(field, force) with the stage where it is at ``board_s``: linear between two points."""
            t = min(max(board_s - start, 0.0), ends[-1])
            k = min(bisect.bisect_right(ends, t), len(moves) - 1)
            (b0, f0), (b1, f1), seconds = moves[k]
            w = min(max((t - (ends[k] - seconds)) / seconds, 0.0), 1.0)
            return ([a + w * (b - a) for a, b in zip(b0, b1)], [a + w * (b - a) for a, b in zip(f0, f1)])

        rig.follow(lambda board_s: self._fields(taxel, stage(board_s)[0]))
        deadline = time.monotonic() + wait_s
        try:
            while rig.board_s < start + ends[-1]:
                if rig.error is not None or time.monotonic() > deadline:
                    raise AssertionError(f"the scan's stage: the simulated board stopped or stalled ({rig.error!r})")
                time.sleep(0.01)
        finally:
            rig.follow(None)
            self.at_rest(rig)
        array = self.readings is not None
        return lambda reference, recording: _log(reference, recording, taxel if array else None, stage, start,
                                                 ends[-1])


def _recorded_s(path: Path) -> float:
    """The device time of the last whole row a recording being written holds (its first column), -1 before any."""
    try:
        with open(path, "rb") as f:
            f.seek(max(0, f.seek(0, os.SEEK_END) - 4096))
            lines = f.read().split(b"\n")[:-1]  # the last piece may be a row half written
    except OSError:
        return -1.0
    for raw in reversed(lines):
        with contextlib.suppress(ValueError):
            return float(raw.split(b",")[0])
    return -1.0


def _log(reference: Path, recording: Path, taxel: int | None, stage, start: float, seconds: float) -> None:
    """The reference sensor's log of the stage's motion (``stage(board_s) -> (field, force)`` from board time
    ``start`` for ``seconds``): a row every millisecond of it, stamped on the host clock as the recording's clock
    merge will read it. A simulated board's clock runs unevenly against the wall clock (it falls behind while the
    stage is followed, with five chips, and more on a loaded machine), while the merge fits one line to the
    recording's (time_s, host_time_s), as for a real board's steady clock. So the log is stamped on that line, found
    here independently (the least-gap line under the pairs, scipy's linear program), at each row's device time: its
    board time less the recording's offset, which the recorded field itself gives (where it best matches the
    stage's, as a lab aligns a log by a tap)."""
    import numpy as np
    from scipy.optimize import linprog

    with open(recording, newline="") as f:
        rows = [r for r in csv.DictReader(line for line in f if not line.startswith("#"))
                if taxel is None or int(r["taxel"]) == taxel]
    t, h, bz = (np.array([float(r[k]) for r in rows]) for k in ("time_s", "host_time_s", "Bz_uT"))
    grid = np.arange(start - 1.0, start + seconds + 1.0, 0.001)  # the stage's field, at rest on both sides
    field = np.array([stage(b)[0][2] for b in grid])

    def misfit(offset: float) -> float:
        return float(np.mean((bz - np.interp(t + offset, grid, field)) ** 2))

    candidates = np.arange(start + seconds - t[-1], start - t[0] + 0.0025, 0.0025)  # the motion within the recording
    if candidates.size == 0:
        raise AssertionError(f"{recording}: the recording ({t[-1]:.1f} s) is shorter than the scan ({seconds:.1f} s)")
    best = min(candidates, key=misfit)
    offset = min(np.arange(best - 0.005, best + 0.005, 0.0001), key=misfit)
    x, y = t - t[0], h - h[0]
    fit = linprog(c=[-len(x), -float(x.sum())], A_ub=np.column_stack([np.ones_like(x), x]), b_ub=y,
                  bounds=[(None, None), (0.1, 10.0)], method="highs")
    if not fit.success:
        raise AssertionError(f"{recording}: no line under its (time_s, host_time_s): {fit.message}")
    a, rate = fit.x
    with open(reference, "w", newline="") as f:
        out = csv.writer(f)
        out.writerow(["time_s", "Fx_N", "Fy_N", "Fz_N"])
        for tick in range(int(seconds * 1000) + 1):
            board_s = start + tick / 1000
            out.writerow([f"{h[0] + a + rate * (board_s - offset - t[0]):.6f}",
                          *(f"{v:.6f}" for v in stage(board_s)[1])])


class Skin:
    """A sensor that is not the nominal one, for the walk's weight calibration: drawn across the material, magnet and
    assembly bands (:func:`magfab.models.weighing_study.draw_sensor`, ``seed``), its response made by the other
    hyperelastic law than the fit's, its magnet tilted and offset, the Earth's field turning with the stand.
    :meth:`field` is what its chip reads with ``mass_g`` on the tip and the board at ``angle_deg`` (no noise: the
    simulated chip adds its own)."""

    def __init__(self, build_dir: Path, seed: int = 3) -> None:
        from magfab.design import derive
        from magfab.models.predict import predict
        from magfab.models.weighing import SensorModel
        from magfab.models.weighing_study import draw_sensor, truth_model
        from magfab.spec import spec_from_json

        design = derive(spec_from_json(json.loads((build_dir / "spec.json").read_text())))
        prediction = predict(design)
        model = SensorModel.of(design, prediction)
        self.rng = np.random.default_rng(seed)
        self.sensor = self.first = draw_sensor(model, truth_model(design, prediction, model), self.rng)

    def field(self, mass_g: float, angle_deg: float) -> list[float]:
        return [float(b) for b in self.sensor.reading(mass_g, angle_deg)]

    def reskin(self) -> None:
        """A new skin cast on the same board and magnet (:meth:`magfab.models.weighing_study.Truth.reskinned`)."""
        self.sensor = self.sensor.reskinned(self.rng)


@dataclass
class Bench:
    """A shell at the bench. ``plug_in(build_dir)`` gives the rig (a context manager made from the build: its
    chip model and address) once the first line needs the board; the scan track is read then too, before a
    calibration replaces the build's simulated scan."""
    cwd: Path
    venv: Path
    plug_in: object
    weight_g: float = 50.0
    press: list | None = None  # every chip's field during a press, held while a Ctrl-C'd ``stream`` runs (zeroed)
    # How long that press is held, in the board's (simulated) time: ~160 of a 5-chip board's cycles, of which the
    # readout prints fewer when it falls behind and leaves cycles out (11 of 0.6 s's ~65 under a load of 7 on 2 cores).
    press_s: float = 1.5
    #: Given the stream's output so far: True once it shows enough of the rest after the press (a stream that falls
    #: behind the board prints the last cycles late, and Ctrl-C would cut them off). None: 0.5 s after, as a person.
    after_press: object = None
    wait_s: float = 120.0  # how long the walk waits for a stream's output (its zeroing, each of those phases)
    rig: object = None
    scan: Scan | None = None
    home: Path | None = None  # the folder the walk started in (the spec's: the README's sensors/ is made there)
    skin: Skin | None = None  # the sensor on the board, when it is not the scan's nominal one (the weights walk)
    weighed: dict | None = None  # the weights walk's: its skin, its first line's index in ran, its board
    ran: list[Ran] = field(default_factory=list)
    #: What the bench's measurements wrote, as each was made: (its line's index in :attr:`ran`, the file, its sha256)
    #: for every ``record``'s recording and its scan's reference log (the next recording in the folder replaces both).
    produced: list[tuple[int, Path, str]] = field(default_factory=list)

    @property
    def env(self) -> dict:
        """:func:`bench_env`, and what the board on the bench sets besides (an RP2040 rig's ``$USER``, which names
        its drive's folder)."""
        return {**bench_env(self.venv, self.rig.port if self.rig is not None else None),
                **getattr(self.rig, "env", {})}

    def swap(self, rig=None):
        """Unplug the board on the bench (powered off: its image and EEPROM kept) and plug in ``rig``, a board used
        before, as it was left; or, with None, leave the bench empty for a new board, which the next line that needs
        one plugs in (:attr:`plug_in`). Returns the board unplugged. The commands then reach the board plugged in:
        the pages' port is its port."""
        old = self.rig
        if old is not None:
            old.power_off()
        self.rig = rig
        if rig is not None:
            rig.power_on()
            self.scan.at_rest(rig)
        return old

    def _board(self, line: str) -> None:
        if self.rig is None and (PAGE_PORT in line or "magfab-readout" in line or "flash.sh" in line):
            self.scan = Scan(self.cwd)
            self.rig = self.plug_in(self.cwd)
            self._at_rest()

    def paste(self, line: str, timeout_s: float = 600) -> Ran:
        self._started = time.monotonic()
        self._board(line)
        if self.rig is not None:
            line = line.replace(PAGE_PORT, self.rig.port)
        if line.startswith("cd "):
            self.cwd = (self.cwd / line[3:].split("#")[0].strip()).resolve()
            return self._log(Ran(line, self.cwd, 0, "", ""))
        if line.startswith("magfab sensor reskin") and self.skin is not None:
            self.skin.reskin()  # the person casts the new skin the line notes
        if (("magfab-readout check" in line or "magfab-readout weigh" in line)
                and not {"--yes", "-y", "--no-weight"} & set(line.split())):
            return self._log(self._interactive(line, timeout_s))
        if "Ctrl-C ends it" in line:
            ran = self._log(self._until_interrupted(line, timeout_s))
            if " record " in f" {line} ":
                self._produced(line)
            return ran
        proc = subprocess.run(["bash", "-c", line], cwd=self.cwd, env=self.env, capture_output=True, text=True,
                              timeout=timeout_s)
        return self._log(Ran(line, self.cwd, proc.returncode, proc.stdout, proc.stderr))

    def _produced(self, line: str) -> None:
        """Note what a ``record`` line and its scan's reference log wrote (:attr:`produced`)."""
        words = line.split("#")[0].split()
        for name in (words[words.index("record") + 1], "reference.csv"):
            path = self.cwd / name
            if path.is_file():
                self.produced.append((len(self.ran) - 1, path, hashlib.sha256(path.read_bytes()).hexdigest()))

    def python(self, source: str, timeout_s: float = 300) -> Ran:
        """A ```python block, in the bench venv's Python. A block that uses LeRobot runs in the tests' Python, which
        has LeRobot's datasets part (tests/lerobot_loader.py), with this build's readout package on its path: the
        bench venv holds only what ``pip install ./readout`` installs."""
        self._started = time.monotonic()
        argv, env = ["python", "-c", source], self.env
        if "from lerobot" in source:
            tests, src = str(Path(__file__).resolve().parents[1]), str(self.cwd / "readout" / "src")
            argv = [sys.executable, "-c", f"import sys; sys.path[:0] = [{tests!r}, {src!r}]; import lerobot_loader; "
                    f"lerobot_loader.install()\n{source}"]
            env = {**env, "HF_HUB_OFFLINE": "1"}
        proc = subprocess.run(argv, cwd=self.cwd, env=env, capture_output=True, text=True, timeout=timeout_s)
        return self._log(Ran("python: " + source.splitlines()[0], self.cwd, proc.returncode, proc.stdout, proc.stderr))

    def _log(self, ran: Ran) -> Ran:
        ran.seconds = time.monotonic() - self._started
        self.ran.append(ran)
        return ran

    def _start(self, line: str, stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kw) -> subprocess.Popen:
        return subprocess.Popen(["bash", "-c", "exec " + line], cwd=self.cwd, env=self.env, text=True,
                                stdout=stdout, stderr=stderr, **kw)

    def _until_interrupted(self, line: str, timeout_s: float) -> Ran:
        """Run it; meanwhile play the scan (``record``) or let it run 2 s; then Ctrl-C (SIGINT to it). Its output
        goes to files, as to a terminal that never stops reading (a pipe nobody reads would stall it)."""
        with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
            board_from = self.rig.board_s if self.rig is not None else 0.0
            proc = self._start(line, stdout=out, stderr=err)
            log = None
            words = line.split("#")[0].split()
            try:
                time.sleep(1.5)  # it opens the port and finds the frames
                if " record " in f" {line} ":
                    taxel = re.search(r"taxel (\d+)", line.partition("#")[2])  # an array's: the taxel the page scans
                    log = self.scan.play(self.rig, int(taxel[1]) if taxel else 0)
                    # A person ends it once the tip is back at rest; a reader that has fallen behind the board (five
                    # chips, a loaded machine) must first have written the samples of the motion's end. Its device
                    # time counts from its first sample, made after board_from: past this, they are in the file.
                    until, path = self.rig.board_s - board_from + 0.3, self.cwd / words[words.index("record") + 1]
                    self._await(line, proc, out, err, "the recording to reach the scan's end",
                                lambda _: _recorded_s(path) >= until)
                elif " stream " in f" {line} " and "--zero" in line and self.press is not None:
                    self._press_while_streaming(line, proc, out, err)
                elif " view " in f" {line} ":
                    self._look_at_view(line, proc, out, err)
                time.sleep(0.5)
                proc.send_signal(signal.SIGINT)
                proc.wait(timeout_s)
            finally:
                proc.kill()  # a no-op once it has ended; else (a failure above) it must not outlive the walk
            if log is not None:  # the reference's log, stamped on the recording's clock (its file, now written)
                log(self.cwd / "reference.csv", path)
            out.seek(0)
            err.seek(0)
            return Ran(line, self.cwd, proc.returncode, out.read(), err.read())

    def _look_at_view(self, line: str, proc: subprocess.Popen, out, err) -> None:
        """``view``: the person opens the address it prints (headless Chromium, in real time), watches for 2 s,
        presses Zero, watches 1.5 s more; the page must have drawn frames, logged the zero and thrown nothing."""
        self._await(line, proc, err, out, "the address it serves", lambda text: "view at http://" in text)
        url = re.search(r"view at (http://127\.0\.0\.1:\d+/)", _text(err))[1]
        with tempfile.TemporaryDirectory() as profile, Chromium(require_tool("chromium"), Path(profile)) as browser:
            browser.open(url)
            browser.wait(2.0)
            browser.evaluate("document.getElementById('zero').click()")
            browser.wait(1.5)
            seen = browser.evaluate("({frames: frames.length, log: document.getElementById('log').textContent})")
            assert seen["frames"] > 0 and "zero: offset" in seen["log"] and not browser.errors, (line, seen,
                                                                                                 browser.errors)

    def _press_while_streaming(self, line: str, proc: subprocess.Popen, out, err) -> None:
        """Once ``stream`` has zeroed (its ``# zero:`` lines out): 0.3 s at rest, :attr:`press` held for
        :attr:`press_s`, then 0.5 s at rest, each timed by the board's own (simulated) clock, not the wall clock: a
        loaded machine runs the simulated board slower, and a press held for a wall-clock time then spans too few of
        its cycles to be read."""
        taxels = len(self.press)
        self._await(line, proc, out, err, "its `# zero:` lines", lambda text: text.count("# zero:") >= taxels)
        for fields, seconds in ((None, 0.3), (self.press, self.press_s), (None, 0.5)):
            if fields is None:
                self.scan.at_rest(self.rig)
            else:
                self.rig.set_fields(fields)
            until = self.rig.board_s + seconds
            self._await(line, proc, out, err, f"the board to run {seconds:g} s more",
                        lambda _, until=until: self.rig.board_s >= until)
        if self.after_press is not None:
            self._await(line, proc, out, err, "the stream to print the rest after the press", self.after_press)

    def _await(self, line: str, proc: subprocess.Popen, out, err, what: str, seen) -> None:
        """Until ``seen(its output so far)``; fails at once if the command ends first or the board stops, and after
        :attr:`wait_s` in any case (a stream's ``--zero N`` takes N of the board's cycles, a few seconds: one that has
        not zeroed by then never will, and the walk would otherwise wait out the whole command's deadline)."""
        deadline = time.monotonic() + self.wait_s
        while not seen(_text(out)):
            problem = (f"it exited {proc.returncode}" if proc.poll() is not None else
                       f"the simulated board stopped: {self.rig.error!r}" if self.rig.error is not None else
                       f"still running after {self.wait_s:g} s" if time.monotonic() > deadline else None)
            if problem:
                raise AssertionError(f"`{line}`: waiting for {what}, {problem} (the board was reset "
                                     f"{self.rig.resets} time(s)):\n{_text(out)[-3000:]}\n{_text(err)[-3000:]}")
            time.sleep(0.1)

    def _at_rest(self) -> None:
        """Nothing on the tip: the skin's field where one is set, else the scan's rest."""
        if self.skin is not None:
            self.rig.set_field(*self.skin.field(0.0, 0.0))
        else:
            self.scan.at_rest(self.rig)

    def _interactive(self, line: str, timeout_s: float) -> Ran:
        """``check`` and ``weigh``: at each of their prompts, what a person does (:meth:`_do`), then Enter."""
        self._at_rest()
        proc = self._start(line, stdin=subprocess.PIPE)
        err: list[str] = []
        prompts: list[str] = []
        asked = threading.Event()

        def read_err() -> None:
            for chunk in iter(lambda: proc.stderr.read(1), ""):
                err.append(chunk)
                if "".join(err[-13:]) == "press Enter: ":
                    prompts.append("".join(err).rpartition("\n")[2])
                    asked.set()

        reader = threading.Thread(target=read_err, daemon=True)
        reader.start()
        deadline = time.monotonic() + timeout_s
        warming = threading.Event()
        while proc.poll() is None and time.monotonic() < deadline:
            if not asked.wait(0.1):
                continue
            asked.clear()
            self._do(prompts[-1], warming)
            time.sleep(0.3)
            proc.stdin.write("\n")
            proc.stdin.flush()
        if proc.poll() is None:  # the deadline passed: end it, so a broken page fails instead of hanging
            proc.kill()
        warming.set()
        if getattr(self, "_warming", None) is not None:
            self._warming.join(5)
            self._warming = None
        out = proc.stdout.read()
        proc.wait(timeout_s)
        reader.join(5)
        self._at_rest()
        return Ran(line, self.cwd, proc.returncode, out, "".join(err))

    def _do(self, prompt: str, stop: threading.Event) -> None:
        """What a person does at a prompt of ``check``: the weight on the tip; the sensor turned upside down (the
        vertical component of a 0.45 G Earth field reversed; the tip's own weight is not modelled here); warming it
        by 6 C over 2 s (the magnet's field falls 0.12 %/C, the chip's temperature rises); ``weigh``'s step: the board
        on the stand at the step's angle, the step's mass on the tip (:attr:`skin`'s field); else at rest."""
        # the prompt's own text: a piped stderr gets no newline from the Enter, so earlier prompts share its line
        text = prompt.removesuffix("press Enter: ").rpartition("press Enter: ")[2]
        step = re.search(r"in the ([\d.]+) deg stand.*\(([\d.]+) g on the tip\)", text)
        if step:
            assert self.skin is not None, "the weights walk needs Bench.skin: the sensor the board reads"
            self.rig.set_field(*self.skin.field(float(step[2]), float(step[1])))
        elif "weight on the tip" in prompt:
            self.rig.set_field(*(self.skin.field(self.weight_g, 0.0) if self.skin is not None
                                 else self.scan.field_at(self.weight_g * 1e-3 * G)))
        elif "upside down" in prompt:
            bx, by, bz = self.scan.rest
            self.rig.set_field(bx, by, bz - 2 * EARTH_Z_UT)
        elif "warm the sensor" in prompt:
            self._warming = threading.Thread(target=self._warm, args=(stop,), daemon=True)
            self._warming.start()
        else:
            self._at_rest()

    def _warm(self, stop: threading.Event, rise_C: float = 6.0, seconds: float = 2.0) -> None:
        t0 = time.monotonic()
        while not stop.is_set():
            dT = rise_C * min((time.monotonic() - t0) / seconds, 1.0)
            self.rig.set_field(*(b * (1.0 + MAGNET_PER_C * dT) for b in self.scan.rest), t_C=25.0 + dT)
            time.sleep(0.05)


def _text(file) -> str:
    """All a running command has written to ``file`` so far, read without moving the file's offset: the command
    shares it (its stdout is this file), and after a ``seek(0)`` here its next write would land at the start, over
    the lines it wrote first (how a stream's ``# zero:`` lines were lost and the walk waited for them until its
    deadline)."""
    fd = file.fileno()
    return os.pread(fd, os.fstat(fd).st_size, 0).decode(errors="replace")


def bench_env(venv: Path, port: str | None = None) -> dict:
    """The shell's environment: the bench venv first on PATH (its pip, python, magfab-readout), then the
    magfab under test (this interpreter's folder), then the system's. PYTHONPATH is the folder holding the magfab
    package this process imports, so the shell's ``magfab`` runs the code under test even when it is not the
    checkout the interpreter's ``magfab`` script was installed from (a second work tree, with PYTHONPATH set)."""
    path = [str(venv / "bin"), str(Path(sys.executable).parent), os.environ.get("PATH", "")]
    env = {k: v for k, v in os.environ.items() if k not in {"PYTHONPATH", "VIRTUAL_ENV", "PYTHONHOME"}}
    env.update(PATH=os.pathsep.join(path), VIRTUAL_ENV=str(venv), PIP_DISABLE_PIP_VERSION_CHECK="1",
               PYTHONPATH=str(Path(magfab.__file__).resolve().parents[1]),
               BROWSER="true")  # `view` opens its page with `true URL`: the walk's own Chromium is the person's browser
    if port:
        env["MAGFAB_READOUT_PORT"] = port
    return env
