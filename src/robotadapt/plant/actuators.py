"""Between the controller's torque command and the joint: limits, delay (:class:`Actuator`), a DC motor (:class:`DCMotor`).

The actuator acts at the control ticks k (sampled-data mode), in this order:

    τ_k  = command computed d ticks earlier (`delay_samples` = d; zero before the first one arrives)
    u_k  = u_{k−1} + clip(sat(τ_k) − u_{k−1}, −R Ts, R Ts),   sat(τ)_i = clip(τ_i, −L_i, L_i),   u_{−1} = 0

so |u_k| ≤ L and |u_k − u_{k−1}| ≤ R Ts at every tick; u_k is held over [k Ts, (k+1) Ts). In continuous time only the
saturation applies (u = sat(τ)); rate limits and delays need a control period. The actuator is pure: its state (u_{k−1}
and the d commands in flight, oldest first) comes in and goes out, `u, state = actuator.apply(state, τ, Ts)`, written
against the array API of its inputs (numpy, or JAX inside the compiled loop).

The DC motor (per joint, armature resistance R, inductance L, torque constant k_t, back-EMF constant k_b, gear ratio N,
rotor inertia J_m) turns the applied torque command u into a current through a proportional current loop of gain K_c:

    i_ref = u / (N k_t),   v = R i_ref + K_c (i_ref − i)   (clipped to ±`voltage_limit`),
    L di/dt = v − R i − k_b N ω,   τ_joint = N k_t i,   the rotor adding N² J_m to the joint's inertia,

ω the joint-side speed of the motor shaft (q̇, or θ̇ behind an elastic joint). At stall i → i_ref, so τ_joint → u; with
K_c = 0 the drive is an open-loop voltage command v = R u/(N k_t). What the controller's model lacks: the electrical lag
L/(R + K_c), the back-EMF damping k_t k_b N²/(R + K_c) of the joint, the rotor inertia and the voltage limit.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..arrays import array_namespace
from ..pytree import Module
from ..validation import ConfigError, as_vector

Array = Any


def _positive(value: Any, n: int, field: str) -> Array:
    return as_vector(value, n, field, positive=True)


@dataclass(frozen=True, eq=False)
class Actuator(Module):
    """Torque limit L (N m, per joint or one for all), rate limit R (N m/s) and a computational delay of
    `delay_samples` control periods (module docstring). None: no limit."""

    n: int
    torque_limit: Any = None
    torque_rate_limit: Any = None
    delay_samples: int = 0

    def __post_init__(self) -> None:
        if self.torque_limit is not None:
            object.__setattr__(self, "torque_limit", _positive(self.torque_limit, self.n, "plant.torque_limit"))
        if self.torque_rate_limit is not None:
            object.__setattr__(self, "torque_rate_limit",
                               _positive(self.torque_rate_limit, self.n, "plant.torque_rate_limit"))
        d = self.delay_samples
        if isinstance(d, bool) or not isinstance(d, int | np.integer) or not 0 <= d <= 10_000:
            raise ConfigError("plant.delay_samples", f"expected a whole number of control periods from 0 to 10000, "
                              f"got {d!r}")
        object.__setattr__(self, "delay_samples", int(d))

    @property
    def needs_sampling(self) -> bool:
        """True when an effect is defined only at control ticks (rate limit, delay)."""
        return self.torque_rate_limit is not None or self.delay_samples > 0

    def saturate(self, tau: Array) -> Array:
        """sat(τ), or τ itself without a torque limit."""
        if self.torque_limit is None:
            return tau
        return array_namespace(tau).clip(tau, -self.torque_limit, self.torque_limit)

    def start(self) -> tuple[Array, Array]:
        """The state before the first tick: (u_{−1} = 0, the d commands in flight = 0, shape `(d, n)`)."""
        return np.zeros(self.n), np.zeros((self.delay_samples, self.n))

    def apply(self, state: tuple[Array, Array], tau: Array, Ts: float) -> tuple[Array, tuple[Array, Array]]:
        """(u_k, next state) for the command τ computed at this tick; nothing is written in place."""
        u_prev, queue = state
        xp = array_namespace(tau, u_prev)
        if self.delay_samples:
            tau, queue = queue[0], xp.concatenate([queue[1:], tau[None]])
        u = self.saturate(tau)
        if self.torque_rate_limit is not None:
            step = self.torque_rate_limit * Ts
            u = u_prev + xp.clip(u - u_prev, -step, step)
        return u, (u, queue)

    def describe(self) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for name in ("torque_limit", "torque_rate_limit"):
            if getattr(self, name) is not None:
                out[name] = getattr(self, name).tolist()
        if self.delay_samples:
            out["delay_samples"] = self.delay_samples
        return out


@dataclass(frozen=True, eq=False)
class DCMotor(Module):
    """A permanent-magnet DC motor per joint behind a current loop (module docstring). SI units: R (Ω), L (H), k_t
    (N m/A), k_b (V s/rad), gear_ratio N (motor turns per joint turn, > 0), rotor_inertia J_m (kg m², motor side),
    current_gain K_c (V/A, 0: voltage drive), voltage_limit (V, None: none). The plant's state gains the currents i."""

    n: int
    R: Any
    L: Any
    k_t: Any
    k_b: Any
    gear_ratio: Any = 1.0
    rotor_inertia: Any = 0.0
    current_gain: Any = 0.0
    voltage_limit: Any = None
    # J_m ≠ 0 somewhere: a flag, so that a compiled loop, whose float arrays are traced, can still choose the plant's branch
    has_rotor_inertia: bool = field(init=False, repr=False, metadata={"internal": True})

    def __post_init__(self) -> None:
        f = "plant.motor"
        for name in ("R", "L", "k_t", "k_b", "gear_ratio"):
            object.__setattr__(self, name, _positive(getattr(self, name), self.n, f"{f}.{name}"))
        for name in ("rotor_inertia", "current_gain"):
            value = as_vector(getattr(self, name), self.n, f"{f}.{name}")
            if np.any(value < 0):
                raise ConfigError(f"{f}.{name}", f"must be zero or positive, got {value}")
            object.__setattr__(self, name, value)
        if self.voltage_limit is not None:
            object.__setattr__(self, "voltage_limit", _positive(self.voltage_limit, self.n, f"{f}.voltage_limit"))
        object.__setattr__(self, "has_rotor_inertia", bool(np.any(self.rotor_inertia)))

    @property
    def reflected_inertia(self) -> Array:
        """N² J_m (kg m²), the rotor's inertia seen at the joint."""
        return self.gear_ratio**2 * self.rotor_inertia

    @property
    def rate(self) -> float:
        """The fastest electrical rate (R + K_c)/L (1/s)."""
        return float(np.max((self.R + self.current_gain) / self.L))

    def torque(self, i: Array) -> Array:
        """τ_joint = N k_t i."""
        return self.gear_ratio * self.k_t * i

    def current_rate(self, u: Array, i: Array, speed: Array) -> Array:
        """di/dt for the applied torque command u, current i and joint-side shaft speed ω."""
        i_ref = u / (self.gear_ratio * self.k_t)
        v = self.R * i_ref + self.current_gain * (i_ref - i)
        if self.voltage_limit is not None:
            v = array_namespace(v).clip(v, -self.voltage_limit, self.voltage_limit)
        return (v - self.R * i - self.k_b * self.gear_ratio * speed) / self.L

    def describe(self) -> dict[str, Any]:
        out = {name: getattr(self, name).tolist() for name in ("R", "L", "k_t", "k_b", "gear_ratio", "rotor_inertia",
                                                               "current_gain")}
        if self.voltage_limit is not None:
            out["voltage_limit"] = self.voltage_limit.tolist()
        return out
