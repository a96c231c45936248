"""Verification by building (magfab.inverse.verify): a design the search offers is one `magfab build` builds; a
refused build is a failed verification with the build's one line, never on the front nor chosen; each outcome is
stored in the study, so a resumed run does not build it again."""

from __future__ import annotations

from pathlib import Path

import pytest

from magfab.check import preflight
from magfab.design import derive
from magfab.errors import InputError
from magfab.inverse import run, verify
from magfab.inverse.result import DesignResult
from magfab.inverse.space import candidate_spec
from magfab.inverse.study import Record
from magfab.inverse.targets import parse_targets
from magfab.spec import load_spec

BASE = load_spec(None)
TARGETS = parse_targets('name = "t"\nobjectives = ["normal_resolution_mN", "diameter_mm"]')
#: 5 x 2 mm N52 discs in a 12 mm and a 16 mm elastomer: the base states a 30 x 30 mm board, which the second's pad
#: leaves no room on.
SMALL = {"magnet": "d5_h2", "grade": "N52", "material": "ecoflex-00-30", "tip": "flat", "d_max_mm": 6.0,
         "d_min_mm": 2.5, "elastomer_diameter_mm": 12.0, "cover_mm": 1.9}
LARGE = {**SMALL, "elastomer_diameter_mm": 16.0}


class FakeStudy:
    def __init__(self) -> None:
        self.user_attrs: dict[str, object] = {}

    def set_user_attr(self, key: str, value: object) -> None:
        self.user_attrs[key] = value


def _record(number: int, point: dict, state: str = "ok", resolution: float = 3.0) -> Record:
    return Record(number, point, state, "", "fe", {"normal_resolution_mN": resolution, "diameter_mm":
                                                    point["elastomer_diameter_mm"]}, [-0.1, 0.0], [])


def test_a_refused_build_fails_the_verification_and_is_stored(monkeypatch, tmp_path):
    calls: list[str] = []

    def refusal(spec, out: Path) -> str | None:
        calls.append(spec.name)
        assert out == tmp_path / verify.BUILDS / spec.name
        return "pcb: something the board cannot hold" if spec.name == "t-2" else None

    monkeypatch.setattr(verify, "build_refusal", refusal)
    study = FakeStudy()
    records = [_record(1, SMALL, resolution=3.0), _record(2, SMALL, resolution=2.0),
               _record(3, SMALL, state="infeasible")]
    names = ["t-1", "t-2", "t-3"]
    out = verify.built(study, records, names, TARGETS, BASE, tmp_path)
    assert calls == ["t-1", "t-2"]  # only what meets the requirements is built, once each
    assert [r.state for r in out] == ["ok", "failed", "infeasible"]
    assert out[1].reason == verify.PREFIX + "pcb: something the board cannot hold"
    assert study.user_attrs == {"built:1": "", "built:2": "pcb: something the board cannot hold"}
    again = verify.built(study, records, names, TARGETS, BASE, tmp_path)  # resumed: the stored outcomes
    assert calls == ["t-1", "t-2"] and again == out
    result = DesignResult(TARGETS, tmp_path, out, out, records, [], None, names)
    run._front(result)
    assert result.front == [0] and result.chosen == 0  # the better design failed its build: never offered


def test_the_build_refusal_is_what_check_says(tmp_path):
    """A design the build refuses before any work: build_refusal's line is check's (preflight's) line, and nothing
    is written."""
    spec = candidate_spec(LARGE, BASE, TARGETS, "large")
    with pytest.raises(InputError) as err:
        preflight(derive(spec))
    reason = verify.build_refusal(spec, tmp_path / "large")
    assert reason == str(err.value) and "pcb.width_mm" in reason and "\n" not in reason
    assert not (tmp_path / "large").exists()
