"""Repetitive (learning) control law of Sadegh, Horowitz, Kao & Tomizuka (docs/laws.md#repetitive, Table 7.2.2)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .._array import array_namespace
from ..robots.base import RobotModel
from ..trajectories import Reference
from ..validation import ConfigError, as_scalar, as_vector
from .base import Array, errors


@dataclass(frozen=True, eq=False)
class Repetitive:
    """Repetitive control law (Table 7.2.2) for a T-periodic desired trajectory:

    r = ė + e,   τ = û_d(t) + k_v r + k_p e + k_a ‖e‖² r                                     (7.2.31)
    û_d(t) = û_d(t − T) + k_L r(t)                     (plain learning law, 7.2.32)
    û_d(t) = sat(û_d(t − T)) + k_L r(t)                (saturated form of Problem 7.2-4, with `u_min`, `u_max`)

    û_d learns the repeatable dynamics u_d(t) = Y_d φ (7.2.29) with no regressor and no model. û_d(t − T) is read from a
    delay line of N = T/dt samples (the step must divide the period) and held over each step; û_d = 0 on [−T, 0).
    The saturation bounds must contain u_d(t) along the trajectory. `period` defaults to the trajectory's own.
    Guarantee: e → 0, ė bounded (→ 0 with the saturated form).
    """

    model: RobotModel
    Kv: Any
    Kp: Any
    Ka: Any
    kL: Any
    period: Any = None
    u_min: Any = None
    u_max: Any = None

    def __post_init__(self) -> None:
        for name in ("Kv", "Kp", "Ka", "kL"):
            object.__setattr__(self, name, as_scalar(getattr(self, name), f"controller.{name}", positive=True))
        if self.period is not None:
            object.__setattr__(self, "period", as_scalar(self.period, "controller.period", positive=True))
        if (self.u_min is None) != (self.u_max is None):
            raise ConfigError("controller.u_min", "give both u_min and u_max for the saturated law, or neither")
        if self.u_min is not None:
            lo = as_vector(self.u_min, self.model.n, "controller.u_min")
            hi = as_vector(self.u_max, self.model.n, "controller.u_max")
            if not np.all(lo < hi):
                raise ConfigError("controller.u_max", f"must exceed u_min component-wise, got {lo} and {hi}")
            object.__setattr__(self, "u_min", lo)
            object.__setattr__(self, "u_max", hi)

    @property
    def state_names(self) -> tuple[str, ...]:
        return tuple(f"u_hat_past{i + 1}" for i in range(self.model.n))

    def initial_state(self, q0: Array, dq0: Array) -> Array:
        return np.zeros(self.model.n)

    def phi_hat(self, x: Array) -> Array:
        """No parameter estimate: the law learns a signal, not φ."""
        return x[..., :0]

    def prepare(self, trajectory: Any, dt: float, t_final: float) -> Repetitive:
        """Take the period from the trajectory when none is given; check that the trajectory repeats with it (7.2.30)
        and that the step divides it."""
        declares = hasattr(trajectory, "period")  # a trajectory class without the attribute: trust `period`
        own: float | None = trajectory.period if declares else None
        if declares and own is None:
            raise ConfigError("controller.period", "the desired trajectory is not periodic: the repetitive law needs "
                              "q_d(t) = q_d(t − T) (7.2.30)")
        period: float | None = self.period if self.period is not None else own
        if period is None:
            raise ConfigError("controller.period", "give controller.period: the trajectory does not say its period")
        if own is not None and abs(period / own - round(period / own)) > 1e-9 * period / own:
            raise ConfigError("controller.period", f"T = {period:.10g} s is not a multiple of the trajectory's period "
                              f"{own:.10g} s")
        steps = period / dt
        if abs(steps - round(steps)) > 1e-6 * steps:
            raise ConfigError("simulation.dt", f"the period T = {period:.10g} s must be a whole number of steps; "
                              f"use dt = T/N, e.g. dt = {period / max(round(steps), 1):.17g}")
        return replace(self, period=period)

    def delay_line(self, dt: float, q0: Array, dq0: Array) -> Array:
        """û_d on [−T, 0): zeros, N = T/dt samples."""
        return np.zeros((round(self.period / dt), self.model.n))

    def sample(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, past: Array) -> tuple[Array, Array]:
        """Hold sat(û_d(t − T)) for this step; store û_d(t) = that + k_L r(t). Pure (array API): the simulator keeps
        the line in its carried state, numpy or compiled."""
        held = past if self.u_min is None else array_namespace(past).clip(past, self.u_min, self.u_max)
        return held, held + self.kL * self.filtered_error(t, x, q, dq, ref)

    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        e, de = errors(q, dq, ref)
        return de + e

    def learned(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """û_d(t) = (held past value) + k_L r(t)."""
        return x + self.kL * self.filtered_error(t, x, q, dq, ref)

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
        e, de = errors(q, dq, ref)
        r = de + e
        tau = x + self.kL * r + (self.Kv + self.Ka * (e * e).sum(axis=-1, keepdims=True)) * r + self.Kp * e
        return tau, 0.0 * x
