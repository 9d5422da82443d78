"""Two-link polar arm: a revolute joint θ and a prismatic joint r carrying a point mass m (docs/laws.md#polar-arm;
Example 3.2.1).

    m r² θ̈ + 2 m r ṙ θ̇ + m g r cos θ = n,     m r̈ − m r θ̇² + m g sin θ = f

M = diag(m r², m), V_m = m [[r ṙ, r θ̇], [−r θ̇, 0]] (Christoffel), G = [m g r cos θ, m g sin θ]. φ = [m]
(+ [fv1, fv2] with `friction_terms=True`). M is singular at r = 0: keep the desired extension away from it.

The hand is the mass, in the radial link's frame Rz(θ): p = r [cos θ, sin θ, 0] (+ R tool). The radial distance is the
joint variable, so the arm has no kinematic parameter but a tool offset's (tool.x adds to r).
"""

from __future__ import annotations

from dataclasses import dataclass

from ..arrays import array_namespace, matrix, vector
from ..validation import as_scalar, check_switch
from .base import Array, RobotModel
from .hand import Hand, TaskKinematics, hand_on, planar_axes, tool_names, tool_values


@dataclass(frozen=True, eq=False)
class PolarArm(TaskKinematics, RobotModel):
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

    @property
    def task_axes(self) -> tuple[int, ...]:
        return (0, 1)

    def kinematic_names(self, tool: Array | None = None) -> tuple[str, ...]:
        """The tool offset's components, when a tool is given (the arm itself has no kinematic parameter)."""
        return tool_names(tool)

    def kinematic_values(self, tool: Array | None = None) -> Array:
        return tool_values([], tool)

    def hand(self, q: Array, dq: Array, tool: Array | None = None) -> Hand:
        """The frame Rz(θ) at p = r e_r (+ R tool): J_v = [r e_θ, e_r] (+ e_z × R tool in column 1), J_ω = [e_z, 0],
        J̇_v = [ṙ e_θ − r θ̇ e_r, θ̇ e_θ] (+ e_z × (θ̇ e_z × R tool))."""
        return self._kinematic_columns(q, dq, tool)[0]

    def _kinematic_columns(self, q: Array, dq: Array, tool: Array | None) -> tuple[Hand, Array, Array, Array]:
        xp = array_namespace(q, dq)
        r, dth, dr = q[..., 1], dq[..., 0], dq[..., 1]
        W, B, dB = planar_axes(xp, q[..., 0], dth, [1.0, 0.0])  # the frame's axes turn with θ only
        e_r, e_t = W[..., 0, :], W[..., 1, :]
        p = r[..., None] * e_r
        Jv = xp.stack([r[..., None] * e_t, e_r], axis=-1)
        dJv = xp.stack([dr[..., None] * e_t - (r * dth)[..., None] * e_r, dth[..., None] * e_t], axis=-1)
        R = xp.swapaxes(W, -1, -2)
        if tool is None:
            W, B, dB = W[..., :0, :], B[..., :0, :, :], dB[..., :0, :, :]
        else:
            offset = xp.asarray(tool, dtype=W.dtype)
            p = p + (offset[:, None] * W).sum(axis=-2)
            Jv = Jv + (offset[:, None, None] * B).sum(axis=-3)
            dJv = dJv + (offset[:, None, None] * dB).sum(axis=-3)
        Jw = xp.asarray([[0.0, 0.0], [0.0, 0.0], [1.0, 0.0]]) + 0.0 * Jv
        return hand_on(xp, q, dq, p, R, xp.concat([Jv, Jw], axis=-2), xp.concat([dJv, 0.0 * dJv], axis=-2)), W, B, dB
