"""A study's time against the estimate it prints before the work (magfab.inverse.budget.study_cost).

Run from anywhere::

    python bench/study_time.py [--quick] [--json out.json]

Each plan runs the way a user runs it (``magfab sweep`` or ``magfab design`` in a child process, its own local
cluster); its wall time is measured (``time.perf_counter`` around the child) and divided by the estimate the
command printed (the ``estimated ...`` line, read back from its stdout at the seconds the same function gives
in-process here). A ratio at most 1 means the estimate bounded the run. The plans:

* the example targets' variables by the cheap models (the surrogate covers them all);
* the default variables (no ``[variables]``), whose corners fall outside the surrogate's region: the FE there;
* the full chain (``--models fe``) on every design;
* a search of the example targets with its verified designs built.

On a loaded machine wall time grows: the load average before each run is printed beside it. Nothing here asserts
on a time.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from magfab.inverse.budget import search_cost, study_cost  # noqa: E402  (the project on the path first)
from magfab.inverse.space import latin_hypercube  # noqa: E402
from magfab.inverse.targets import load_targets  # noqa: E402

EXAMPLE = (ROOT / "magfab" / "examples" / "targets.toml").read_text()
DEFAULT = "[study]\ntrials = 300\n"
#: The installed command, as a user runs it (beside this Python, or on the PATH).
MAGFAB = str(Path(sys.executable).with_name("magfab")) if Path(sys.executable).with_name("magfab").exists() \
    else shutil.which("magfab") or "magfab"


def plans(quick: bool) -> list[tuple[str, str, list[str]]]:
    """(name, targets text, the command's arguments after the targets file)."""
    n, fe = (30, 3) if quick else (120, 8)
    search = EXAMPLE.replace("trials = 250", f"trials = {40 if quick else 120}").replace("verify = 6", "verify = 2")
    return [
        (f"sweep --lhs {n}, example variables", EXAMPLE, ["sweep", "--lhs", str(n), "--workers", "2"]),
        (f"sweep --lhs {n}, default variables", DEFAULT, ["sweep", "--lhs", str(n), "--workers", "2"]),
        (f"sweep --models fe --lhs {fe}", EXAMPLE, ["sweep", "--models", "fe", "--lhs", str(fe), "--workers", "2"]),
        ("design, example targets, verify 2", search, ["design", "--workers", "2"]),
    ]


def estimated_s(path: Path, args: list[str]) -> float:
    """The estimate the command prints, computed as it computes it."""
    targets, base = load_targets(path)
    workers = int(args[args.index("--workers") + 1])
    if args[0] == "design":
        return search_cost(targets, base, workers).seconds
    n = int(args[args.index("--lhs") + 1])
    fidelity = args[args.index("--models") + 1] if "--models" in args else "surrogate"
    points = latin_hypercube(targets.variables, n, targets.study.seed)
    return study_cost(points, n, base, targets, fidelity, workers).seconds


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--json", type=Path)
    opts = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, (name, text, args) in enumerate(plans(opts.quick)):
            folder = Path(tmp) / str(k)
            folder.mkdir()
            (folder / "t.toml").write_text(text)
            estimate = estimated_s(folder / "t.toml", args)
            load = os.getloadavg()[0]
            t0 = time.perf_counter()
            run = subprocess.run([MAGFAB, args[0], "t.toml", *args[1:], "--out", "s"],
                                 cwd=folder, capture_output=True, text=True)
            wall = time.perf_counter() - t0
            printed = next((line for line in run.stdout.splitlines() if line.startswith("estimated ")), "")
            rows.append({"plan": name, "exit": run.returncode, "estimate_s": round(estimate, 1),
                         "wall_s": round(wall, 1), "ratio": round(wall / estimate, 2), "load": round(load, 1),
                         "printed": printed})
            print(f"{name:42s} exit {run.returncode}  measured/estimated {wall / estimate:5.2f}  "
                  f"(load {load:.1f})  {printed}", flush=True)
            if run.returncode not in (0, 3):
                print(run.stderr[-2000:], file=sys.stderr)
    if opts.json:
        opts.json.write_text(json.dumps(rows, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
