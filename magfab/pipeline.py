"""The pipeline: Spec -> Design -> solids -> meshes -> checks -> artifacts, written atomically.

:func:`plan` is pure (returns artifacts as bytes); :func:`write` is the only code that touches the
output directory. It writes into a temporary folder beside the target and renames it into place only
when everything succeeded, so an error or an interrupt never leaves half an output and never clobbers
the previous good one.
"""

from __future__ import annotations

import hashlib
import json
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

from . import __version__, pcb
from .array_bench import measured_scan_path
from .check import (
    crosstalk_findings,
    design_findings,
    errors_in,
    fabrication_findings,
    mesh_findings,
    mould_fit_findings,
    predict_with_findings,
    preflight,
)
from .design import Design, derive
from .elastomer import elastomer_solid
from .errors import BuildError, Finding, ModelLimitError, OutputError, ScanError, Severity
from .export import (
    bom,
    calibration_chart,
    checklist,
    crosstalk_figures,
    drift_figures,
    figures,
    firmware,
    kicad,
    readout,
    weights_figures,
)
from .export import cad as cad_files
from .export.report import draw_pictures, part_figure, render_report
from .export.weigh_plan import weigh_plan
from .fit import mould_fit
from .fork import deferred_interrupt, parallel_available, side_branch
from .formats.scan_csv import scan_csv
from .jig import ANGLES_DEG as JIG_ANGLES_DEG
from .jig import cap_solid, stand_solid
from .limits import check_scan
from .models import calibration as calibrate
from .models import crosstalk
from .models.acceptance import acceptance
from .models.scan import scan_plan, simulate_scan
from .models.scan_guards import MERGED, merged_csv, scan_depth_warnings
from .models.taxels import array_field, calibrate_taxels, compensated, simulate_taxel_scan
from .models.weighing import stated_error
from .mould import cup_solid, lid_solid
from .output import Artifact, check_target, write
from .pad import pad_solid
from .spec import Spec
from .stages import (
    AcceptanceStage,
    ArrayStage,
    BoardStage,
    BuildResult,
    BundleStage,
    CadStage,
    CrosstalkStage,
    PredictionStage,
    ScanStage,
    SolidsStage,
    Stage,
)

if TYPE_CHECKING:
    import cadquery as cq
    import trimesh

    from .formats.scan_csv import Scan
    from .models.calibration import FitResult
    from .models.predict import Prediction

# CadQuery and trimesh are imported lazily, in the CAD branch, for speed: importing the pipeline stays cheap, and the
# kernel's load is timed on its own (with Ctrl-C deferred while VTK initialises).


__all__ = ["Artifact", "BuildResult", "OutputError", "plan", "write", "build", "check_target", "PARTS", "Part",
           "parts_of", "Stage", "default_out_dir", "acceptance_stage", "bundle_stage"]


@dataclass(frozen=True)
class Part:
    """A solid the build makes: ``make`` is its builder (the part modules import the CAD kernel inside it, so
    holding it here costs nothing until a build calls it)."""

    stem: str  # file stem of its STL and STEP
    make: Callable[[Design], cq.Workplane]
    printed: bool
    description: str
    single: bool = False  # made for a single taxel only (the weight jig: an array is calibrated from a scan)


PARTS = (
    Part("elastomer", elastomer_solid, False, "the cast silicone part, with its magnet pocket (reference)"),
    Part("mould_cup", cup_solid, True, "mould cup with the cavities, print pose"),
    Part("mould_lid", lid_solid, True, "mould lid with the pocket cores, fill and vent holes, print pose"),
    Part("pad", pad_solid, True, "mounting pad: chip recess below, centring lip above, print pose"),
    Part("weigh_cap", cap_solid, True, "weight jig's cap: a flat face on the tip, coin pockets beside it, print pose",
         single=True),
    *(Part(f"weigh_stand_{a:g}", partial(stand_solid, angle_deg=a), True,
           f"weight jig's stand at {a:g} degrees: the board's pocket, open uphill for its cable, print pose",
           single=True)
      for a in JIG_ANGLES_DEG),
)

Progress = Callable[[str], None]


def parts_of(design: Design) -> tuple[Part, ...]:
    """The solids a build of ``design`` makes (the weight jig for a single taxel only)."""
    return tuple(p for p in PARTS if not (p.single and design.array is not None))


def _json_bytes(obj: object) -> bytes:
    return (json.dumps(obj, indent=2, sort_keys=True) + "\n").encode()


def _board(design: Design, say: Progress = lambda _stage: None) -> BoardStage:
    """The footprint library, the routed breakout board and, where KiCad is installed, its Gerbers."""
    say("placing and routing the board")
    timings: dict[str, float] = {}
    t = time.perf_counter()
    board = pcb.board(design)
    found = pcb.findings(board)
    files = pcb.files(board)
    timings["pcb"] = time.perf_counter() - t
    what = {".kicad_mod": "footprint (KiCad 6 library)", ".kicad_pcb": "breakout board (KiCad 6)",
            ".kicad_pro": "KiCad project: the design rules the board was routed to",
            "fp-lib-table": "KiCad library table for the footprints"}
    out = [Artifact(f"pcb/{rel}", data, next(v for k, v in what.items() if rel.endswith(k)))
           for rel, data in sorted(files.items())]
    if errors_in(found, strict=False):
        return BoardStage(artifacts=out, findings=found, board=board, timings_s=timings)
    if kicad.kicad_python() is None:
        found.append(Finding(Severity.INFO, "pcb-gerbers-skipped",
                             "KiCad (Debian package 'kicad') is not installed, so no Gerbers were plotted: open "
                             f"pcb/{design.spec.name}.kicad_pcb in KiCad and plot them, or install KiCad and rebuild",
                             "pcb"))
        return BoardStage(artifacts=out, findings=found, board=board, timings_s=timings)
    say("plotting Gerbers with KiCad")
    t = time.perf_counter()
    for name, data in sorted(kicad.plot_gerbers(files, design.spec.name).items()):
        kind = "drill file (Excellon)" if name.endswith(".drl") else "Gerber (plotted by KiCad)"
        out.append(Artifact(f"pcb/gerbers/{name}", data, kind))
    timings["gerbers"] = time.perf_counter() - t
    return BoardStage(artifacts=out, findings=found, board=board, timings_s=timings)


def _predictions(design: Design, say: Progress, timings: dict[str, float]) -> PredictionStage:
    """predictions.json and the prediction's design checks (docs/models.md, M9, M18); its plots are :func:`_plots`'."""
    say("predicting sensitivity, resolution and range")
    t = time.perf_counter()
    pred, found = predict_with_findings(design)
    timings["predict"] = time.perf_counter() - t
    if pred is None:
        raise BuildError(found)
    c = design.spec.calibration  # not fitted yet: what the spec asks for ('auto' may fit either method)
    measured = firmware.measured_rate_for(design, {"method": c.method.value, "order": c.order})
    out = [Artifact("predictions.json", _json_bytes({**pred.as_json(), **({} if measured is None else {
        "readout_measured": measured})}), "predicted field, force curve, sensitivity, resolution, range and noise, "
                    "with the models used; the readout's rate as the shipped image measured it")]
    return PredictionStage(artifacts=out, findings=found, prediction=pred)


def _charts(folder: str, drawn: dict[str, bytes], captions: dict[str, str]) -> list[Artifact]:
    """Drawn chart files ({name: bytes}) as artifacts in ``folder``, each described by its caption and format."""
    out = []
    for name, data in sorted(drawn.items()):
        stem, kind = name.rsplit(".", 1)
        out.append(Artifact(f"{folder}{name}", data, captions[stem] + ", " + kind.upper()))
    return out


def _plots(drawn: dict[str, bytes], pred: Prediction) -> list[Artifact]:
    """The prediction's plots (``drawn``: :func:`magfab.export.figures.figures`' files) and the drift chart."""
    return _charts("plots/", drawn, figures.CAPTIONS) + _drift_charts(pred)


def _drift_charts(pred: Prediction) -> list[Artifact]:
    """The drift budget's chart (predictions.json's ``drift``), when the prediction has one."""
    if pred.drift is None:
        return []
    return _charts(drift_figures.FOLDER, drift_figures.figures(pred.drift), drift_figures.CAPTIONS)


def acceptance_stage(design: Design, prediction: Prediction) -> AcceptanceStage:
    """The acceptance test's bands (magfab.models.acceptance), for the readout package and the checklist."""
    try:
        return AcceptanceStage(bands=acceptance(design, prediction))
    except ModelLimitError as exc:  # e.g. no weight fits the predicted range: the bundle ships without the check
        return AcceptanceStage(bands=None, findings=[Finding(Severity.WARNING, "acceptance", "the readout package "
                               f"has no acceptance test for this design: {exc}", "predict.material_law")])


def _calibration_finding(result: FitResult, prefix: str, source: str = "") -> Finding:
    """The calibration's held-out errors, a warning when they miss the tolerance."""
    err: Any = result.calibration.to_json()["errors"]
    return Finding(Severity.INFO if result.meets_tolerance else Severity.WARNING, "calibration",
                   f"{prefix}{source}{result.chosen}, held-out RMS Fz {1000 * err['Fz_N']['rms_holdout']:.2f} mN, "
                   f"Fr {1000 * err['Fr_N']['rms_holdout']:.2f} mN ({err['folds']}-fold)"
                   + ("" if result.meets_tolerance else f"; {result.message}")
                   + (f"; {result.thermal_note}" if result.thermal_note else ""), "calibration.tolerance_mN")


def _scan(design: Design, prediction: Prediction | None, scan: Scan | None, say: Progress) -> ScanStage:
    """The scan a single taxel's calibration is fitted to: ``scan`` (with the depth warnings, and the merged file kept
    when it was merged in memory) or a simulated one. The simulated scan is shipped either way (it is deterministic,
    and a measured calibration may have been fitted to it: ``magfab calibrate calibration/scan_simulated.csv``
    must not remove its own input)."""
    say("simulating a calibration scan")
    simulated = simulate_scan(design, prediction)
    made = Artifact("calibration/scan_simulated.csv", scan_csv(simulated).encode(),
                    "the simulated y-z scan behind the provisional calibration (scan CSV format)")
    if scan is None:
        return ScanStage(artifacts=[made], scan=simulated)
    out = [made]
    if MERGED in scan.source:  # made in memory from a recording and a reference log: keep what was fitted
        out.append(Artifact("calibration/scan_merged.csv", merged_csv(scan),
                            "the recording merged with the reference log, as fitted (scan CSV format)"))
    found = [] if prediction is None else [Finding(Severity.WARNING, "scan-range", text, "calibration.scan_z_mm")
                                           for text in scan_depth_warnings(scan, prediction)]
    return ScanStage(artifacts=out, findings=found, scan=scan)


def bundle_stage(design: Design, prediction: Prediction | None, scan: Scan | dict[int, Scan] | None,
                 acceptance: dict[str, Any] | None, say: Progress, timings: dict[str, float]) -> BundleStage:
    """The firmware-plus-calibration bundle: calibration.json (from ``scan``, or a simulated scan when there
    is none yet), its chart, the firmware sources, the generic AVR image with the .eep of its settings and
    calibration, the flash scripts and the readout package."""
    out: list[Artifact] = []
    found: list[Finding] = []
    t = time.perf_counter()
    mls = calibrate.fits_mls(design)
    array_doc = None
    if design.array is not None:
        say("fitting every taxel's calibration")
        assert prediction is not None, "an array's calibration needs the prediction (its neighbours' field)"
        arrayed = _taxel_calibrations(design, prediction, cast("dict[int, Scan] | None", scan), mls)
        out += arrayed.artifacts
        found += arrayed.findings
        result, array_doc = arrayed.fits[0], arrayed.doc
    else:
        scanned = _scan(design, prediction, cast("Scan | None", scan), say)
        out += scanned.artifacts
        found += scanned.findings
        say("fitting the calibration")
        result = calibrate.fit(scanned.scan, design, mls=mls)
    cal: dict[str, Any] = result.calibration.to_json()
    timings["calibrate"] = time.perf_counter() - t
    if array_doc is None:
        found.append(_calibration_finding(result, "", f"calibration from the {cal['scan']['source']} scan "
                                          f"({cal['scan']['rows']} rows): "))
        out.append(Artifact("calibration/calibration.json", _json_bytes(cal), "force calibration (polynomial in Bz, "
                            "Br): coefficients, scaling, valid region, held-out errors, scan hash"))
    for name, data in sorted(calibration_chart.chart(result).items()):
        out.append(Artifact(f"calibration/{name}", data, calibration_chart.caption(result)
                            + ("" if array_doc is None else " (taxel 0)")))
    if acceptance is not None:
        out.append(Artifact("calibration/acceptance.json", _json_bytes(acceptance),
                            "acceptance-test bands: field at rest and the rise under a known weight, with assumptions"))
    plan = None
    try:
        plan = None if prediction is None else weigh_plan(design, prediction)
    except ScanError as e:  # the design's ranges take no plan of the weight jig: the report says why
        found.append(Finding(Severity.INFO, "weigh-plan", f"no weight plan (calibrate from a scan): {e}"))
    if plan is not None:
        out.append(Artifact("calibration/weigh_plan.json", _json_bytes(plan), "the weighings of a calibration with "
                            "known weights on the weight jig: stand angles and coins (magfab-readout weigh)"))
        out += _charts(weights_figures.FOLDER, weights_figures.figures(weights_figures.bench_rows()),
                       weights_figures.CAPTIONS)
    say("rendering the firmware and the readout package")
    t = time.perf_counter()
    fw = firmware.render(design, cal)
    out += [Artifact(f"firmware/{rel}", data, firmware.RECORD_CAPTIONS.get(rel, "firmware source"))
            for rel, data in sorted(fw.items())]
    rd = readout.render(design, cal, acceptance, array_doc,
                        () if array_doc is None else tuple(f.calibration.to_json() for f in arrayed.fits),
                        None if array_doc is None else _artifact_json(arrayed.artifacts, "array/crosstalk.json"),
                        weigh_plan=plan)
    out += [Artifact(rel, data, "readout package (pip install ./readout)") for rel, data in sorted(rd.items())]
    timings["render"] = time.perf_counter() - t
    # the ready-to-flash image, the same on every machine (a compiler or not): the generic image shipped in the
    # package, its settings and calibration the record's (bench/firmware.py measured it against a build-specific one)
    out.append(Artifact(*firmware.ready_image(design, cal)))
    return BundleStage(artifacts=out, findings=found, fit=result, weighing=plan)


def _artifact_json(artifacts, path: str) -> dict[str, Any] | None:
    """The JSON file ``path`` among ``artifacts`` (None when it is not there)."""
    return next((json.loads(a.data) for a in artifacts if a.path == path), None)


def _crosstalk(design: Design, prediction: Prediction) -> CrosstalkStage:
    """The array's crosstalk budget (:mod:`magfab.models.crosstalk`): array/crosstalk.json, its charts, its
    findings, and whether the host is to remove a moving neighbour's field (the budget is over without it)."""
    xt = crosstalk.crosstalk(design, prediction)
    out = [Artifact("array/crosstalk.json", _json_bytes(xt.as_json()), "the crosstalk budget: each taxel's misreading "
                    "as its neighbours move, with and without the host's compensation, the least pitch per polarity")]
    out += _charts("array/", crosstalk_figures.figures(xt), crosstalk_figures.CAPTIONS)
    return CrosstalkStage(artifacts=out, findings=crosstalk_findings(design, xt), dynamic=xt.dynamic)


def _taxel_calibrations(design: Design, prediction: Prediction, scans: dict[int, Scan] | None,
                        mls: bool) -> ArrayStage:
    """An array's calibrations: each taxel's scan (measured, from ``scans`` {taxel: Scan}, or simulated with its
    neighbours' field), its fit to the scan with the neighbours' field removed, and calibration/array.json
    (:mod:`magfab.models.taxels`). A measured scan is kept in the build (:mod:`magfab.array_bench`) so the next
    taxel's calibration refits it."""
    scans = scans or {}
    field = array_field(design)
    simulated = tuple(simulate_taxel_scan(design, prediction, t.index, field) for t in design.taxels)
    every = tuple(scans.get(t.index) or simulated[t.index] for t in design.taxels)
    xt = _crosstalk(design, prediction)
    out, found = list(xt.artifacts), list(xt.findings)
    arrayed = calibrate_taxels(design, prediction, every, mls=mls, dynamic=xt.dynamic)
    doc = arrayed.as_json(design)
    out += [Artifact("calibration/array.json", _json_bytes(doc), "the array: each taxel's address, order code, "
                    "polarity, position and calibration file, and the neighbours' field the host removes")]
    for taxel, fitted, scan in zip(design.taxels, arrayed.fits, arrayed.scans):
        k = taxel.index
        out.append(Artifact(f"calibration/{arrayed.file_name(k)}", _json_bytes(fitted.calibration.to_json()),
                            f"force calibration of taxel {k} (fitted to its scan with the neighbours' field removed)"))
        out.append(Artifact(f"calibration/scan_simulated_taxel_{k:02d}.csv", scan_csv(simulated[k]).encode(),
                            f"the simulated scan of taxel {k}, as its chip reads it (scan CSV format)"))
        if k in scans:  # the simulated one stays too: it may be the measured one's source (calibrate's own input)
            out.append(Artifact(measured_scan_path(k), scan_csv(scan, [f"taxel {k}, measured: {scan.source}"]).encode(),
                                f"the measured scan taxel {k}'s calibration is fitted to (scan CSV format)"))
            found += [Finding(Severity.WARNING, "scan-range", f"taxel {k}: {text}", "calibration.scan_z_mm")
                      for text in scan_depth_warnings(compensated(scan, field, k), prediction)]
        found.append(_calibration_finding(fitted, f"taxel {k}: ", f"{'measured' if k in scans else 'simulated'} "
                                          "scan, "))
    return ArrayStage(artifacts=out, findings=found, fits=tuple(arrayed.fits), doc=doc)


def _fabrication(design: Design, prediction: Prediction, acceptance: dict[str, Any] | None,
                 weighing: dict[str, Any] | None, say: Progress, timings: dict[str, float]) -> Stage:
    """The bench papers: checklist.md, checklist.html (tick boxes, printable) and bom.csv. The checklist's scan
    step spans the simulated scan's extent (one depth for the scan, the checklist and the predicted range);
    ``weighing`` is the bundle's weight plan."""
    say("writing the checklist and the bill of materials")
    t = time.perf_counter()
    plan = scan_plan(design, prediction)
    out = [
        Artifact("checklist.md", checklist.checklist_md(design, acceptance, plan, weighing).encode(),
                 "fabrication checklist with the quantities filled in (Markdown)"),
        Artifact("checklist.html", checklist.checklist_html(design, acceptance, plan, weighing).encode(),
                 "the same checklist with tick boxes, to print"),
        Artifact("bom.csv", bom.bom_csv(design, acceptance, weighing).encode(),
                 f"bill of materials for {design.spec.fabrication.sensors} sensor(s)"),
    ]
    timings["checklist"] = time.perf_counter() - t
    return Stage(artifacts=out, findings=fabrication_findings(design))


def model_bench() -> list[dict[str, object]]:
    """The speed-accuracy table bench/models.py last measured (shipped with the package), or []."""
    return figures.packaged_rows("model_bench.json")


def plan(spec: Spec, progress: Progress | None = None, scan=None, parallel: bool | None = None) -> BuildResult:
    """Everything a build would write, as bytes, with its findings; raises on an error-level finding.

    ``scan`` (a :class:`magfab.formats.scan_csv.Scan`) calibrates the firmware and readout from real data;
    without it the bundle carries a provisional calibration fitted to a simulated scan. The CAD branch runs
    here while the physics branch runs in a forked worker (:mod:`magfab.fork`; ``parallel=False`` or
    ``MAGFAB_JOBS=1`` runs both in this process); the result is the same either way."""
    say = progress or (lambda _stage: None)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    for measured in (scan.values() if isinstance(scan, dict) else [] if scan is None else [scan]):
        check_scan(spec, measured)
    say("deriving the design")
    design = preflight(derive(spec))  # the reference chip's site, the build's cost, the board: before any work
    spec = design.spec  # with the board's size where the spec left it unstated: spec.json and its hash say so
    findings = design_findings(design)
    timings["derive"] = time.perf_counter() - t0
    _stop(findings, spec)

    parallel = parallel_available() if parallel is None else parallel
    with side_branch(_physics, design, scan, parallel, parallel=parallel) as physics:
        cad = _cad(design, say, timings, parallel)
        _stop(findings + cad.findings, spec)
        say("drawing the parts and the board for the report")
        t = time.perf_counter()
        # the mould's two views are half the pictures' time: drawn in a worker beside the others where the build forks
        mould = tuple(p.stem for p in PARTS if p.make in (cup_solid, lid_solid))
        with side_branch(_part_views, cad.meshes, mould, parallel=parallel) as beside:
            views = _part_views(cad.meshes, tuple(stem for stem in cad.meshes if stem not in mould))
            views |= beside.result()
        pictures = draw_pictures(design, cad.meshes, cad.artifacts, cad.board, views)
        timings["report-pictures"] = time.perf_counter() - t
        say("waiting for the predictions and the bundle")
        t = time.perf_counter()
        branch = physics.result()
        if physics.forked:  # how long the CAD branch waited for the worker
            timings["wait-physics"] = time.perf_counter() - t
    findings += cad.findings
    artifacts = list(cad.artifacts)
    for stage in branch.stages:  # predictions, bundle, bench papers: each stops the build in turn
        findings += stage.findings
        _stop(findings, spec)
        artifacts += stage.artifacts
    timings.update(branch.timings)
    prediction, cal = branch.prediction, branch.calibration

    say("writing reports")
    artifacts.append(Artifact("design.json", _json_bytes(design.as_dict()), "every derived dimension, mm and mm^3"))
    artifacts.append(Artifact("spec.json", _json_bytes(spec.dump()), "the spec with every default filled in"))
    artifacts.append(Artifact("findings.json", _json_bytes([f.as_dict() for f in findings]), "design and mesh checks"))
    say("drawing the report")
    t = time.perf_counter()
    report_files = [("report.html", "this page: the whole build on one page"),
                    ("manifest.json", "what made what: hashes, versions")]
    artifacts.append(Artifact("report.html", render_report(spec, design, findings, list(artifacts), prediction, cal,
                                                           cad.meshes, extra_files=report_files, board=cad.board,
                                                           pictures=pictures),
                              "the whole build on one page, for a browser"))
    timings["report"] = time.perf_counter() - t
    models = {f"{m.family}_model": m.as_dict() for m in prediction.models}
    artifacts.append(Artifact("manifest.json", _manifest(spec, design, artifacts, models),
                              "what made what: hashes, versions"))
    timings["total"] = time.perf_counter() - t0
    image = next((a.path for a in artifacts if a.path == firmware.image_path(design)), None)
    calibration = {"source": cal["scan"]["source"], "method": cal["method"], "order": cal["order"],
                   "rms_holdout_Fz_mN": round(1000 * cal["errors"]["Fz_N"]["rms_holdout"], 2),
                   "rms_holdout_Fr_mN": round(1000 * cal["errors"]["Fr_N"]["rms_holdout"], 2), "image": image,
                   **stated_error(cal)}
    return BuildResult(spec, design, artifacts, findings, timings, prediction=prediction, calibration=calibration)


def _part_views(meshes: dict[str, trimesh.Trimesh], stems: tuple[str, ...]) -> dict[str, bytes]:
    """The report's PNG of each part in ``stems``, whole and cut away."""
    return {stem: part_figure(stem, meshes[stem]) for stem in stems}


def _stop(findings: list[Finding], spec: Spec) -> None:
    stop = errors_in(findings, spec.build.strict)
    if stop:
        raise BuildError(stop)


def _cad(design: Design, say: Progress, timings: dict[str, float], parallel: bool = False) -> CadStage:
    """The CAD branch: every solid as STL (and STEP), the mesh checks, the closed mould's fit, the board; stops at
    the first stage with an error. The board needs no CAD kernel: where the build forks (``parallel``), it is
    routed and plotted in a worker while this process loads the kernel (a third of this branch's time) and models
    the parts."""
    say("placing and routing the board" + (" beside the CAD kernel" if parallel else ""))
    with side_branch(_board, design, parallel=parallel) as board:
        solids = _solids(design, say, timings)  # raises on an error: the board's worker is ended with the block
        t = time.perf_counter()
        routed: BoardStage = board.result()
        if board.forked:
            timings["wait-board"] = time.perf_counter() - t
    timings.update(routed.timings_s)
    return CadStage(artifacts=solids.artifacts + routed.artifacts, findings=solids.findings + routed.findings,
                    meshes=solids.meshes, board=routed.board)


def _solids(design: Design, say: Progress, timings: dict[str, float]) -> SolidsStage:
    """Every solid as STL (and STEP), the mesh checks and the closed mould's fit (no board yet); raises where they
    find an error."""
    spec = design.spec
    say("loading the CAD kernel")
    t = time.perf_counter()
    with deferred_interrupt():  # a Ctrl-C inside VTK's initialisation crashed the process: deliver it after
        import cadquery  # noqa: F401 - lazy: the CAD kernel, timed on its own, not charged to the first part
        import trimesh  # noqa: F401

    timings["import"] = time.perf_counter() - t
    artifacts: list[Artifact] = []
    findings: list[Finding] = []
    meshes: dict[str, trimesh.Trimesh] = {}
    tol, ang = spec.mould.tessellation_tolerance_mm, spec.mould.angular_tolerance_deg
    for part in parts_of(design):
        stem, description = part.stem, part.description
        say(f"modelling {stem}")
        t = time.perf_counter()
        solid = part.make(design)
        timings[f"solid:{stem}"] = time.perf_counter() - t
        t = time.perf_counter()
        mesh = cad_files.tessellate(solid, tol, ang)
        meshes[stem] = mesh
        findings += mesh_findings(stem, mesh, cast("cq.Shape", solid.val()).Volume(), tol)
        artifacts.append(Artifact(f"{stem}.stl", cad_files.stl_bytes(mesh, f"{spec.name} {stem}"),
                                  description + ", STL"))
        if spec.build.step:
            artifacts.append(Artifact(f"{stem}.step", cad_files.step_bytes(solid, f"{spec.name}-{stem}"),
                                      description + ", STEP"))
        timings[f"export:{stem}"] = time.perf_counter() - t
    if not errors_in(findings, strict=False):  # booleans need sound meshes
        t = time.perf_counter()
        findings += mould_fit_findings(design, mould_fit(design, meshes, tol))
        timings["mould-fit"] = time.perf_counter() - t
    _stop(findings, spec)
    return SolidsStage(artifacts=artifacts, findings=findings, meshes=meshes)


@dataclass(frozen=True)
class _PhysicsBranch:
    """What the physics branch hands back (pickled when it ran in the worker)."""

    stages: tuple[Stage, ...]  # predictions, bundle, bench papers, in pipeline order
    prediction: Prediction
    calibration: dict[str, object]  # calibration.json as written
    timings: dict[str, float]


def _physics(design: Design, scan: Scan | dict[int, Scan] | None, parallel: bool = False) -> _PhysicsBranch:
    """The physics branch: predictions and plots, the acceptance bands, the calibration, firmware and readout
    bundle, and the bench papers. Nothing here needs the CAD kernel.

    It is the build's longest branch, and its plots the longest part of it: where the build forks (``parallel``), the
    speed-accuracy chart and the field contours are drawn in a worker of its own while this one draws the others and
    fits the bundle."""
    timings: dict[str, float] = {}
    say: Progress = lambda _stage: None
    predicted = _predictions(design, say, timings)
    prediction = predicted.prediction
    t = time.perf_counter()
    beside = ("field_contours", "speed_accuracy")  # the worker's share: they took just over half the plots' CPU
    mine = tuple(name for name in figures.MAKERS if name not in beside)
    with side_branch(figures.figures, design, prediction, model_bench(), beside, parallel=parallel) as worker:
        drawn = figures.figures(design, prediction, (), mine)
        timings["plots"] = time.perf_counter() - t  # the worker's plots too where they were drawn in-process
        accepted = acceptance_stage(design, prediction)
        bundle = bundle_stage(design, prediction, scan, accepted.bands, say, timings)
        papers = _fabrication(design, prediction, accepted.bands, bundle.weighing, say, timings)
        t = time.perf_counter()
        drawn |= worker.result()
        if worker.forked:
            timings["wait-plots"] = time.perf_counter() - t
    predicted = replace(predicted, artifacts=predicted.artifacts + _plots(drawn, prediction))
    stages = (predicted, Stage(artifacts=bundle.artifacts, findings=accepted.findings + bundle.findings), papers)
    return _PhysicsBranch(stages, prediction, bundle.fit.calibration.to_json(), timings)


def _manifest(spec: Spec, design: Design, artifacts: list[Artifact], models: dict[str, Any]) -> bytes:
    made: dict[str, Any] = {"geometry": "cadquery-occt", "land_patterns": f"IPC-7351B {spec.pcb.density.value}",
                            "board": "magfab grid router", "gerbers": _kicad_version(artifacts)}
    return _json_bytes({
        "magfab_version": __version__,
        "spec_name": spec.name,
        "spec_sha256": spec.sha256(),
        "printer": design.printer.key,
        "models": made | models,
        "artifacts": [
            {"path": a.path, "sha256": hashlib.sha256(a.data).hexdigest(), "bytes": len(a.data),
             "description": a.description}
            for a in artifacts
        ],
    })


def build(spec: Spec, out_dir: Path | None = None, progress: Progress | None = None, scan=None) -> BuildResult:
    """Plan and write a build (calibrated from ``scan`` if given); returns what was written where."""
    target = check_target(Path(out_dir) if out_dir is not None else default_out_dir(spec))
    result = plan(spec, progress, scan)
    if progress:
        progress("writing files")
    t = time.perf_counter()
    result.out_dir = write(target, result.artifacts)
    result.timings_s["write"] = time.perf_counter() - t
    return result


def default_out_dir(spec: Spec) -> Path:
    return Path("build") / spec.name


def _kicad_version(artifacts: list[Artifact]) -> str | None:
    """The KiCad that plotted the Gerbers, as it signs them (None when no Gerbers were plotted)."""
    for a in artifacts:
        if a.path.endswith(".gbr"):
            m = re.search(rb"%TF\.GenerationSoftware,KiCad,Pcbnew,([^*]*)\*%", a.data)
            if m:
                return "KiCad " + m.group(1).decode("ascii", "replace")
    return None
