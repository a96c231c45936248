"""Elastomer force models: normal force against indentation, magnet displacement, and shear stiffness.

A rigid flat frictionless indenter pushes the elastomer's top down by ``delta`` (the indentation, mm).
Every normal model returns a :class:`Curve` (force, magnet displacement, stiffness, peak stretch and
stress against indentation). Cheapest first (:data:`MODELS`, keyed by :class:`MechanicsModel`):

``column``, ``hertz_column``
    Closed forms (:mod:`.closed_forms`): the volume-equivalent bonded neo-Hookean column, and Hertz contact of
    the cap in series with the column of the base.
``fe``
    Axisymmetric large-strain finite elements on scikit-fem (:mod:`.fe`): incompressible neo-Hookean (or Yeoh),
    Taylor-Hood P2/P1, the magnet a rigid inclusion, the indenter by an active set; failures (element inversion,
    Newton non-convergence, excessive distortion) raise :class:`MechanicsError` naming the indentation, or with
    ``on_failure="truncate"`` end the curve there.

Shear: :func:`shear_stiffness` (Timoshenko closed form, or a small-strain Fourier-mode-1 FE of the same
axisymmetric body under a lateral load on the magnet). Material band: :func:`band` and :func:`band_curves`
(one solve scaled by mu). Studies: :func:`convergence` and :func:`measure` (:mod:`.study`).

The package, one job per module: ``body`` (the body, results, input checks, material band), ``options`` (the
option Enums), ``closed_forms``, ``mesh`` (triangulation), ``discretisation`` (Taylor-Hood bases, assembly),
``material`` (hyperelastic law), ``energy`` (the body's energy on a discretisation), ``indentation`` (contact
and Newton), ``fe`` (load stepping, the :func:`fe` model), ``shear``, ``registry`` (models by name, band
curves), ``study`` (convergence, timing).

Units: lengths in mm, forces in N, moduli and stresses in kPa at the API; the closed forms are evaluated in SI.
scikit-fem (and scipy's sparse solvers) are imported inside the functions that need them, so importing this
package is cheap.
"""

from __future__ import annotations

from .body import Body, Convergence, Curve, MechanicsError, band, check_option
from .closed_forms import column, hertz_column
from .energy import STRETCH_AVERAGING_FRACTION
from .fe import STRETCH_LIMIT, fe
from .indentation import MagnetInterface
from .mesh import BUILD_MESH_FRACTION, channel_wall
from .options import MaterialLaw, MechanicsModel, OnFailure, ShearEnds, ShearModel
from .registry import MODELS, band_curves
from .shear import SHEAR_MODELS, shear_compliance, shear_stiffness
from .shear_surface import REST_PATCH_INDENTATION_MM, ShearLoad, ShearProbe, ShearResponse, shear_response
from .study import clear_caches, convergence, measure

#: What the FE models, for the report (shown beside the stack-up drawing, which shows the pocket).
#:
#: Bonded, chosen by measurement (bench/pocket.py): the protocol seals the magnet with Sil-Poxy (docs/models.md,
#: M23, step 4). Against the bonded model, at 1 mm (0.5 mm) of indentation on a 0.75 mm mesh, nominal mu: a
#: sliding magnet (bilateral frictionless) gives -16.0 % (-21.5 %) force on MagOne, -5.5 % on small_magnet, -5.7 % on
#: flat_tip, +13 % (+15 %) magnet travel per N on MagOne; the design's channel and funnel left open give -34 %
#: (-23 %) force and +75 % (+54 %) travel per N on MagOne (-14 % and +32 % on small_magnet, -23 % and +58 % on
#: flat_tip). Both are far beyond predict.tolerance_pct (1 %), and neither variant reaches the 3 mm the build
#: solves to (the void's corner folds at ~1.0 mm, the sliding edge at ~1.1 mm on MagOne), so the build keeps the
#: bonded model and says what it needs: a glued magnet and a channel filled up to it. MagOne's differences at
#: 0.5 mm agree within 0.3 points on 1.0, 0.75 and 0.5 mm meshes.
MODEL_DESCRIPTION = ("Axisymmetric large-strain FE: incompressible neo-Hookean silicone (Taylor-Hood P2/P1), base "
                     "bonded to the pad, rigid flat frictionless indenter; the rigid magnet, edges rounded to the "
                     "recipe's edge radius on a graded mesh, is bonded in solid silicone: it assumes the Sil-Poxy "
                     "seal glues the magnet and fills the insertion channel and funnel up to it. Measured on MagOne "
                     "at 1 mm (bench/pocket.py): an unglued, sliding magnet gives 16 % less force and 13 % more "
                     "magnet travel per N; an open, unfilled channel and funnel give 34 % less force and 75 % more "
                     "travel per N.")

__all__ = [
    "MODEL_DESCRIPTION",
    "STRETCH_AVERAGING_FRACTION",
    "MechanicsError",
    "Body",
    "Curve",
    "Convergence",
    "band",
    "band_curves",
    "column",
    "hertz_column",
    "fe",
    "clear_caches",
    "convergence",
    "shear_stiffness",
    "shear_compliance",
    "shear_response",
    "ShearResponse",
    "ShearProbe",
    "ShearLoad",
    "REST_PATCH_INDENTATION_MM",
    "MODELS",
    "SHEAR_MODELS",
    "measure",
    "BUILD_MESH_FRACTION",
    "STRETCH_LIMIT",
    "MechanicsModel",
    "OnFailure",
    "ShearModel",
    "ShearEnds",
    "MaterialLaw",
    "MagnetInterface",
    "channel_wall",
    "check_option",
]
