"""What each pipeline stage hands on, by name: its files and findings, and the values later stages read; and what
the whole build hands back (:class:`BuildResult`).

Frozen dataclasses rather than tuples, so a reader (or a type checker) can follow ``stage.board`` from the stage
that made it to the ones that use it. The physics branch's results are pickled back from its worker process.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

from .errors import Finding
from .output import Artifact

if TYPE_CHECKING:
    import trimesh

    from .design import Design
    from .formats.scan_csv import Scan
    from .models.calibration import FitResult
    from .models.predict import Prediction
    from .pcb import Board
    from .spec import Spec

__all__ = ["Stage", "BoardStage", "SolidsStage", "CadStage", "PredictionStage", "AcceptanceStage", "ScanStage",
           "CrosstalkStage", "ArrayStage", "BundleStage", "BuildResult"]


@dataclass(frozen=True, kw_only=True)
class Stage:
    """What a stage hands on: its files and its findings (the build stops on an error among them)."""

    artifacts: list[Artifact] = field(default_factory=list)
    findings: list[Finding] = field(default_factory=list)


@dataclass(frozen=True, kw_only=True)
class BoardStage(Stage):
    board: Board  # the routed board, which the report draws rather than routing again
    timings_s: dict[str, float] = field(default_factory=dict)  # routing and plotting, s (it may run in a worker)


@dataclass(frozen=True, kw_only=True)
class SolidsStage(Stage):
    meshes: dict[str, trimesh.Trimesh]  # by part stem


@dataclass(frozen=True, kw_only=True)
class CadStage(BoardStage):
    """The CAD branch whole: the solids and the board."""

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
    weighing: dict[str, Any] | None = None  # the weight plan (calibration/weigh_plan.json), which the papers list too


@dataclass
class BuildResult:
    spec: Spec
    design: Design
    artifacts: list[Artifact]
    findings: list[Finding]
    timings_s: dict[str, float] = field(default_factory=dict)
    out_dir: Path | None = None
    prediction: Prediction | None = None
    calibration: dict[str, object] | None = None  # what the CLI summary says of the bundle

    def summary(self) -> dict[str, object]:
        """What ``magfab build --json`` prints."""
        d = self.design
        return {
            "spec": self.spec.name,
            "out_dir": str(self.out_dir) if self.out_dir else None,
            "artifacts": [a.path for a in self.artifacts],
            "figures": {
                "d_rest_mm": round(d.d_rest_mm, 4),
                "cover_mm": round(d.cover_mm, 4),
                "skin_mm": round(d.skin_mm, 4),
                "cavity_volume_mL": round(d.elastomer_volume_mm3 / 1000.0, 4),
                "silicone_per_part_g": round(d.elastomer_volume_mm3 / 1000.0 * d.material.density_g_cm3.nominal, 3),
                "cavities": d.cavities,
                **self._array_summary(),
            },
            "predictions": self._prediction_summary(),
            "calibration": self.calibration,
            "findings": [f.as_dict() for f in self.findings],
            "timings_s": {k: round(v, 3) for k, v in self.timings_s.items()},
        }

    def _array_summary(self) -> dict[str, object]:
        """An array's taxels (none for a single taxel, whose summary is what it was)."""
        arr = self.design.array
        if arr is None:
            return {}
        return {"taxels": len(arr.taxels), "pitch_mm": round(arr.pitch_mm, 4), "skin": arr.skin.value,
                "polarity": arr.polarity.value, "addresses": [f"0x{t.i2c_address:02X}" for t in arr.taxels],
                "option_codes": list(arr.option_codes)}

    def _prediction_summary(self) -> dict[str, object] | None:
        p = self.prediction
        if p is None:
            return None
        n, s = p.normal, p.shear
        return {
            "Bz_rest_G": round(p.field.Bz_rest_G, 1),
            "dBz_dz_rest_G_per_mm": round(p.field.dBz_dz_rest_G_per_mm, 1),
            # significant digits, not decimals: a soft or a stiff design's figures never print as 0
            "normal_sensitivity_G_per_N": [_sig(x) for x in n.sensitivity_G_per_N],
            "normal_resolution_mN": _sig(n.resolution_mN),
            "normal_range_N": round(n.range_N, 3),
            "normal_range_limit": n.range_limit,
            "normal_range_text": n.range_text(),
            "shear_sensitivity_G_per_N": [_sig(x) for x in s.sensitivity_G_per_N],
            "shear_resolution_mN": _sig(s.resolution_mN),
            "shear_range_N": round(s.range_N, 3),
            "noise_G": round(p.noise.total_z_G, 3),
            "models": {m.family: m.name for m in p.models},
        }


def _sig(x: float, digits: int = 4) -> float:
    """``x`` to ``digits`` significant digits (the summary's figures: 0.000123 stays 0.000123, 1234.5 is 1235)."""
    return float(f"{x:.{digits}g}")
