"""``magfab-readout view``: the build's readout package, run as a user runs it on the simulated
board, serves the live page on 127.0.0.1; its frames carry every taxel's force, field and flags at the board's rate;
Zero tares from the page's request; the page itself, opened in headless Chromium in real time, draws the frames and
reports its read-to-drawn latency back to the readout's summary; a screenshot under virtual time shows the layout,
the series and the flags; bad options are one line and exit 2."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from cdp import Chromium
from conftest import require_tool
from test_readout_formats import readout


class View:
    """A running ``magfab-readout view --simulate --no-browser`` of a build's readout package."""

    def __init__(self, build, cwd: Path, *args: str) -> None:
        src = str(build.out_dir / "readout" / "src")
        self.proc = subprocess.Popen(
            [sys.executable, "-c", f"import sys; sys.path.insert(0, {src!r}); from magfab_readout.cli import main; "
             "sys.exit(main())", "view", "--simulate", "--no-browser", *args],
            cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        assert self.proc.stderr is not None
        first = self.proc.stderr.readline()
        m = re.match(r"magfab-readout: view at (http://127\.0\.0\.1:\d+/) \(Ctrl-C to stop\)$", first.strip())
        assert m, first + self.proc.stderr.read()
        self.url = m.group(1)

    def get(self, path: str) -> bytes:
        with urllib.request.urlopen(self.url + path.lstrip("/"), timeout=10) as r:
            return r.read()

    def post(self, path: str, body: bytes = b"") -> int:
        request = urllib.request.Request(self.url + path.lstrip("/"), data=body, method="POST")
        try:
            with urllib.request.urlopen(request, timeout=10) as r:
                return r.status
        except urllib.error.HTTPError as exc:
            return exc.code

    def events(self, seconds: float) -> tuple[list[dict], list[str]]:
        """The frames and notes the page is sent over ``seconds``."""
        frames: list[dict] = []
        notes: list[str] = []
        end = time.monotonic() + seconds
        with urllib.request.urlopen(self.url + "events", timeout=10) as r:
            for line in r:
                if line.startswith(b"data: "):
                    batch = json.loads(line[6:])
                    frames += batch.get("frames", [])
                    notes += batch.get("notes", [])
                if time.monotonic() > end:
                    break
        return frames, notes

    def finish(self) -> tuple[int, str]:
        _, err = self.proc.communicate(timeout=120)
        return self.proc.returncode, err


def test_frames_at_the_board_rate_and_zero_from_the_page(default_build, tmp_path):
    """The page's frames come in order at the board's rate, each with its taxel's force, field and flags. Zero,
    asked while the simulated tip is pressed (Fz over 1 N), subtracts that press from every later frame: at the next
    rest, where the tip reads 0 N untared, the frames read minus the offset the readout reports."""
    view = View(default_build, tmp_path, "--seconds", "9")
    meta = json.loads(view.get("/meta"))
    assert meta["taxels"] == [[0.0, 0.0]] and meta["spec"] == "magone" and meta["rate_Hz"] > 500
    assert b"<canvas" in view.get("/") and b"magfab-readout view" in view.get("/?raw")
    frames, notes = [], []
    asked = None
    end = time.monotonic() + 30
    with urllib.request.urlopen(view.url + "events", timeout=10) as r:
        for line in r:
            if not line.startswith(b"data: "):
                continue
            batch = json.loads(line[6:])
            frames += batch["frames"]
            notes += batch["notes"]
            if asked is None and any(f["F"][0][2] is not None and f["F"][0][2] > 1.0 for f in batch["frames"]):
                asked = frames[-1]["t"]
                assert view.post("/zero") == 202
            if (asked is not None and frames and frames[-1]["t"] > asked + 3.0) or time.monotonic() > end:
                break
    code, err = view.finish()
    assert code == 0, err
    assert asked is not None, "the simulated tip was never pressed"
    t = np.array([f["t"] for f in frames])
    assert np.all(np.diff(t) > 0)  # in order, none twice
    assert np.median(np.diff(t)) == pytest.approx(1 / meta["rate_Hz"], rel=0.02)
    assert all(len(f["F"]) == len(f["B"]) == len(f["f"]) == 1 and len(f["F"][0]) == 3 for f in frames)
    zero = [n for n in notes if n.startswith("zero: offset Fx")]
    assert len(zero) == 1, notes
    offset = np.array([float(x) for x in re.findall(r"[-+]\d+\.\d+", zero[0])])
    assert offset[2] > 0.5  # taken while pressed
    after = np.array([f["F"][0] for f in frames if f["t"] > asked + 0.3])
    # the tared frames at rest (the untared rest reads 0 N) read minus the offset
    assert after[:, 2].min() == pytest.approx(-offset[2], abs=0.01)
    assert re.search(r"view: \d+ samples shown \(100 more went to the zero\); 5\d\d\.\d samples/s", err), err


@pytest.mark.parametrize("which", ["single", "strip_1x5"])
def test_the_page_in_a_browser(default_build, array_builds, tmp_path, which):
    """Headless Chromium on the page in real time (no virtual clock), as a user opens it: the layout, the series
    and the raw field drawn, the flag table, Zero pressed on the page, no script error; the page's own latency
    (read to drawn) reaches the readout's summary. The screenshot is kept beside the test's folder to look at."""
    build = default_build if which == "single" else array_builds[which]
    taxels = 1 if which == "single" else 5
    view = View(build, tmp_path, "--seconds", "9", "--simulate-corrupt", "0.01")
    with Chromium(require_tool("chromium"), tmp_path / "profile") as browser:
        browser.open(view.url + "?raw")
        browser.wait(3.0)
        browser.evaluate("document.getElementById('zero').click()")
        browser.wait(2.5)
        shot = tmp_path / "view.png"
        browser.screenshot(shot)
        page = browser.evaluate("({title: document.getElementById('title').textContent, "
                                "log: document.getElementById('log').textContent, "
                                "rows: document.querySelectorAll('#flags tr').length, "
                                "state: document.getElementById('state').textContent})")
        # a flagged frame as the decoder would send it (the simulated board sends none): taxel 0 with a chip error
        # and its fault's name, which the page logs, counts and outlines in red
        browser.evaluate("(() => { const f = JSON.parse(JSON.stringify(frames[frames.length - 1])); "
                         "f.t += 0.001; f.f[0] = '-E' + f.f[0].slice(2).replace(/./g, '-'); f.F[0] = [null, null, "
                         "null]; f.e[0] = 'nack_at_read'; take(f); dirty = true; })()")
        browser.wait(0.3)
        flagged = browser.evaluate("({log: document.getElementById('log').textContent, "
                                   "E: document.querySelectorAll('#flags tr')[2].textContent})")
        errors = list(browser.errors)
        code, err = view.finish()
    assert code == 0, err
    assert errors == []
    assert ("magone" if taxels == 1 else "strip_1x5") in page["title"]
    assert "zero: offset" in page["log"] and "100 more went to the zero" in err
    assert page["rows"] == 1 + (4 if taxels == 1 else 5)  # a row per flag: an array's adds M (missing)
    assert "taxel 0  E chip error (nack_at_read)" in flagged["log"] and flagged["E"] == "E chip error1"
    m = re.search(r"the page drew (\d+) updates \((\d+) frames, (\d+) a second\), from read to drawn median "
                  r"([\d.]+) ms, p95 ([\d.]+) ms", err)
    assert m, err
    drawn, frames, _, median, p95 = map(float, m.groups())
    assert drawn > 20 and frames > 100
    assert 0 < median <= p95 < 2000  # sane: a page seconds behind the sensor would be broken, not slow
    import matplotlib.image as mpimg

    image = mpimg.imread(shot)[:, :, :3]
    assert image.shape[:2] == (800, 1400)
    colours = np.unique((image * 255).round().astype(np.uint8).reshape(-1, 3), axis=0)
    assert len(colours) > 200  # text, traces, discs: not a blank page
    red = (image[:, :, 0] > 0.75) & (image[:, :, 1] < 0.3) & (image[:, :, 2] < 0.3)
    assert red.sum() > 200  # the Fx and Bx traces and the shear arrows
    (tmp_path.parent / f"view_{which}.png").write_bytes(shot.read_bytes())


@pytest.mark.parametrize(("args", "says"), [
    (["--http-port", "70000"], "--http-port 70000: must be a port number"),
    (["--seconds", "-1"], "--seconds must be positive"),
    (["--count", "0"], "--count needs a positive number"),
    (["--zero", "-3"], "--zero needs a positive number"),
])
def test_bad_options_are_one_line(default_build, tmp_path, args, says):
    run = readout(default_build, tmp_path, "view", "--simulate", "--no-browser", *args, timeout=60)
    assert run.returncode == 2 and run.stderr.count("\n") == 1 and says in run.stderr, run.stderr
    assert list(tmp_path.iterdir()) == []


def test_a_port_in_use_is_one_line(default_build, tmp_path):
    view = View(default_build, tmp_path, "--seconds", "3")
    port = view.url.rsplit(":", 1)[1].strip("/")
    run = readout(default_build, tmp_path, "view", "--simulate", "--no-browser", "--http-port", port, timeout=60)
    assert run.returncode == 2 and run.stderr.count("\n") == 1 and f"--http-port {port}: cannot serve" in run.stderr
    assert view.finish()[0] == 0


def test_the_page_s_requests_are_checked(default_build, tmp_path):
    """What the page posts is bounded and checked: junk and oversized bodies are refused, unknown paths are 404,
    and only the known figures are kept."""
    view = View(default_build, tmp_path, "--seconds", "3")
    assert view.post("/stats", b"not json") == 400
    assert view.post("/stats", b"[1, 2]") == 400
    assert view.post("/stats", b"{" + b" " * 5000 + b"}") == 413
    assert view.post("/elsewhere") == 404
    # another site's page in the same browser (its Origin), or a host name rebound to 127.0.0.1, is refused
    port = view.url.rsplit(":", 1)[1].strip("/")
    for headers in ({"Origin": "http://evil.example"}, {"Host": f"evil.example:{port}"}):
        request = urllib.request.Request(view.url + "zero", data=b"", method="POST", headers=headers)
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(request, timeout=10)
        assert refused.value.code == 403
    with pytest.raises(urllib.error.HTTPError):
        view.get("/../etc/passwd")
    assert view.post("/stats", json.dumps({"drawn": 5, "frames": 40, "latency_median_ms": 3.0,
                                           "latency_p95_ms": 4.0, "latency_max_ms": 9.0, "fps": 30,
                                           "extra": "<script>"}).encode()) == 204
    code, err = view.finish()
    assert code == 0 and "the page drew 5 updates (40 frames, 30 a second)" in err and "<script>" not in err
