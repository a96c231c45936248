"""What ``magfab design`` found (:class:`DesignResult`): made by :mod:`.run`, written out by :mod:`.page`."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .pareto import values_of
from .study import Record
from .targets import Targets

__all__ = ["DesignResult"]


@dataclass
class DesignResult:
    """What ``magfab design`` found: every trial, the verified designs, the front among them and the chosen one."""

    targets: Targets
    folder: Path
    trials: list[Record]
    verified: list[Record]  # the full chain's results, in verification order
    screened: list[Record]  # the same designs' cheap-model results
    front: list[int]  # indices into verified: feasible and non-dominated by the full chain
    chosen: int | None  # index into verified
    names: list[str] = field(default_factory=list)  # design names of the verified designs
    files: list[Path] = field(default_factory=list)

    def objective_values(self, recs: list[Record]) -> np.ndarray:
        return values_of(recs, [o.value for o in self.targets.objectives])
