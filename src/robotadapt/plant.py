"""The true system a controller acts on: a robot model, its true parameters and an additive disturbance (6.7.1).

    τ = M(q) q̈ + V_m(q, q̇) q̇ + G(q) + F(q̇) + T_d(t, q, q̇)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._array import array_namespace
from .robots.base import RobotModel
from .validation import ConfigError, as_scalar, as_vector

Array = Any
Disturbance = Callable[[Array, Array, Array], Array]


@dataclass(frozen=True, eq=False)
class SinusoidalDisturbance:
    """T_d,i(t) = A_i sin(ω t + φ_i) + b_i (Example 6.7.1 uses A = 2, ω = 10 rad/s on both joints)."""

    amplitude: Array
    omega: float
    phase: Array
    bias: Array

    def __call__(self, t: Array, q: Array, dq: Array) -> Array:
        xp = array_namespace(q)
        tt = xp.asarray(t, dtype=xp.float64)[..., None]
        return self.amplitude * xp.sin(self.omega * tt + self.phase) + self.bias + 0.0 * q

    @property
    def bound(self) -> Array:
        """Component-wise bound sup_t |T_d,i| (what k_d must exceed, 6.7.8)."""
        return np.abs(self.amplitude) + np.abs(self.bias)


def sinusoidal_disturbance(n: int, amplitude: Any = 0.0, omega: Any = 1.0, phase: Any = 0.0,
                           bias: Any = 0.0) -> SinusoidalDisturbance:
    """Validated constructor; `bias` alone gives a constant disturbance (Problem 6.7-1: T_d = [2, 1])."""
    f = "plant.disturbance"
    return SinusoidalDisturbance(as_vector(amplitude, n, f"{f}.amplitude"), as_scalar(omega, f"{f}.omega"),
                                 as_vector(phase, n, f"{f}.phase"), as_vector(bias, n, f"{f}.bias"))


@dataclass(frozen=True, eq=False)
class Plant:
    """`model` with the true parameters `phi` and an optional disturbance `T_d(t, q, q̇)` (torques, shape `(..., n)`)."""

    model: RobotModel
    phi: Any
    disturbance: Disturbance | None = None

    def __post_init__(self) -> None:
        phi = as_vector(self.phi, self.model.p, "plant.phi", broadcast=False)
        object.__setattr__(self, "phi", phi)

    def check_state(self, q: Array) -> None:
        """Raise unless M(q) is positive definite at the initial configuration (negative masses, r = 0, ...)."""
        M = self.model.mass_matrix(np.asarray(q, dtype=float), self.phi)
        eig = np.linalg.eigvalsh(0.5 * (M + np.swapaxes(M, -1, -2)))
        if not np.all(eig > 0):
            names = ", ".join(f"{k}={v:g}" for k, v in zip(self.model.param_names, self.phi, strict=True))
            raise ConfigError("plant.phi", f"the mass matrix is not positive definite at q0 ({names}): "
                              "masses must be positive and the configuration non-singular")

    def acceleration(self, t: Array, q: Array, dq: Array, tau: Array) -> Array:
        """q̈ from (6.7.1): M q̈ = τ − V_m q̇ − G − F − T_d."""
        if self.disturbance is not None:
            tau = tau - self.disturbance(t, q, dq)
        return self.model.forward_dynamics(q, dq, tau, self.phi)
