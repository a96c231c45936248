"""What ``magfab design`` found (:class:`DesignResult`): made by :mod:`.run`, written out by :mod:`.page`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..models.predict import MODEL_REACH
from .evaluate import REQUIREMENTS, margin_of, requirement_names, shortfall, slack_of
from .pareto import values_of
from .study import Record
from .targets import Targets

__all__ = ["DesignResult", "Margin", "margins", "nearest", "closest"]


@dataclass(frozen=True)
class Margin:
    """One requirement for one design: how far it is met (``slack``, relative: > 0 met by that much) against the
    margin it must be met by (relative); ``met`` when slack >= margin."""

    name: str
    value: float  # the design's figure
    need: float  # the requirement
    slack: float
    margin: float
    at_least: bool = False  # the figure is a model's reach (a range the material data or the FE ended): a lower bound

    @property
    def shown(self) -> str:
        """The figure as a person reads it: "1.021", or "at least 1.021" for a model's reach."""
        return f"{'at least ' * self.at_least}{self.value:.4g}"

    @property
    def met(self) -> bool:
        return self.slack >= self.margin

    @property
    def short(self) -> float:
        """How far short of its margin (<= 0: met)."""
        return self.margin - self.slack


def margins(targets: Targets, r: Record) -> list[Margin]:
    """Each requirement of ``targets`` for the design ``r`` (a record with figures)."""
    m = r.metrics
    reach = m.get("range_limit") in MODEL_REACH
    return [Margin(n, float(m.get(REQUIREMENTS[n][0], math.nan)), float(getattr(targets.require, n)),
                   slack_of(targets, n, m), margin_of(targets, n, m), reach and n == "normal_range_N")
            for n in requirement_names(targets)]


def nearest(targets: Targets, recs: list[Record]) -> list[int]:
    """Indices of the records with figures, nearest to meeting the targets first: those with every figure a
    requirement needs, then those without error findings, then by the largest shortfall of a requirement from its
    margin."""
    def key(i: int) -> tuple[bool, bool, float, int]:
        worst = max([m.short for m in margins(targets, recs[i])] or [-math.inf])
        return (not worst < math.inf, bool(recs[i].errors), worst, i)

    return sorted((i for i, r in enumerate(recs) if r.metrics), key=key)


def closest(targets: Targets, recs: list[Record], names: list[str] | None = None) -> str:
    """One line: the design among ``recs`` nearest to meeting the targets (one without error findings if there is
    one: the smallest largest shortfall of a requirement from its margin), and that requirement (or, when it meets
    every requirement, the error findings it has)."""
    order = nearest(targets, recs)
    if not order:
        return "no design could be evaluated (trials.csv gives each reason)"
    i = order[0]
    r, name = recs[i], (names[i] if names else f"trial-{recs[i].number}")
    ms = margins(targets, r)
    short = [m for m in ms if not m.met]
    if short:
        m = max(short, key=lambda m: m.short)
        return f"closest: {name} ({r.model}), {shortfall(targets, m.name, r.metrics)}"
    return f"closest: {name} ({r.model}) meets every requirement with margin, but: " + "; ".join(r.errors[:2])


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

    def closest(self) -> str:
        """The line saying which design came nearest and by how much (:func:`closest`): among the verified designs,
        or the search's when none was verified."""
        if any(r.metrics for r in self.verified):
            return closest(self.targets, self.verified, self.names)
        return closest(self.targets, self.trials)
