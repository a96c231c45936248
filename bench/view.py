"""Live-view benchmark: what watching the sensor costs at the board's full rate, for the view magfab ships
(``magfab-readout view``: a page served by the readout, drawn by the browser) and for Rerun (``rerun-sdk``, the viewer
LeRobot uses), on the same simulated board, in the same run.

Run from the project root::

    python bench/view.py BUILD_DIR [--seconds S]

BUILD_DIR is a ``magfab build`` output folder (its ``readout/``: a single taxel's or an array's). What it measures,
each over S seconds of the simulated board at the firmware's rate (the simulated device paces its frames by the wall
clock, as a board does):

1. **Baseline**: the readout alone (``stream --simulate`` to /dev/null): its CPU, as a share of one core.
2. **The page**: ``magfab-readout view --simulate --no-browser`` with headless Chromium (tests/cdp.py, in real time)
   on its page. The readout's summary gives its own CPU and the page's figures: updates drawn a second and the time
   from a frame's read to the update that drew it (the page's clock against the readout's: one machine). Chromium's
   CPU is summed over its processes from /proc (utime + stime), as a share of one core.
3. **Rerun**, when ``import rerun`` works: the same frames from the same simulated board, logged as a user of Rerun
   would (per frame the time, Fx, Fy, Fz as ``Scalars`` and each taxel's force as an ``Arrows3D``), into a
   recording file (``rr.save``: no viewer can open a window here). Its CPU in this process, and the log calls' cost
   per frame. Rerun's viewer, which draws, needs a GPU surface this machine lacks; its cost is not counted, so this
   is the logging side only (a lower bound on Rerun's total).

Every figure is a ratio or a share measured in this run; nothing here asserts on a time. Prints a table and writes
``view_bench.json`` beside this script's output folder (``--out``, default the current folder).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from cdp import Chromium  # noqa: E402 - tests/ is put on the path just above

TICK = os.sysconf("SC_CLK_TCK")


def _readout(build: Path, *args: str, **kw) -> subprocess.Popen:
    src = str(build / "readout" / "src")
    return subprocess.Popen([sys.executable, "-c", f"import sys; sys.path.insert(0, {src!r}); "
                             "from magfab_readout.cli import main; sys.exit(main())", *args],
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, **kw)


def _session_cpu_s(session: int) -> float:
    """utime + stime of every process in session ``session`` (a browser and its children), s."""
    total = 0
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            fields = (entry / "stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[3]) == session:  # field 6 of stat (session id), counted after the command's name
            total += int(fields[11]) + int(fields[12])
    return total / TICK


def _child_cpu(run) -> tuple[float, str]:
    """Run ``run()`` (which waits for one child) and return that child's CPU seconds and run()'s result."""
    import resource

    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    result = run()
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), result


def measure_stream(build: Path, seconds: float) -> dict:
    start = time.monotonic()
    cpu, err = _child_cpu(lambda: _readout(build, "stream", "--simulate", "--seconds", str(seconds))
                          .communicate(timeout=seconds + 120)[1])
    wall = time.monotonic() - start
    return {"readout_cpu_share": cpu / wall, "summary": err.strip().splitlines()[0]}


def measure_page(build: Path, seconds: float) -> dict:
    start = time.monotonic()
    proc = _readout(build, "view", "--simulate", "--no-browser", "--seconds", str(seconds))
    assert proc.stderr is not None
    url = re.search(r"(http://127\.0\.0\.1:\d+/)", proc.stderr.readline())[1]
    with tempfile.TemporaryDirectory() as profile, Chromium("chromium", Path(profile)) as browser:
        browser.open(url)
        browser.wait(1.0)  # the page loads and its first frames arrive
        cpu0, t0 = _session_cpu_s(browser.proc.pid), time.monotonic()
        browser.wait(max(1.0, seconds - 3.0))
        browser_cpu = (_session_cpu_s(browser.proc.pid) - cpu0) / (time.monotonic() - t0)
        errors = list(browser.errors)
    cpu, err = _child_cpu(lambda: proc.communicate(timeout=seconds + 120)[1])
    wall = time.monotonic() - start
    m = re.search(r"the page drew (\d+) updates \((\d+) frames, (\d+) a second\), from read to drawn median "
                  r"([\d.]+) ms, p95 ([\d.]+) ms, most ([\d.]+) ms", err)
    page = dict(zip(("drawn", "frames", "updates_per_s", "latency_median_ms", "latency_p95_ms", "latency_max_ms"),
                    map(float, m.groups()))) if m else {}
    return {"readout_cpu_share": cpu / wall, "browser_cpu_share": browser_cpu, "page": page, "errors": errors,
            "summary": err.strip().splitlines()[-1]}


def measure_rerun(build: Path, seconds: float) -> dict | None:
    try:
        import rerun as rr
    except ImportError:
        return None
    sys.path.insert(0, str(build / "readout" / "src"))
    from magfab_readout import ArrayCalibration, Calibration, Device
    from magfab_readout.array_sim import SimulatedArray
    from magfab_readout.simulate import SimulatedDevice
    from magfab_readout.taxels import ArrayReader

    array = ArrayCalibration.embedded()
    if array is None:
        device = Device(text=False, transport=SimulatedDevice(Calibration.embedded()))
        centres = [(0.0, 0.0, 0.0)]

        def frames():
            for s in device.samples(seconds=seconds):
                yield s.time_s, (s,)
    else:
        device = Device(text=False, transport=SimulatedArray(array), calibration=array.calibrations[0])
        reader = ArrayReader(device, array)
        centres = array.compensator.centres

        def frames():
            for c in reader.cycles(seconds=seconds, keep_up=True):
                yield c.time_s, c.taxels

    with tempfile.TemporaryDirectory() as folder:
        rr.init("magfab_view_bench", spawn=False)
        rr.save(str(Path(folder) / "view.rrd"))
        n, log_s = 0, 0.0
        start, cpu0 = time.monotonic(), time.process_time()
        with device:
            for t, taxels in frames():
                a = time.perf_counter()
                rr.set_time("device", duration=t or 0.0)
                for k, tx in enumerate(taxels):
                    fx, fy, fz = tx.force_N
                    rr.log(f"taxel/{k}/force", rr.Scalars([fx, fy, fz]))
                    rr.log(f"layout/taxel/{k}", rr.Arrows3D(origins=[centres[k]], vectors=[[fx, fy, fz]]))
                log_s += time.perf_counter() - a
                n += 1
        wall, cpu = time.monotonic() - start, time.process_time() - cpu0
        rr.disconnect()
        size = (Path(folder) / "view.rrd").stat().st_size
    return {"frames": n, "process_cpu_share": cpu / wall, "log_ms_per_frame": 1e3 * log_s / max(n, 1),
            "log_cpu_share": log_s / wall, "recording_bytes": size, "version": rr.__version__}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("build", type=Path, help="a magfab build's output folder")
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--out", type=Path, default=Path("."))
    args = parser.parse_args(argv)
    results = {"stream": measure_stream(args.build, args.seconds), "page": measure_page(args.build, args.seconds),
               "rerun": measure_rerun(args.build, args.seconds)}
    base = results["stream"]["readout_cpu_share"]
    page = results["page"]
    print(f"baseline  readout stream alone: {base:.1%} of a core  ({results['stream']['summary']})")
    print(f"page      readout + server: {page['readout_cpu_share']:.1%} ({page['readout_cpu_share'] / base:.2f}x the "
          f"baseline); browser: {page['browser_cpu_share']:.1%}; page: {page['page']}; errors: {page['errors']}")
    rerun = results["rerun"]
    if rerun is None:
        print("rerun     not installed (pip install rerun-sdk): not measured")
    else:
        print(f"rerun {rerun['version']}: process (readout + logging) {rerun['process_cpu_share']:.1%} "
              f"({rerun['process_cpu_share'] / base:.2f}x the baseline), log calls {rerun['log_cpu_share']:.1%} of a "
              f"core, {rerun['log_ms_per_frame']:.3f} ms a frame, {rerun['frames']} frames, "
              f"{rerun['recording_bytes'] / 1e6:.1f} MB recorded; its viewer not counted")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "view_bench.json").write_text(json.dumps(results, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
