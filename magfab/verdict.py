"""``magfab check``'s verdict on a spec: every finding it reports, and the refusal ``magfab build`` would stop with.

The build (:func:`magfab.pipeline.plan`) refuses before any work what :func:`~magfab.check.preflight` refuses, then
stops at the first of its stages whose findings so far hold an error (a warning too with ``build.strict``), with
one line: the design's checks; the CAD branch (the board routed and its rules, the solids' meshes and the closed
mould; errors and notes only); the prediction; the bundle (the acceptance test and the calibration; warnings only);
the bench papers (:func:`~magfab.check.fabrication_findings`; warnings only).

:func:`verdict` runs the same stages but the solids of the CAD branch (of which it routes and checks the board,
beside its prediction, a few seconds: only routing finds that a connection has no path with the board's rules) and,
unless ``build.strict`` makes their warnings stop a build, the bundle and the papers; it refuses where the build
refuses, with the build's line (``tests/test_check_build_agree.py`` holds them to each other over the design space,
the solids included).
"""

from __future__ import annotations

from . import pcb
from .check import design_findings, errors_in, fabrication_findings, predict_with_findings, preflight
from .design import Design, derive
from .errors import BuildError, Finding
from .fork import side_branch
from .pipeline import acceptance_stage, bundle_stage
from .spec import Spec

__all__ = ["verdict"]


def verdict(spec: Spec) -> tuple[Design, list[Finding], BuildError | None]:
    """(the design the build goes on with, every finding check reports, the build's refusal or None). Raises
    :func:`preflight`'s refusal."""
    design = preflight(derive(spec))
    strict = spec.build.strict
    findings = design_findings(design)
    stop = errors_in(findings, strict)  # the build stops here, before its CAD branch
    # the board routed and checked, beside the prediction (forked where the build forks): only routing finds that a
    # connection has no path with the board's rules
    routed: list[Finding] = []
    if stop:
        pred, found = predict_with_findings(design)
    else:
        with side_branch(board_findings, design) as board:
            pred, found = predict_with_findings(design)
            routed = board.result()
    findings += routed
    stop = stop or errors_in(findings, strict)
    findings += found
    stop = stop or errors_in(findings, strict)
    if strict and not stop and pred is not None:  # the bundle's and the papers' warnings stop a strict build
        accepted = acceptance_stage(design, pred)
        findings += accepted.findings + bundle_stage(design, pred, None, accepted.bands, lambda _: None, {}).findings
        stop = errors_in(findings, strict)
        findings += fabrication_findings(design)
        stop = stop or errors_in(findings, strict)
    return design, findings, BuildError(stop) if stop else None


def board_findings(design: Design) -> list[Finding]:
    """The routed board's findings, as the build's board stage makes them (:func:`magfab.pcb.findings`)."""
    return pcb.findings(pcb.board(design))
