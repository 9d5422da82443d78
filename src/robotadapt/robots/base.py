"""The robot-model contract: rigid-body dynamics linear in a parameter vector φ (docs/laws.md#model).

    τ = M(q) q̈ + V_m(q, q̇) q̇ + G(q) + F(q̇)                       (6.2.1)
    M(q) a + V_m(q, q̇) v + G(q) + F(q̇) = Y(q, q̇, v, a) φ          (P3, the "two-slot" regressor)

Task space: a model that has a hand frame is also a :class:`~robotadapt.robots.hand.TaskKinematics` (:mod:`.hand`).

Every method accepts leading batch axes: `q, dq, v, a` have shape `(..., n)`, `phi` `(..., p)` (or `(p,)`), and outputs
carry exactly the broadcast leading axes. Models are pure: the parameters are arguments, never state.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any, ClassVar

from ..arrays import array_namespace, matvec, solve
from ..pytree import Module

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
