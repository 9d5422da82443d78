"""One-link arm with viscous friction in a horizontal plane (docs/laws.md#robots; Examples 6.5.1, 6.5.2, 6.6.1–6.6.3).

    τ = m q̈ + b q̇  (+ k q with `stiffness=True`),   φ = [m, b] (or [m, b, k]),   Y(q, q̇, v, a) = [a, q̇ (, q)]

The friction column uses the measured q̇, not v (docs/laws.md#robots). The optional spring term `k q` gives the
three-parameter
model of docs/laws.md#persistency-of-excitation (iii), which one sinusoid cannot excite.

The dynamics have no length; the hand sits at the link's end, `length` = 1 m along the link (a class constant, the
kinematic parameter "l"), in the frame Rz(q): p = l [cos q, sin q, 0] (+ the rotated tool offset).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ..arrays import array_namespace, matrix, vector
from ..validation import check_switch
from .base import Array, RobotModel
from .hand import PlanarChain


@dataclass(frozen=True, eq=False)
class OneLinkArm(PlanarChain, RobotModel):
    """One revolute joint, inertia `m`, viscous friction `b`, no gravity; optional joint stiffness `k`."""

    stiffness: bool = False
    #: the link's length (m) to the hand: the kinematic parameter "l" (the dynamics do not depend on it)
    length: ClassVar[float] = 1.0

    def __post_init__(self) -> None:
        check_switch(self.stiffness, "robot.stiffness")

    @property
    def n(self) -> int:
        return 1

    @property
    def param_names(self) -> tuple[str, ...]:
        return ("m", "b", "k") if self.stiffness else ("m", "b")

    def mass_matrix(self, q: Array, phi: Array) -> Array:
        return phi[..., 0:1, None] + 0.0 * q[..., None]

    def coriolis_matrix(self, q: Array, dq: Array, phi: Array) -> Array:
        return 0.0 * (q[..., None] + dq[..., None] + phi[..., 0:1, None])

    def gravity(self, q: Array, phi: Array) -> Array:
        return phi[..., 2:3] * q if self.stiffness else 0.0 * (q + phi[..., 0:1])

    def friction(self, dq: Array, phi: Array) -> Array:
        return phi[..., 1:2] * dq

    def regressor(self, q: Array, dq: Array, v: Array, a: Array) -> Array:
        xp = array_namespace(q, dq, v, a)
        cols = [a[..., 0], dq[..., 0]] + ([q[..., 0]] if self.stiffness else [])
        return matrix(xp, [cols]) + 0.0 * (q[..., None] + v[..., None])

    def remainder_regressor(self, q: Array, dq: Array) -> Array:
        xp = array_namespace(q, dq)
        cols = [0.0 * q[..., 0], dq[..., 0]] + ([q[..., 0]] if self.stiffness else [])
        return vector(xp, cols)[..., None, :]

    @property
    def _hand_links(self) -> tuple[tuple[str, float], ...]:
        return (("l", self.length),)
