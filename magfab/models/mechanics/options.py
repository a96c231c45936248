"""The option Enums the elastomer models take.

Each is a ``str`` Enum, so a caller passing the old string (``on_failure="truncate"``) still works: the models
convert with ``Enum(value)`` through :func:`~magfab.models.mechanics.body.check_option`. The normal-force model
names are :class:`magfab.spec.MechanicsModel`'s (its ``auto`` is the spec's choice among them, not a model), and the
hyperelastic law is :class:`magfab.spec.MaterialLaw` (``predict.material_law``).
"""

from __future__ import annotations

from enum import Enum

from ...spec import MaterialLaw, MechanicsModel

__all__ = ["MechanicsModel", "OnFailure", "ShearModel", "ShearEnds", "MaterialLaw"]


class OnFailure(str, Enum):
    """What the FE does when it fails part way: raise, or return the curve up to where it failed."""

    RAISE = "raise"
    TRUNCATE = "truncate"


class ShearModel(str, Enum):
    """Shear-stiffness model: Timoshenko's closed form for the column below the magnet, or the mode-1 FE."""

    TIMOSHENKO = "timoshenko"
    FE = "fe"


class ShearEnds(str, Enum):
    """How the magnet is held under a lateral load: free to tilt, or guided (kept level)."""

    FREE = "free"
    GUIDED = "guided"
