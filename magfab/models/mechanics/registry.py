"""The normal-force models by name, and the material band from one solve.

Scaling law used for the band: an incompressible material with one modulus (neo-Hookean, or Yeoh with fixed
C20/C10 and C30/C10) under prescribed indentation has a displacement field independent of mu, and every force and
stress proportional to mu. One solve therefore gives the soft, nominal and stiff curves (:meth:`Curve.scaled`,
:func:`band_curves`); all three models obey it, and a test checks it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np

from .body import Body, Curve, check_option
from .closed_forms import column, hertz_column
from .fe import fe
from .options import MechanicsModel

__all__ = ["MODELS", "band_curves"]

#: Normal-force models by name, cheapest first: callable(body, mu_kPa, indentation_mm, **options) -> Curve.
#: Keys are :class:`MechanicsModel` members, so the plain names ("column", ...) look them up too.
MODELS: Mapping[MechanicsModel, Callable[..., Curve]] = {
    MechanicsModel.COLUMN: column, MechanicsModel.HERTZ_COLUMN: hertz_column, MechanicsModel.FE: fe}


def band_curves(body: Body, mu_band_kPa: Sequence[float], model: MechanicsModel | str = MechanicsModel.FE,
                indentation_mm: Sequence[float] | np.ndarray = (0.0,), **options: object) -> dict[str, Curve]:
    """Curves for (soft, nominal, stiff) moduli from ONE solve at the nominal modulus, scaled by mu.

    ``mu_band_kPa`` is what :func:`~.body.band` returns; ``model`` a key of :data:`MODELS`; ``options`` go to the
    model. Returns {"soft": ..., "nominal": ..., "stiff": ...}.
    """
    soft, nominal, stiff = (float(m) for m in mu_band_kPa)
    chosen = check_option(MechanicsModel, model, "model", tuple(MODELS))
    ref = MODELS[chosen](body, nominal, indentation_mm, **options)
    return {"soft": ref.scaled(soft), "nominal": ref, "stiff": ref.scaled(stiff)}
