"""The sensor in a LeRobot dataset: the readout README's block, run as written with the build's
readout package on the simulated board (a single taxel's and the strip's), makes a dataset that LeRobot's own loader
reads back value for value; and the feed's alignment (:class:`TactileFeed`), over drawn rates, frame rates, clock
skews and read delays, puts every sample in exactly one frame, the one at its time."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

FORCE, WINDOW, COUNT = "observation.tactile.force", "observation.tactile.window", "observation.tactile.count"
TESTS = Path(__file__).resolve().parents[1]

#: Run before the README's block: LeRobot's loader as the tests import it, and a record of every frame the feed
#: gives (the block itself is run exactly as the page has it).
PRELUDE = """
import atexit, sys
sys.path[:0] = [{tests!r}, {src!r}]
import lerobot_loader
lerobot_loader.install()
import numpy as np
from magfab_readout import lerobot as feed_module
given = []
frame = feed_module.TactileFeed.frame
def recorded(self, at=None):
    out = frame(self, at)
    given.append(out)
    return out
feed_module.TactileFeed.frame = recorded
atexit.register(lambda: np.savez("given.npz", **{{k: np.stack([g[k] for g in given]) for k in given[0]}}))
exec(compile(open("block.py").read(), "README.md", "exec"), {{"__name__": "__main__"}})
"""


def _block(readme: str) -> str:
    blocks = re.findall(r"^```python\n(.*?)^```$", readme, flags=re.S | re.M)
    return next(b for b in blocks if "LeRobotDataset" in b)


@pytest.mark.parametrize("which", ["single", "strip_1x5"])
def test_the_readme_block_makes_a_dataset_lerobot_reads(default_build, array_builds, tmp_path, which):
    from lerobot_loader import dataset_class

    build = default_build if which == "single" else array_builds[which]
    taxels = 1 if which == "single" else 5
    (tmp_path / "block.py").write_text(_block((build.out_dir / "readout" / "README.md").read_text()))
    prelude = PRELUDE.format(tests=str(TESTS), src=str(build.out_dir / "readout" / "src"))
    run = subprocess.run([sys.executable, "-c", prelude], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                         env={"HF_HUB_OFFLINE": "1", "PATH": "/usr/bin:/bin", "HOME": str(tmp_path)})
    assert run.returncode == 0, run.stderr[-3000:]
    given = np.load(tmp_path / "given.npz")
    dataset = dataset_class()("lab/press", root=tmp_path / "press_dataset")
    assert len(dataset) == len(given[FORCE]) == 60
    assert dataset.meta.fps == 30 and dataset.meta.features[WINDOW]["shape"] == given[WINDOW].shape[1:]
    assert given[WINDOW].shape[2] == given[FORCE].shape[1] == 3 * taxels
    for i in range(len(dataset)):
        item = dataset[i]
        # every value LeRobot's loader reads is the one the feed gave, NaN where it gave NaN
        for key in (FORCE, WINDOW, COUNT):
            np.testing.assert_array_equal(item[key].numpy(), given[key][i])
        n = int(given[COUNT][i][0])
        if n:  # the force is the window's newest sample; the rows before the samples are NaN
            np.testing.assert_array_equal(given[FORCE][i], given[WINDOW][i][-1])
            assert np.isnan(given[WINDOW][i][:-n]).all() and not np.isnan(given[WINDOW][i][-n:]).all()
    counts = given[COUNT][1:, 0]  # the first frame holds what came while the dataset was made
    window = given[WINDOW].shape[1]
    assert np.median(counts) >= 0.5 * (window - 4)  # the chip's rate (or the array's cycles) kept between frames
    assert "tensor(" in run.stdout  # the block's last line: a frame's force read back


@pytest.fixture(scope="module")
def feed_class(default_build):
    """The default build's readout package's TactileFeed, imported in this process."""
    from readout_support import imported

    with imported({}, default_build.out_dir):
        from magfab_readout import lerobot

        assert (lerobot.FORCE, lerobot.WINDOW, lerobot.COUNT) == (FORCE, WINDOW, COUNT)
        yield lerobot.TactileFeed


@settings(max_examples=60, deadline=None)
@given(rate=st.floats(100, 1000), fps=st.floats(10, 60), skew=st.floats(-0.005, 0.005),
       batch=st.integers(1, 30), jitter_ms=st.floats(0, 20), seed=st.integers(0, 2**16))
def test_every_sample_lands_in_one_frame_at_its_time(feed_class, rate, fps, skew, batch, jitter_ms, seed):
    """Samples on a device clock that runs ``skew`` off the host's, read in batches of ``batch`` late by up to
    ``jitter_ms`` (a serial link's buffering), frames asked at ``fps``: each sample is in exactly one frame's window,
    in order, and in the first frame asked after it was made (to the clock map's error, under 2 ms here; the map
    is the lower hull under the reads, so a sample is never placed before it was made by more than that)."""
    rng = np.random.default_rng(seed)
    feed = feed_class(None, fps, rate)
    duration = 3.0
    made = np.arange(0.0, duration, 1.0 / rate)  # host time each sample was made (the truth)
    device_t = 5.0 + made * (1.0 + skew)  # what the board's clock says
    reads: list = []  # (host read time, index): a batch read when its last sample is made, plus a delay; in order
    for start in range(0, len(made), batch):
        end = min(start + batch, len(made))
        delay = rng.uniform(0, jitter_ms / 1e3) if rng.random() > 0.1 else 0.0  # some reads are prompt
        read = max(made[end - 1] + delay, reads[-1][0] if reads else 0.0)  # a link delivers in order
        reads += [(read, k) for k in range(start, end)]
    frames_at = np.arange(0.2, duration, 1.0 / fps)
    base = 1.7e9
    got, r = [], 0
    for at in frames_at:
        while r < len(reads) and reads[r][0] <= at:
            k = reads[r][1]
            feed.add(device_t[k], base + reads[r][0], (float(k), 0.0, -float(k)))
            r += 1
        f = feed.frame(base + at)
        n, dropped = (int(c) for c in f[COUNT])
        assert n <= feed.window and (dropped == 0 or n == feed.window)
        rows = f[WINDOW][feed.window - n:]
        assert not np.isnan(rows).any() and np.isnan(f[WINDOW][:feed.window - n]).all()
        got.append([int(v) for v in rows[:, 0]])
        if n:
            assert f[FORCE][0] == rows[-1, 0]
    seen = [k for frame in got for k in frame]
    overflow = any(len(g) == feed.window for g in got)
    if not overflow:
        assert seen == list(range(len(seen)))  # each once, in order, none skipped
    else:
        assert seen == sorted(set(seen))
    for j, frame in enumerate(got):
        for k in frame:
            assert made[k] <= frames_at[j] + 0.002  # not before it was made (to the map's error)
            if j > 0 and not (overflow and len(frame) == feed.window):
                # not later than the first frame after it was read
                read = next(t for t, i in reads if i == k)
                assert frames_at[j - 1] < read + 0.002 or math.isclose(frames_at[j - 1], read)


def test_a_bad_frame_rate_is_refused(feed_class):
    for fps in (0.0, -30.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="fps must be a positive number"):
            feed_class(None, fps, 543.0)
