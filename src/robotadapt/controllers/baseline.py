"""Non-adaptive baselines: PD, PD plus gravity (6.3.5) and computed torque with fixed estimates (6.2.2)."""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from ..arrays import matvec
from ..robots.base import RobotModel
from ..trajectories import Reference
from .base import Array, FixedEstimate, errors, estimate, gains
from .registry import Contender


@dataclass(frozen=True, eq=False)
class _Fixed(FixedEstimate):
    """Shared parts of controllers whose estimate φ̂ is a constant (no state)."""

    tuned = ("Kp", "Kv")

    model: RobotModel
    Kp: Any
    Kv: Any
    phi_hat0: Any

    def __post_init__(self) -> None:
        gains(self, ("Kp", "Kv"), self.model.n)
        estimate(self)

    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """r = ė + K_v⁻¹K_p e: the PD law's own filtered error (K_p = K_v Λ)."""
        e, de = errors(q, dq, ref)
        return de + e @ np.linalg.solve(self.Kv, self.Kp).T


@dataclass(frozen=True, eq=False)
class PD(_Fixed):
    """τ = K_p e + K_v ė. No model knowledge; `phi_hat0` is only reported (pass zeros)."""

    kind = "pd"
    family = "6"
    lineup = (Contender("pd", "PD", "baseline", "K_p = K_v Λ, K_v of Example 6.3.1", {"kind": "pd", "Kp": 25.0, "Kv": 10.0},
                        rank=30),)

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        e, de = errors(q, dq, ref)
        return e @ self.Kp.T + de @ self.Kv.T, 0.0 * x + 0.0 * q[..., :0]


@dataclass(frozen=True, eq=False)
class PDGravity(_Fixed):
    """PD plus gravity and friction compensation with fixed estimates (Arimoto & Miyazaki; 6.3.5):
    τ = K_p e + K_v ė + Ĝ(q) + F̂(q̇). For a set point (q̇_d = 0) this is the book's (6.3.5), stable by LaSalle."""

    kind = "pd_gravity"
    nominal = True
    family = "6"
    lineup = (Contender("pd_gravity", "PD + gravity, fixed φ̂", "(6.3.5)", "K_p = K_v Λ, K_v of Example 6.3.1",
                        {"kind": "pd_gravity", "Kp": 25.0, "Kv": 10.0}, rank=40),)

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        e, de = errors(q, dq, ref)
        comp = self.model.gravity(q, self.phi_hat0) + self.model.friction(dq, self.phi_hat0)
        return e @ self.Kp.T + de @ self.Kv.T + comp, 0.0 * x + 0.0 * q[..., :0]


@dataclass(frozen=True, eq=False)
class ComputedTorque(_Fixed):
    """Computed torque with fixed estimates (6.2.2; Example 6.2.1):
    τ = M̂(q)(q̈_d + K_v ė + K_p e) + V̂_m q̇ + Ĝ + F̂ = Y(q, q̇, q̇, q̈_d + K_v ė + K_p e) φ̂.
    With φ̂ ≠ φ the error obeys ë + K_v ė + K_p e = M̂⁻¹ W φ̃ and stays bounded without decaying."""

    kind = "computed_torque"
    nominal = True
    powers = MappingProxyType({})  # K_p, K_v act through M̂ (6.2.2): rates, whatever the arm's scale
    lineup = (Contender("computed_torque", "computed torque, fixed φ̂", "(6.2.2)", "Example 6.2.1's K_p, K_v",
                        {"kind": "computed_torque", "Kp": 4.0, "Kv": 4.0}, rank=20),)

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        e, de = errors(q, dq, ref)
        u = ref.ddq_des + de @ self.Kv.T + e @ self.Kp.T
        return matvec(self.model.regressor(q, dq, dq, u), self.phi_hat0), 0.0 * x + 0.0 * q[..., :0]
