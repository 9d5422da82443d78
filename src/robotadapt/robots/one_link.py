"""One-link arm with viscous friction in a horizontal plane (docs/laws.md#robots; Examples 6.5.1, 6.5.2, 6.6.1–6.6.3).

    τ = m q̈ + b q̇  (+ k q with `stiffness=True`),   φ = [m, b] (or [m, b, k]),   Y(q, q̇, v, a) = [a, q̇ (, q)]

The friction column uses the measured q̇, not v (docs/laws.md#robots). The optional spring term `k q` gives the
three-parameter
model of docs/laws.md#persistency-of-excitation (iii), which one sinusoid cannot excite.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..arrays import array_namespace, matrix, vector
from ..validation import check_switch
from .base import Array, RobotModel


@dataclass(frozen=True, eq=False)
class OneLinkArm(RobotModel):
    """One revolute joint, inertia `m`, viscous friction `b`, no gravity; optional joint stiffness `k`."""

    stiffness: bool = False

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
