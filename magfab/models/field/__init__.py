"""Field of the magnet: an axially magnetised cylinder, four models of it, their errors and their cost.

Frame and units. The magnet is centred at the origin with its axis on z and is magnetised along +z;
its lower face is at z = -H/2. Lengths are in mm at the API, the remanence Br_rem in tesla, and every
field comes back in gauss (1 T = 10^4 G). A sensor at axial distance d below the lower face and radial
offset r sits at (r, 0, -(H/2 + d)). Below the magnet Bz > 0 and the radial component points inwards.

One module per job: :mod:`.magnet` (the magnet, the point checks, :class:`FieldModelError`), :mod:`.exact`,
:mod:`.closed_forms` (axial closed form, dipole, multipoles), :mod:`.surrogate`, :mod:`.choice` (working volume,
error against exact, the registry and the choice), :mod:`.sensor` ((Bz, Br) against (d, r)) and :mod:`.timing`.
Everything public is re-exported here: callers write ``from magfab.models import field; field.exact(...)``.

The models (docs/models.md, M6 and M15), each ``model(magnet, points_mm, *, rtol=...) -> (N, 3)`` gauss, named by
:class:`magfab.spec.FieldModel` (its ``auto`` is :func:`choose`):

* :func:`exact` -- Derby & Olbert (2010), complete elliptic integrals: magpylib's own kernel
  (``magpylib.core.magnet_cylinder_axial_Bfield``, the code ``magpylib.magnet.Cylinder`` runs), called
  directly on cylindrical coordinates so it skips ``getB``'s per-call bookkeeping (3-5x faster). The
  reference everything else is measured against; :func:`magpylib_cylinder` is the same field through
  magpylib's class interface and the tests pin the two together. Our own Derby-Olbert code with
  Bulirsch's cel (bench/field.py) ran at 1.0-1.6x the speed of that kernel under varying machine
  load, so it is not kept here: a second copy of the special functions is not worth that.
* :func:`on_axis` -- docs/models.md, M6: Bz on the axis, Bx = By = 0. Exact on the axis (written here in a
  form without the far-field cancellation of the textbook form); wrong off it.
* :func:`dipole` -- a point dipole of moment m = Br_rem V / mu0. Wrong near the magnet.
* :func:`surrogate` -- a table of the dimensionless exact field over (r/R, z/R), one per aspect H/R,
  built lazily (~0.1 s) from :func:`exact` and interpolated bilinearly: within 1e-4 of it over the
  MagOne working volume (3e-4 anywhere in its domain) and 40-80x faster than magpylib's ``getB``.

Failures are detected and raised as :class:`FieldModelError`, never returned as numbers:

* every model refuses points inside the magnet or within ``SURFACE_GAP`` R of its surface (the sensor
  cannot be there; Bz jumps across the side face and Br diverges logarithmically at the rim);
* :func:`exact` refuses points so far away that its two face terms cancel to below ``rtol`` (relative
  rounding error ~ eps D^3 / (R^2 H); from D ~ 1000 R on the dipole is the more accurate of the two);
* :func:`on_axis` refuses points off the axis whose paraxial error estimate exceeds ``rtol``;
* :func:`dipole` refuses points inside the magnet's circumscribed sphere (the multipole series
  diverges: no error estimate) or whose next-multipole error estimate exceeds ``rtol``;
* :func:`surrogate` refuses points outside its table (``SurrogateDomain``) or an ``rtol`` tighter
  than the error the table measured on itself when it was built.

``rtol=None`` turns the error-estimate checks off (never the inside-the-magnet check): benchmarks use
it to measure how wrong a model is where it would refuse.

Error of a model at a point: ``|B_model - B_exact| / |B_exact|`` with vector norms. The vector norm
does not vanish outside the magnet, so this stays finite where Bz alone crosses zero off the axis
(component-wise relative errors would explode there). :func:`model_error` also gives the error
normalised by the largest |B| over the points, the figure to quote where |B| itself becomes small.
"""

from __future__ import annotations

from ...units import GAUSS_PER_TESLA
from .choice import MODELS, Choice, FieldModel, Model, ModelAccuracy, choose, model_error, model_name, working_volume
from .closed_forms import (
                           axial_multipoles,
                           axis_bz,
                           axis_dbz_dz,
                           dipole,
                           dipole_error_estimate,
                           on_axis,
                           on_axis_error_estimate,
)
from .exact import exact, exact_rounding_estimate, magpylib_cylinder
from .magnet import DEFAULT_RTOL, EXACT_RTOL, MU0, SURFACE_GAP, FieldModelError, Magnet
from .sensor import FD_STEP, bz_br, dbz_dz, saturation_gap
from .surrogate import SURROGATE_BUILD_RTOL, SurrogateDomain, SurrogateTable, surrogate, surrogate_table
from .tilt import lateral_field, lateral_rates, tilted_field
from .timing import Measurement, measure

__all__ = [
    "FieldModelError", "Magnet", "GAUSS_PER_TESLA", "MU0", "DEFAULT_RTOL", "EXACT_RTOL", "SURFACE_GAP",
    "exact", "magpylib_cylinder", "exact_rounding_estimate",
    "on_axis", "on_axis_error_estimate", "axis_bz", "axis_dbz_dz",
    "dipole", "dipole_error_estimate", "axial_multipoles",
    "SURROGATE_BUILD_RTOL", "SurrogateDomain", "SurrogateTable", "surrogate_table", "surrogate",
    "working_volume", "ModelAccuracy", "model_error",
    "FieldModel", "Model", "MODELS", "model_name", "Choice", "choose", "bz_br", "dbz_dz", "saturation_gap", "FD_STEP",
    "Measurement", "measure", "lateral_field", "lateral_rates", "tilted_field",
]
