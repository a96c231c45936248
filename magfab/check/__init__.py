"""Every finding about a design, in one package; each is a :class:`~magfab.errors.Finding` with a severity, and
error-level findings stop a build (:class:`~magfab.errors.BuildError`, :func:`errors_in`).

One module per thing checked:

* :mod:`.design`: the derived geometry against the printer recipe's minimums, the fits, the cavity volume. Cheap.
* :mod:`.mesh`: each exported mesh (watertight, oriented, its volume the exact solid's) and the closed mould on them.
* :mod:`.predict`: the prediction (docs/models.md: M9 as errors, the M18 guidelines as warnings), with the drift
  budget's (:mod:`.drift`) and the reference chip's (:mod:`.reference`) findings: :func:`predict_with_findings`.
* :mod:`.crosstalk`: an array's crosstalk budget. :mod:`.fabrication`: the silicone against its pot life.
* :mod:`.preflight`: what refuses a spec before any work (the reference chip's site, the build's cost limits, a
  board too small for its parts), as one line; it returns the design to go on with, its board sized where the spec
  leaves the size out (:mod:`magfab.board.fit`).
* :mod:`.refusal`: ``magfab check``'s findings and the refusal the build would stop with, stage by stage as it does.

The routed board's rule checks are the board's own (:func:`magfab.pcb.findings`).
"""

from __future__ import annotations

from .crosstalk import crosstalk_findings
from .design import design_findings
from .drift import drift_findings
from .fabrication import fabrication_findings
from .mesh import mesh_findings, mould_fit_findings
from .predict import predict_with_findings, prediction_findings
from .preflight import preflight
from .reference import reference_findings
from .stop import errors_in

__all__ = ["design_findings", "mesh_findings", "mould_fit_findings", "prediction_findings", "predict_with_findings",
           "drift_findings", "reference_findings", "crosstalk_findings", "fabrication_findings", "preflight",
           "errors_in"]
