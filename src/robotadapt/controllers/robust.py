"""Torque-based disturbance rejection of Slotine & Li (1985c): an adaptive law plus k_d sgn(r)
(docs/laws.md#sign-robust–7.2; §6.7).

With an additive bounded disturbance (6.7.1) the Slotine–Li Lyapunov function (6.3.7) only gives
V̇ = −rᵀK_v r + rᵀT_d (6.7.2): r stays bounded but e no longer goes to zero and φ̂ may drift (Example 6.7.1). A
switching term larger than the disturbance restores V̇ ≤ −rᵀK_v r (6.7.12) and hence e → 0 (Example 6.7.2).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, replace
from typing import Any, ClassVar

import numpy as np

from ..arrays import array_namespace
from ..robots.base import RobotModel
from ..trajectories import Reference
from ..validation import ConfigError, as_scalar, as_vector
from .base import Array, Law, freeze
from .registry import Contender


@dataclass(frozen=True, eq=False)
class SignRobust(Law):
    """An adaptive controller `base` with a filtered error r, plus the disturbance-rejecting switching term:

    τ = τ_a + k_d sgn(r),  sgn(r) = [sgn(r_1), …, sgn(r_n)]ᵀ,  sgn(0) = 0           (6.7.6), (6.7.7)

    where τ_a and the update law are the base's, unchanged (Table 6.3.1 for Slotine–Li). With V the base's Lyapunov
    function (6.3.7) and a plant with disturbance T_d (6.7.1),

    V̇ = −rᵀK_v r + rᵀT_d − Σ_i k_d,i |r_i| ≤ −rᵀK_v r + Σ_i |r_i| (|T_d,i| − k_d,i)   (6.7.9)–(6.7.11)

    so k_d,i > sup_t |T_d,i| (the book's scalar k_d > max_i sup |T_d,i|, (6.7.8)) gives V̇ ≤ −rᵀK_v r (6.7.12):
    r ∈ L2, e → 0, φ̂ bounded. `kd` is a scalar (the book) or one value per joint, each ≥ 0; `kd = 0` is the base.

    `boundary_layer` ε > 0 replaces sgn(r_i) by sat(r_i/ε) to soften the chattering of the switching torque. This
    changes the theory (docs/laws.md#sign-robust): inside the layer the term is only the linear k_d r_i/ε, so
    (6.7.11) becomes
    V̇ ≤ −rᵀK_v r + ε Σ_i sup|T_d,i|² / (4 k_d,i), and only a residual set is guaranteed (the time average of ‖r‖²
    is O(ε); in practice |r_i| ≲ ε): e no longer goes exactly to zero.

    Everything else is the base's, forwarded hook by hook (:class:`~robotadapt.controllers.base.Law`): the state x,
    φ̂, the filtered error, the Lyapunov function, the regressor (for the passivity integral (6.4.4)), the φ̂ the torque
    uses (Landau's PI law, (6.4.20)), a projection, tables prepared ahead of the run.
    """

    #: constants tuning leaves alone, with why (robotadapt.studies.gain_space.locate)
    untuned: ClassVar[dict[str, str]] = {"kd": "is set above the disturbance's bound (6.7.8), not tuned for the error; "
                                               "tune the base law's gains (controller.base.Kv, ...)"}
    kind = "sign_robust"
    family = "6"
    lineup = (Contender("sign_robust", "Slotine–Li + k_d sgn(r)", "(6.7.6)", "Example 6.7.2 (k_d = 2.2)",
                        {"kind": "sign_robust", "kd": 2.2, "boundary_layer": 0.0,
                         "base": {"kind": "slotine_li", "Lam": 2.5, "Kv": 10.0, "Gamma": 20.0}}, rank=80),)

    model: RobotModel
    base: Any
    kd: Any
    boundary_layer: Any = 0.0

    def __post_init__(self) -> None:
        base = self.base
        if not isinstance(base, Law) or not base.has("filtered_error"):  # an argument check: what it wraps
            raise ConfigError("controller.base", "expected an adaptive controller with a filtered error r (such as "
                              f"slotine_li), got {type(base).__name__}")
        if base.needs_acceleration:
            raise ConfigError("controller.base", f"{type(base).__name__} needs the measured acceleration; the sign term "
                              "(6.7.6) wraps laws whose torque and update are one map, such as slotine_li")
        if base.model is not self.model and (base.model.n, base.model.param_names) != (self.model.n,
                                                                                        self.model.param_names):
            raise ConfigError("controller.base", f"the base's model ({base.model.n} joints, parameters "
                              f"{', '.join(base.model.param_names)}) differs from the robot's ({self.model.n} joints, "
                              f"{', '.join(self.model.param_names)})")
        kd = as_vector(self.kd, self.model.n, "controller.kd")
        if not np.all(kd >= 0):
            raise ConfigError("controller.kd", f"must be zero or positive (above sup |T_d,i|, (6.7.8)), got {kd.tolist()}")
        freeze(self, kd=kd, boundary_layer=as_scalar(self.boundary_layer, "controller.boundary_layer",
                                                     nonnegative=True))

    # Everything but the torque is the base's, forwarded hook by hook (robotadapt.controllers.base.Law).
    def has(self, hook: str) -> bool:
        return self.base.has(hook)

    @property
    def records(self) -> int:
        return self.base.records

    def prepare(self, trajectory: Any, dt: float, t_final: float) -> SignRobust:
        """The wrapper around the prepared base."""
        base = self.base.prepare(trajectory, dt, t_final)
        return self if base is self.base else replace(self, base=base)

    def guard(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array | None:
        return self.base.guard(t, x, q, dq, ref)

    def stop_reason(self, q: Array, x: Array) -> str:
        return self.base.stop_reason(q, x)

    def project(self, x: Array) -> Array:
        return self.base.project(x)

    def applied(self, dx: Array, tau: Array, u: Array) -> Array:
        return self.base.applied(dx, tau, u)

    def delay_line(self, dt: float, q0: Array, dq0: Array) -> Array | None:
        return self.base.delay_line(dt, q0, dq0)

    def sample(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, past: Array) -> tuple[Array, Array]:
        return self.base.sample(t, x, q, dq, ref, past)

    def step(self, x: Array, dx: Array, h: Any) -> Array:
        return self.base.step(x, dx, h)

    def regressor(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array] | None:
        return self.base.regressor(t, x, q, dq, ref)

    def regressor_products(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference,
                           phi: Array) -> tuple[Array, Array, Array]:
        return self.base.regressor_products(t, x, q, dq, ref, phi)

    def lyapunov(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, phi: Array) -> Array | None:
        return self.base.lyapunov(t, x, q, dq, ref, phi)

    def phi_hat_at(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        return self.base.phi_hat_at(t, x, q, dq, ref)

    def passivity_caveat(self) -> str | None:
        return self.base.passivity_caveat()

    def lyapunov_caveat(self) -> str | None:
        return self.base.lyapunov_caveat()

    def monitors(self, x: Array, q: Array) -> dict[str, Array]:
        return self.base.monitors(x, q)

    @property
    def state_names(self) -> tuple[str, ...]:
        return self.base.state_names

    def initial_state(self, q0: Array, dq0: Array) -> Array:
        return self.base.initial_state(q0, dq0)

    def phi_hat(self, x: Array) -> Array:
        return self.base.phi_hat(x)

    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        return self.base.filtered_error(t, x, q, dq, ref)

    def switching(self, r: Array) -> Array:
        """sgn(r) (6.7.7), or sat(r/ε) with a boundary layer ε > 0, componentwise."""
        xp = array_namespace(r)
        if self.boundary_layer == 0.0:
            return xp.sign(r)
        return xp.clip(r / self.boundary_layer, -1.0, 1.0)

    def surrogate(self, width: float) -> SmoothedSign:
        """The smooth law tuning differentiates in place of this one (docs/tuning.md#switching-laws): sgn(r_i) (or
        sat(r_i/ε)) replaced by tanh(r_i/width), continued toward the exact law as width → 0."""
        fields = {f.name: getattr(self, f.name) for f in dataclasses.fields(SignRobust)}  # a surrogate's own: its law's
        return SmoothedSign(**fields, width=width)

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        tau_a, dx = self.base(t, x, q, dq, ref)
        tau = tau_a + self.kd * self.switching(self.filtered_error(t, x, q, dq, ref))
        return tau, self.base.applied(dx, tau_a, tau)  # a composite base filters the torque applied, sign term included


@dataclass(frozen=True, eq=False)
class SmoothedSign(SignRobust):
    """:class:`SignRobust` with the switching term k_d sgn(r) of (6.7.6) replaced by k_d tanh(r/width): the smooth
    surrogate whose gradient tuning follows, its width (traced, > 0) driven toward zero; the exact law is what the
    tuned gains are scored and checked on (docs/tuning.md#switching-laws)."""

    width: Any = 1.0

    def switching(self, r: Array) -> Array:
        """tanh(r/width), componentwise (→ sgn(r) as width → 0)."""
        return array_namespace(r).tanh(r / self.width)
