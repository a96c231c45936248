"""What each pipeline stage hands on, by name: its files and findings, and the values later stages read.

Frozen dataclasses rather than tuples, so a reader (or a type checker) can follow ``stage.board`` from the stage
that made it to the ones that use it. The physics branch's results are pickled back from its worker process.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from .errors import Finding
from .output import Artifact

if TYPE_CHECKING:
    import trimesh

    from .formats.scan_csv import Scan
    from .models.calibration import FitResult
    from .models.predict import Prediction
    from .pcb import Board

__all__ = ["Stage", "BoardStage", "CadStage", "PredictionStage", "AcceptanceStage", "ScanStage", "CrosstalkStage",
           "ArrayStage", "BundleStage"]


@dataclass(frozen=True, kw_only=True)
class Stage:
    """What a stage hands on: its files and its findings (the build stops on an error among them)."""

    artifacts: list[Artifact] = field(default_factory=list)
    findings: list[Finding] = field(default_factory=list)


@dataclass(frozen=True, kw_only=True)
class BoardStage(Stage):
    board: Board | None  # the routed board, which the report draws rather than routing again (None: not routed yet)
    timings_s: dict[str, float] = field(default_factory=dict)  # routing and plotting, s (it may run in a worker)


@dataclass(frozen=True, kw_only=True)
class CadStage(BoardStage):
    meshes: dict[str, trimesh.Trimesh]  # by part stem


@dataclass(frozen=True, kw_only=True)
class PredictionStage(Stage):
    prediction: Prediction


@dataclass(frozen=True, kw_only=True)
class AcceptanceStage(Stage):
    bands: dict[str, Any] | None  # calibration/acceptance.json, or None where no test fits the design


@dataclass(frozen=True, kw_only=True)
class ScanStage(Stage):
    scan: Scan  # what the single taxel's calibration is fitted to


@dataclass(frozen=True, kw_only=True)
class CrosstalkStage(Stage):
    dynamic: bool  # whether the host removes a moving neighbour's field


@dataclass(frozen=True, kw_only=True)
class ArrayStage(Stage):
    fits: tuple[FitResult, ...]  # per taxel
    doc: dict[str, Any]  # calibration/array.json


@dataclass(frozen=True, kw_only=True)
class BundleStage(Stage):
    fit: FitResult  # the single taxel's calibration (an array's taxel 0)
