"""Over random histories (calibrations of any taxel, checks, re-skins, uploads, notes, in any order and number), what
``magfab sensor show --json`` and ``magfab sensor list --json`` say agrees with the events as written: one row per
event in order, the skin each belongs to, the counts, the newest calibration and the last verdict."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sensor_support import calibration, check

from magfab.cli import main
from magfab.formats import sensor_records as rec

#: acceptance.json's bands (the parts the comparison reads): the calibrations of sensor_support lie within them.
BANDS = json.dumps({"rest": {"Bz_uT": {"min": 17000.0, "nominal": 18700.0, "max": 21000.0}, "Bxy_max_uT": 3000.0},
                    "weight": {"force_N": 0.49, "delta_Bz_uT": {"min": 1200.0, "nominal": 2900.0,
                                                                 "max": 6400.0}}}).encode()

STEP = st.one_of(
    st.tuples(st.just("calibration"), st.sampled_from([None, 0, 1]), st.floats(1.0, 20.0)),
    st.tuples(st.just("check"), st.sampled_from(["pass", "fail"]), st.floats(0.0, 50.0)),
    st.tuples(st.just("reskin"), st.text(max_size=8), st.just(0.0)),
    st.tuples(st.just("upload"), st.none(), st.just(0.0)),
    st.tuples(st.just("note"), st.text(max_size=8), st.just(0.0)),
)


def _write(s: rec.Sensor, steps: list) -> None:
    for n, (kind, arg, x) in enumerate(steps):
        date = f"2026-{1 + n // 28:02d}-{1 + n % 28:02d}T08:00:00Z"
        if kind == "calibration":
            data, files = calibration(arg, fz=x, n=n)
            s.append(kind, data, files, date=date)
        elif kind == "check":
            s.append(kind, check(arg, error=x), date=date)
        elif kind == "reskin":
            s.append(kind, {"note": arg}, date=date)
        elif kind == "upload":
            s.append(kind, {"calibration_sha256": "c" * 64, "taxel": None}, date=date)
        else:
            s.append(kind, {"text": arg}, date=date)


def _cli(root: Path, *args: str) -> object:
    result = CliRunner().invoke(main, ["sensor", *args, "--sensors", str(root), "--json"])
    assert result.exit_code == 0, result.output
    return json.loads(result.output)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(steps=st.lists(STEP, max_size=14))
def test_show_and_list_agree_with_the_events(steps: list) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp) / "sensors"
        s = rec.create(root, "S", {"spec_name": "magone"}, {"acceptance.json": BANDS}, date="2025-12-31T00:00:00Z")
        _write(s, steps)
        shown = _cli(root, "show", "S")
        assert [e["kind"] for e in shown["events"]] == ["added"] + [k for k, _, _ in steps]
        assert [e["number"] for e in shown["events"]] == list(range(1, len(steps) + 2))
        epochs = [0]
        for kind, _, _ in steps:
            epochs.append(epochs[-1] + (kind == "reskin"))
        assert [e["epoch"] for e in shown["events"]] == epochs
        calibrations = [(n, arg, x) for n, (k, arg, x) in enumerate(steps) if k == "calibration"]
        checks = [arg for k, arg, _ in steps if k == "check"]
        (listed,) = _cli(root, "list")
        assert listed == shown["sensor"]
        assert listed["epoch"] == epochs[-1] and listed["calibrations"] == len(calibrations)
        assert listed["checks"] == len(checks) and listed["last_check"] == (checks[-1] if checks else None)
        if calibrations:
            assert listed["last_rms_holdout_Fz_mN"] == calibrations[-1][2]
        for taxel in (None, 0, 1):  # the newest calibration of the skin in use, taxel by taxel
            mine = [c for c in calibrations if c[1] == taxel and epochs[c[0] + 1] == epochs[-1]]
            if mine:
                assert s.current_calibration(taxel)[0]["number"] == mine[-1][0] + 2
        # the re-skin comparison: each taxel calibrated on both the skin in use and the one before it, every quantity
        both = {c[1] for c in calibrations if epochs[c[0] + 1] == epochs[-1]} & {
            c[1] for c in calibrations if epochs[c[0] + 1] == epochs[-1] - 1}
        order = lambda t: -1 if t is None else t  # a single taxel's (None) sorts first
        assert sorted((c["taxel"] for c in shown["reskin"]), key=order) == sorted(
            [t for t in both for _ in range(6)], key=order)
        assert not any(c["flagged"] for c in shown["reskin"])  # the same sensor, within its bands
