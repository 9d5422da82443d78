"""Two-link planar revolute ("elbow") arm with point masses at the link ends (docs/laws.md#robots; book Example 3.2.2).

Angles from the horizontal, gravity along −y. φ = [m1, m2] (+ [fv1, fv2] with `friction=True`, F = diag(fv) q̇).

    M  = [[(m1+m2) l1² + m2 l2² + 2 m2 l1 l2 c2,  m2 l2² + m2 l1 l2 c2], [m2 l2² + m2 l1 l2 c2,  m2 l2²]]
    V_m = m2 l1 l2 s2 [[−q̇2, −(q̇1+q̇2)], [q̇1, 0]]       (Christoffel form)
    G  = [(m1+m2) g l1 c1 + m2 g l2 c12,  m2 g l2 c12]

The hand is link 2's frame R = Rz(q1 + q2) (x along link 2, z out of the plane) at p = [l1 c1 + l2 c12, l1 s1 + l2 s12,
0] (+ R tool); kinematic parameters (l1, l2) (+ tool.x, tool.y, tool.z; tool.x adds to l2: one direction).
"""

from __future__ import annotations

from dataclasses import dataclass

from ..arrays import array_namespace, matrix
from ..validation import as_scalar, check_switch
from .base import Array, RobotModel
from .hand import PlanarChain


@dataclass(frozen=True, eq=False)
class TwoLinkArm(PlanarChain, RobotModel):
    """Link lengths `l1, l2` (m) and gravity `g` (m/s²) are known constants; the book uses l1 = l2 = 1, g = 9.8."""

    l1: float = 1.0
    l2: float = 1.0
    g: float = 9.8
    friction_terms: bool = False

    def __post_init__(self) -> None:
        for name in ("l1", "l2"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), f"robot.{name}", positive=True, maximum=1e3))
        object.__setattr__(self, "g", as_scalar(self.g, "robot.g", nonnegative=True, maximum=1e3))
        check_switch(self.friction_terms, "robot.friction_terms")

    @property
    def n(self) -> int:
        return 2

    @property
    def param_names(self) -> tuple[str, ...]:
        return ("m1", "m2", "fv1", "fv2") if self.friction_terms else ("m1", "m2")

    def _trig(self, q: Array) -> tuple[Array, Array, Array, Array]:
        xp = array_namespace(q)
        return xp.cos(q[..., 0]), xp.cos(q[..., 1]), xp.sin(q[..., 1]), xp.cos(q[..., 0] + q[..., 1])

    def mass_matrix(self, q: Array, phi: Array) -> Array:
        xp = array_namespace(q, phi)
        _, c2, _, _ = self._trig(q)
        m1, m2 = phi[..., 0], phi[..., 1]
        l1, l2 = self.l1, self.l2
        m12 = m2 * l2**2 + m2 * l1 * l2 * c2
        return matrix(xp, [[(m1 + m2) * l1**2 + m2 * l2**2 + 2 * m2 * l1 * l2 * c2, m12], [m12, m2 * l2**2 + 0 * c2]])

    def coriolis_matrix(self, q: Array, dq: Array, phi: Array) -> Array:
        xp = array_namespace(q, dq, phi)
        h = phi[..., 1] * self.l1 * self.l2 * xp.sin(q[..., 1])
        return matrix(xp, [[-h * dq[..., 1], -h * (dq[..., 0] + dq[..., 1])], [h * dq[..., 0], 0.0 * h]])

    def gravity(self, q: Array, phi: Array) -> Array:
        c1, _, _, c12 = self._trig(q)
        m1, m2 = phi[..., 0], phi[..., 1]
        xp = array_namespace(q, phi)
        g2 = m2 * self.g * self.l2 * c12
        return xp.stack([(m1 + m2) * self.g * self.l1 * c1 + g2, g2], axis=-1)

    def friction(self, dq: Array, phi: Array) -> Array:
        return phi[..., 2:4] * dq if self.friction_terms else 0.0 * dq + 0.0 * phi[..., :1]

    def regressor(self, q: Array, dq: Array, v: Array, a: Array) -> Array:
        """Y of docs/laws.md#robots (general two-slot form), plus diag(q̇) friction columns."""
        xp = array_namespace(q, dq, v, a)
        c1, c2, s2, c12 = self._trig(q)
        l1, l2, g = self.l1, self.l2, self.g
        h = l1 * l2
        a1, a2, v1, v2, dq1, dq2 = a[..., 0], a[..., 1], v[..., 0], v[..., 1], dq[..., 0], dq[..., 1]
        y11 = l1**2 * a1 + l1 * g * c1
        y12 = ((l1**2 + l2**2 + 2 * h * c2) * a1 + (l2**2 + h * c2) * a2 - h * s2 * dq2 * v1
               - h * s2 * (dq1 + dq2) * v2 + l1 * g * c1 + l2 * g * c12)
        y22 = (l2**2 + h * c2) * a1 + l2**2 * a2 + h * s2 * dq1 * v1 + l2 * g * c12
        zero = 0.0 * y11
        rows = [[y11, y12], [zero, y22]]
        if self.friction_terms:
            rows = [[y11, y12, dq1, zero], [zero, y22, zero, dq2]]
        return matrix(xp, rows)

    def remainder_regressor(self, q: Array, dq: Array) -> Array:
        """Y_g of docs/laws.md#robots: `Y_g φ = −V_mᵀ q̇ + G + F`."""
        xp = array_namespace(q, dq)
        c1, _, s2, c12 = self._trig(q)
        l1, l2, g = self.l1, self.l2, self.g
        dq1, dq2 = dq[..., 0], dq[..., 1]
        zero = 0.0 * (c1 + dq1)
        y11 = g * l1 * c1 + zero
        rows = [[y11, y11 + g * l2 * c12], [zero, l1 * l2 * s2 * (dq1**2 + dq1 * dq2) + g * l2 * c12]]
        if self.friction_terms:
            rows = [rows[0] + [dq1, zero], rows[1] + [zero, dq2]]
        return matrix(xp, rows)

    @property
    def _hand_links(self) -> tuple[tuple[str, float], ...]:
        return (("l1", self.l1), ("l2", self.l2))
