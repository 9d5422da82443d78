"""Two-link polar arm: a revolute joint θ and a prismatic joint r carrying a point mass m (docs/laws.md#polar-arm;
Example 3.2.1).

    m r² θ̈ + 2 m r ṙ θ̇ + m g r cos θ = n,     m r̈ − m r θ̇² + m g sin θ = f

M = diag(m r², m), V_m = m [[r ṙ, r θ̇], [−r θ̇, 0]] (Christoffel), G = [m g r cos θ, m g sin θ]. φ = [m]
(+ [fv1, fv2] with `friction_terms=True`). M is singular at r = 0: keep the desired extension away from it.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..arrays import array_namespace, matrix, vector
from ..validation import as_scalar, check_switch
from .base import Array, RobotModel


@dataclass(frozen=True, eq=False)
class PolarArm(RobotModel):
    """Revolute + prismatic arm; `g` in m/s² (the book's 9.8 by default)."""

    g: float = 9.8
    friction_terms: bool = False

    def __post_init__(self) -> None:
        object.__setattr__(self, "g", as_scalar(self.g, "robot.g", nonnegative=True, maximum=1e3))
        check_switch(self.friction_terms, "robot.friction_terms")

    @property
    def n(self) -> int:
        return 2

    @property
    def param_names(self) -> tuple[str, ...]:
        return ("m", "fv1", "fv2") if self.friction_terms else ("m",)

    def mass_matrix(self, q: Array, phi: Array) -> Array:
        xp = array_namespace(q, phi)
        m, r = phi[..., 0], q[..., 1]
        return matrix(xp, [[m * r**2, 0.0 * m * r], [0.0 * m * r, m + 0.0 * r]])

    def coriolis_matrix(self, q: Array, dq: Array, phi: Array) -> Array:
        xp = array_namespace(q, dq, phi)
        m, r, dth, dr = phi[..., 0], q[..., 1], dq[..., 0], dq[..., 1]
        return matrix(xp, [[m * r * dr, m * r * dth], [-m * r * dth, 0.0 * m * r * dth]])

    def gravity(self, q: Array, phi: Array) -> Array:
        xp = array_namespace(q, phi)
        m, th, r = phi[..., 0], q[..., 0], q[..., 1]
        return vector(xp, [m * self.g * r * xp.cos(th), m * self.g * xp.sin(th)])

    def friction(self, dq: Array, phi: Array) -> Array:
        return phi[..., 1:3] * dq if self.friction_terms else 0.0 * dq + 0.0 * phi[..., :1]

    def regressor(self, q: Array, dq: Array, v: Array, a: Array) -> Array:
        """Y = [[r² a1 + r ṙ v1 + r θ̇ v2 + g r cos θ], [a2 − r θ̇ v1 + g sin θ]] (docs/laws.md#polar-arm)."""
        xp = array_namespace(q, dq, v, a)
        th, r, dth, dr = q[..., 0], q[..., 1], dq[..., 0], dq[..., 1]
        y1 = r**2 * a[..., 0] + r * dr * v[..., 0] + r * dth * v[..., 1] + self.g * r * xp.cos(th)
        y2 = a[..., 1] - r * dth * v[..., 0] + self.g * xp.sin(th)
        return self._with_friction(xp, y1, y2, dq)

    def remainder_regressor(self, q: Array, dq: Array) -> Array:
        """Y_g φ = −V_mᵀ q̇ + G + F = m [g r cos θ, −r θ̇² + g sin θ] + F."""
        xp = array_namespace(q, dq)
        th, r, dth = q[..., 0], q[..., 1], dq[..., 0]
        return self._with_friction(xp, self.g * r * xp.cos(th) + 0.0 * dth, -r * dth**2 + self.g * xp.sin(th), dq)

    def _with_friction(self, xp: object, y1: Array, y2: Array, dq: Array) -> Array:
        if not self.friction_terms:
            return matrix(xp, [[y1], [y2]])
        zero = 0.0 * y1
        return matrix(xp, [[y1, dq[..., 0], zero], [y2, zero, dq[..., 1]]])
