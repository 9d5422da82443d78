"""The robot-model contract: rigid-body dynamics linear in a parameter vector φ (docs/laws.md#model).

    τ = M(q) q̈ + V_m(q, q̇) q̇ + G(q) + F(q̇)                       (6.2.1)
    M(q) a + V_m(q, q̇) v + G(q) + F(q̇) = Y(q, q̇, v, a) φ          (P3, the "two-slot" regressor)

Task space (DESIGN "Task space"): `hand` gives the hand frame's pose, geometric Jacobian and its rate, `kinematic_basis`
and `kinematic_regressor` the position linear in kinematic parameters (Cheah, Liu & Slotine 2006; :mod:`.hand`).

Every method accepts leading batch axes: `q, dq, v, a` have shape `(..., n)`, `phi` `(..., p)` (or `(p,)`), and outputs
carry exactly the broadcast leading axes. Models are pure: the parameters are arguments, never state.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np

from ..arrays import array_namespace, matvec, solve
from ..pytree import Module
from ..validation import ConfigError
from .hand import Hand, KinematicBasis

Array = Any


class RobotModel(Module, ABC):
    """Abstract rigid manipulator. Subclasses give the closed forms; the dynamics below are shared."""

    #: the model's own parameter values (published, or from its URDF), used when a scenario gives no plant.phi;
    #: None for the textbook arms, whose parameters the scenario always states
    default_phi: Any = None
    #: True when every method is written with the array API of its inputs, so that JAX can trace it (the compiled
    #: engine); False for models that call out to compiled code of their own (Pinocchio's C++)
    traceable: ClassVar[bool] = True

    @property
    @abstractmethod
    def n(self) -> int:
        """Number of joints."""

    @property
    @abstractmethod
    def param_names(self) -> tuple[str, ...]:
        """Names of the entries of φ, in order."""

    @property
    def p(self) -> int:
        """Number of parameters, `len(param_names)`."""
        return len(self.param_names)

    @abstractmethod
    def mass_matrix(self, q: Array, phi: Array) -> Array:
        """M(q), symmetric positive definite, shape `(..., n, n)` (property P1)."""

    @abstractmethod
    def coriolis_matrix(self, q: Array, dq: Array, phi: Array) -> Array:
        """V_m(q, q̇) in Christoffel form, so that Ṁ − 2V_m is skew-symmetric (property P2), shape `(..., n, n)`."""

    @abstractmethod
    def gravity(self, q: Array, phi: Array) -> Array:
        """G(q), shape `(..., n)`."""

    @abstractmethod
    def friction(self, dq: Array, phi: Array) -> Array:
        """F(q̇), shape `(..., n)`."""

    @abstractmethod
    def regressor(self, q: Array, dq: Array, v: Array, a: Array) -> Array:
        """Y(q, q̇, v, a) of shape `(..., n, p)` with `Y φ = M(q) a + V_m(q, q̇) v + G(q) + F(q̇)` (P3)."""

    def regressor_products(self, q: Array, dq: Array, v: Array, a: Array, phi: Array, r: Array) -> tuple[Array, Array]:
        """(Y φ, Yᵀ r) for Y = Y(q, q̇, v, a) (P3): what an adaptive law with Table 6.3.1's torque needs of Y, (6.3.11)
        and (6.3.16). Generic form: through Y; an n-DOF model computes both without forming Y."""
        Y = self.regressor(q, dq, v, a)
        return matvec(Y, phi), matvec(Y.mT, r)

    def remainder_regressor(self, q: Array, dq: Array) -> Array:
        """Y_g(q, q̇) with `Y_g φ = −Ṁ q̇ + V_m q̇ + G + F = −V_mᵀ q̇ + G + F` (6.6.4), for torque filtering.

        Generic form: Y(q, q̇, q̇, 0) minus the regressor of Ṁ q̇, the derivative of Y_h along q̇ by central differences
        (relative error ~1e-9). The textbook arms override it with closed forms.
        """
        xp = array_namespace(q, dq)
        scale = xp.sqrt((dq * dq).sum(axis=-1, keepdims=True)) + 1.0
        h = 1e-5 / scale
        Mdot = (self.momentum_regressor(q + h * dq, dq) - self.momentum_regressor(q - h * dq, dq)) / (2 * h[..., None])
        return self.regressor(q, dq, dq, 0.0 * dq) - Mdot

    def momentum_regressor(self, q: Array, dq: Array) -> Array:
        """Y_h(q, q̇) with `Y_h φ = M(q) q̇` (6.6.3): the a-slot of Y with gravity and friction cancelled."""
        zero = 0.0 * dq
        return self.regressor(q, zero, zero, dq) - self.regressor(q, zero, zero, zero)

    def inverse_dynamics(self, q: Array, dq: Array, ddq: Array, phi: Array) -> Array:
        """τ = M q̈ + V_m q̇ + G + F (6.2.1), through the regressor."""
        return matvec(self.regressor(q, dq, dq, ddq), phi)

    def forward_dynamics(self, q: Array, dq: Array, tau: Array, phi: Array) -> Array:
        """q̈ = M(q)⁻¹ (τ − V_m q̇ − G − F)."""
        xp = array_namespace(q, dq, tau)
        bias = matvec(self.regressor(q, dq, dq, 0.0 * dq), phi)
        return solve(xp, self.mass_matrix(q, phi), tau - bias)

    # -- task space -----------------------------------------------------------------------------------------------------

    @property
    def task_axes(self) -> tuple[int, ...]:
        """The position rows a task uses: (0, 1, 2); (0, 1) for an arm whose hand moves in the x–y plane."""
        return (0, 1, 2)

    def hand(self, q: Array, dq: Array, tool: Array | None = None) -> Hand:
        """The hand frame at (q, q̇): the last link's frame offset by `tool` (3,) in its axes (m; None: zero):
        position, orientation, geometric Jacobian J (rows: linear velocity of the origin, angular velocity; world axes)
        and J̇ at (q, q̇), so that the hand's classical acceleration is J q̈ + J̇ q̇ (:class:`.hand.Hand`)."""
        raise NotImplementedError(self._no_hand())

    def kinematic_names(self, tool: Array | None = None) -> tuple[str, ...]:
        """Every candidate kinematic parameter of the hand position, in order ("tool.x", "tool.y", "tool.z" last when
        a tool is given)."""
        raise NotImplementedError(self._no_hand())

    def kinematic_values(self, tool: Array | None = None) -> Array:
        """The true values (m) of `kinematic_names(tool)`, in order."""
        raise NotImplementedError(self._no_hand())

    def _kinematic_columns(self, q: Array, dq: Array, tool: Array | None) -> tuple[Hand, Array, Array, Array]:
        """(the hand, and for every kinematic parameter j its columns h_j `(..., k, 3)`, B_j `(..., k, 3, n)`, Ḃ_j):
        the parts of p, J_v and J̇_v that θ_k,j multiplies; the rest (prismatic travel) is what they leave."""
        raise NotImplementedError(self._no_hand())

    def _no_hand(self) -> str:
        return (f"{type(self).__name__} has no hand frame: task-space kinematics (hand, kinematic_basis) are on "
                "KinematicTree (robotadapt.robots.kinematic_tree: URDF and DH arms), SymbolicArm and the book's arms")

    def kinematic_basis(self, q: Array, dq: Array, tool: Array | None = None,
                        unknown: tuple[str, ...] | None = None) -> KinematicBasis:
        """The hand position linear in the parameters named in `unknown` (default: every `kinematic_names(tool)`), in
        that order: p = h[0] + Σ_j θ_k[j] h[j+1], J_v = B[0] + Σ_j θ_k[j] B[j+1], dB its rate (Cheah, Liu & Slotine
        2006). Index 0 is the rest at the model's values: the known parameters folded in, and what no parameter
        multiplies (prismatic travel)."""
        names = self.kinematic_names(tool)
        wanted = names if unknown is None else tuple(unknown)
        missing = [name for name in wanted if name not in names]
        if missing or len(set(wanted)) != len(wanted):
            raise ConfigError("unknown", f"expected distinct names among {', '.join(names) or '(none)'}; got "
                              f"{', '.join(map(repr, wanted))}")
        hand, h, B, dB = self._kinematic_columns(q, dq, tool)
        xp = array_namespace(h, B, dB)
        pick = np.array([names.index(name) for name in wanted], dtype=int)
        theta = xp.take(xp.asarray(self.kinematic_values(tool)), pick, axis=-1)
        h, B, dB = xp.take(h, pick, axis=-2), xp.take(B, pick, axis=-3), xp.take(dB, pick, axis=-3)
        h0 = hand.p - (theta[:, None] * h).sum(axis=-2)
        B0 = hand.J[..., :3, :] - (theta[:, None, None] * B).sum(axis=-3)
        dB0 = hand.dJ[..., :3, :] - (theta[:, None, None] * dB).sum(axis=-3)
        lead = hand.J.shape[:-2]  # the broadcast leading axes of q and q̇

        def on(x: Array, k: int) -> Array:
            return xp.broadcast_to(x, lead + x.shape[x.ndim - k :])

        return KinematicBasis(xp.concat([on(h0[..., None, :], 2), on(h, 2)], axis=-2),
                              xp.concat([on(B0[..., None, :, :], 3), on(B, 3)], axis=-3),
                              xp.concat([on(dB0[..., None, :, :], 3), on(dB, 3)], axis=-3))

    def kinematic_regressor(self, q: Array, dq: Array, tool: Array | None = None,
                            unknown: tuple[str, ...] | None = None) -> tuple[Array, Array]:
        """(Y_k `(..., 3, k)`, known `(..., 3)`) with ẋ = J_v q̇ = Y_k θ_k + known: Y_k[:, j] = B[j+1] q̇ and
        known = B[0] q̇ of :meth:`kinematic_basis` (Cheah, Liu & Slotine 2006)."""
        B = self.kinematic_basis(q, dq, tool, unknown).B
        Bq = (B * dq[..., None, None, :]).sum(axis=-1)  # (..., k+1, 3)
        xp = array_namespace(Bq)
        return xp.swapaxes(Bq[..., 1:, :], -1, -2), Bq[..., 0, :]
