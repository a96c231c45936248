"""The incompressible hyperelastic material of the large-strain FE, in units of mu, per quadrature point.

The axisymmetric deformation gradient is carried as g = (F_rr, F_rz, F_zr, F_zz, F_thth). :class:`_Material`
gives the energy's first and second derivatives in g (Yeoh; neo-Hookean when its ratios are zero), principal
Cauchy stresses, and :func:`_stretches` the principal stretches.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .body import MechanicsError, check_option
from .options import MaterialLaw

_G0 = np.array([1.0, 0.0, 0.0, 1.0, 1.0])
# Second derivatives of J = (F_rr F_zz - F_rz F_zr) F_thth with respect to g (a symmetric constant pattern, times
# the entries of g listed in _HJ).
_HJ = ((0, 3, 4), (1, 2, 4), (0, 4, 3), (3, 4, 0), (1, 4, 2), (2, 4, 1))  # (i, j, index of g; sign below)
_HJ_SIGN = (1.0, -1.0, 1.0, 1.0, -1.0, -1.0)


@dataclass(frozen=True)
class _Material:
    """Incompressible Yeoh in units of mu = 2 C10: W = 1/2 [(I1-3) + k2 (I1-3)^2 + k3 (I1-3)^3 - 2 ln J] + p (J-1).

    k2 = C20/C10, k3 = C30/C10; k2 = k3 = 0 is neo-Hookean. The -ln J term makes the reference state stress-free
    at p = 0; with J = 1 enforced it changes nothing else.
    """

    k2: float = 0.0
    k3: float = 0.0

    def response(self, g: np.ndarray, p: np.ndarray):
        """(dW/dg, d2W/dg2, dJ/dg, J, det2) at every point; g (..., 5), p (...).

        d2W/dg2 = 2 W_1 I + (p - 1/J) d2J/dg2 + j j^T / J^2 (+ 4 W_11 g g^T for Yeoh), built in place: the Hessian
        of J has six symmetric pairs of entries (_HJ), each an entry of g."""
        a, b, c, d, h = (g[..., i] for i in range(5))
        det2 = a * d - b * c
        J = det2 * h
        j = np.stack([d * h, -c * h, -b * h, a * h, det2], axis=-1)
        s = np.einsum("...i,...i->...", g, g) - 3.0
        f1 = 0.5 * (1.0 + 2.0 * self.k2 * s + 3.0 * self.k3 * s * s)  # dW/dI1
        Jinv = 1.0 / J
        q = p - Jinv
        S = 2.0 * f1[..., None] * g + q[..., None] * j
        jJ = j * Jinv[..., None]
        D = jJ[..., :, None] * jJ[..., None, :]
        for i in range(5):
            D[..., i, i] += 2.0 * f1
        for (i, k, m), sign in zip(_HJ, _HJ_SIGN):
            v = (sign * q) * g[..., m]
            D[..., i, k] += v
            D[..., k, i] += v
        if self.k2 or self.k3:
            f2 = 0.5 * (2.0 * self.k2 + 6.0 * self.k3 * s)  # d2W/dI1^2
            D += (4.0 * f2)[..., None, None] * g[..., :, None] * g[..., None, :]
        return S, D, j, J, det2

    def cauchy(self, g: np.ndarray, p: np.ndarray) -> np.ndarray:
        """Principal Cauchy stresses (..., 3) in units of mu: sigma = (2 W_1 b - I) / J + p I."""
        s = np.sum(g * g, axis=-1) - 3.0
        f1 = 0.5 * (1.0 + 2.0 * self.k2 * s + 3.0 * self.k3 * s * s)
        a, b, c, d, h = (g[..., i] for i in range(5))
        J = (a * d - b * c) * h
        b11, b12, b22 = a * a + b * b, a * c + b * d, c * c + d * d
        mean, rad = 0.5 * (b11 + b22), np.sqrt(0.25 * (b11 - b22) ** 2 + b12 * b12)
        bev = np.stack([mean + rad, mean - rad, h * h], axis=-1)
        return (2.0 * f1[..., None] * bev - 1.0) / J[..., None] + p[..., None]


def _stretches(g: np.ndarray) -> np.ndarray:
    """Principal stretches (..., 3): in-plane from C's 2x2 block, and the hoop stretch."""
    a, b, c, d, h = (g[..., i] for i in range(5))
    c11, c12, c22 = a * a + c * c, a * b + c * d, b * b + d * d
    mean, rad = 0.5 * (c11 + c22), np.sqrt(0.25 * (c11 - c22) ** 2 + c12 * c12)
    return np.sqrt(np.stack([mean + rad, np.maximum(mean - rad, 0.0), h * h], axis=-1))


def _material(material: MaterialLaw | str, yeoh_ratios: tuple[float, float] | None) -> _Material:
    """The :class:`_Material` for a law and, for Yeoh, its ratios (C20/C10, C30/C10)."""
    law = check_option(MaterialLaw, material, "material")
    if law == MaterialLaw.NEO_HOOKEAN:
        if yeoh_ratios is not None:
            raise MechanicsError("Input yeoh_ratios must be omitted for material 'neo-hookean'")
        return _Material()
    if yeoh_ratios is None:
        raise MechanicsError("Input yeoh_ratios = (C20/C10, C30/C10) must be given for material 'yeoh' (a silicone's "
                             "are its recipe's yeoh_k2 and yeoh_k3, recipes/materials.toml)")
    k2, k3 = (float(v) for v in yeoh_ratios)
    return _Material(k2, k3)
