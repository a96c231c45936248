"""bench/adversarial.py's classifier, on fake children: a traceback counts as a traceback whatever the exit code, a
refusal that writes a file or says two lines is not clean, exit 0 where a refusal belongs is accepted bad, a file
the case must keep that changes is lost, a child past its time or memory is over budget. So the runner cannot pass
everything by accident."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

import adversarial as adv  # (bench/, put on sys.path above)


@pytest.fixture
def runner(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    e = adv.Env(work=tmp_path, quick=True, seed=0, golden=tmp_path, replay=tmp_path, golden_tree={}, steps=[],
                in_place=[], magfab_env=env, readout_env=env, decode_env=env, harness=None)
    return adv.Runner(e, keep_failures=None)


def fake(runner, code: str, expect: str = "refuse", **kw) -> adv.Outcome:
    """A child running ``code`` judged as a case expecting ``expect``."""
    case = adv.Case(8, "fake", "python", [], code=code, expect=expect, **kw)
    return runner.run(case, len(runner.outcomes) + 1, 0)


ONE_LINE = "import sys; sys.stderr.write('x: error: no such file\\n'); sys.exit(2)"


def test_a_clean_refusal_is_refused(runner):
    out = fake(runner, ONE_LINE, words=("no such",))
    assert out.label == "refused" and not out.lost


def test_a_traceback_is_a_traceback_even_with_exit_2(runner):
    code = ("import sys; sys.stderr.write('Traceback (most recent call last):\\n  File \"x\", line 1\\nValueError: "
            "boom\\n'); sys.exit(2)")
    assert fake(runner, code).label == "traceback"
    assert fake(runner, "raise ValueError('boom')").label == "traceback"  # Python's own, exit 1
    assert fake(runner, "import sys; sys.stderr.write('internal error\\n'); sys.exit(1)").label == "traceback"


def test_a_refusal_that_writes_or_says_two_lines_is_not_clean(runner):
    wrote = fake(runner, "open('out.txt', 'w').write('x'); " + ONE_LINE)
    assert wrote.label == "unclean" and "+out.txt" in wrote.why
    made = fake(runner, "import os; os.mkdir('out'); " + ONE_LINE)
    assert made.label == "unclean"
    two = fake(runner, "import sys; sys.stderr.write('error: one\\nand two\\n'); sys.exit(2)")
    assert two.label == "unclean"


def test_progress_lines_before_a_refusal_or_an_interrupt_are_set_apart(runner):
    """magfab writes a build's stages done (and a study's progress) on stderr when it is not a terminal: those lines
    before the one that says what went wrong keep a refusal (or a stop) clean; any other line does not."""
    progress = ("magfab: deriving the design: done in 0.1 s\\nmagfab: modelling pad: done in 1 min 02 s\\n"
                "magfab: search 30/300 (10 %) in 10.6 s, about 1 min 36 s left\\n")
    said = f"import sys; sys.stderr.write('{progress}x: error: no such file\\n'); sys.exit(2)"
    assert fake(runner, said, words=("no such",)).label == "refused"
    stop = f"import sys; sys.stderr.write('{progress}x: error: interrupted\\n'); sys.exit(130)"
    assert fake(runner, stop, expect="stop").label == "stopped"
    other = "import sys; sys.stderr.write('magfab: deriving the design\\nx: error: no such file\\n'); sys.exit(2)"
    assert fake(runner, other).label == "unclean"


def test_the_parsers_usage_block_is_a_refusal_reported_apart(runner):
    code = ("import sys; sys.stderr.write('Usage: magfab check [OPTIONS]\\nTry \\'magfab check -h\\' for help.\\n\\n"
            "Error: No such option: --bogus\\n'); sys.exit(2)")
    out = fake(runner, code)
    assert out.label == "refused" and out.usage_block


def test_exit_0_where_a_refusal_belongs_is_accepted_bad(runner):
    assert fake(runner, "print('done')").label == "accepted bad"
    assert fake(runner, "print('done')", expect="either").label == "ok"
    assert fake(runner, ONE_LINE, expect="ok").label == "wrongly refused"


def test_a_refusal_for_another_reason(runner):
    assert fake(runner, ONE_LINE, words=("deep",)).label == "other reason"


def test_a_file_the_case_must_keep_that_changes_is_lost(runner):
    keep = adv.writes({"mine/notes.txt": "precious"})
    out = fake(runner, "open('mine/notes.txt', 'w').write('gone'); print('ok')", expect="ok", setup=keep,
               keep=("mine",))
    assert out.label == "ok" and out.lost
    out = fake(runner, "import shutil; shutil.rmtree('mine'); print('ok')", expect="ok", setup=keep, keep=("mine",))
    assert out.lost
    assert not fake(runner, "print('ok')", expect="ok", setup=keep, keep=("mine",)).lost


def test_past_the_time_or_the_memory_is_over_budget(runner):
    assert fake(runner, "import time; time.sleep(30)", timeout_s=1.0).label == "over budget"
    out = fake(runner, "x = bytearray(8 * 1024**3)")  # past the child's address space: MemoryError
    assert out.label == "over budget" and "memory" in out.why


def test_an_interrupt_must_end_in_one_line_or_the_signal(runner):
    stop = "import sys; sys.stderr.write('x: error: interrupted\\n'); sys.exit(130)"
    assert fake(runner, stop, expect="stop").label == "stopped"
    assert fake(runner, stop).label == "unclean"  # 130 without an interrupt
    assert fake(runner, "import os, signal; os.kill(os.getpid(), signal.SIGKILL)", expect="stop").label == "stopped"
    assert fake(runner, "import os, signal; os.kill(os.getpid(), signal.SIGSEGV)").label == "traceback"


def test_the_table_counts_every_label(runner):
    fake(runner, ONE_LINE)
    fake(runner, "raise SystemExit(1)")
    rows = adv.summary(runner.outcomes)
    assert rows[0]["tried"] == 2 and rows[0]["refused"] == 1 and rows[0]["traceback"] == 1
    assert "8 exit codes" in adv.table(rows)
