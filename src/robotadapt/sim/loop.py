"""The closed loop, defined once (DESIGN "Simulation"): the state layout z = [s, x], the vector field dz/dt = f(t, z)
(:class:`ClosedLoop`), the one RK4 step every fixed-step path takes (numpy, batches, the compiled engine), the delay line
of a law with one (HasDelayLine), and the divergence guard.

State z = [s, x]: the plant's state s = [q, q̇] (then θ, θ̇ of elastic joints and the motor currents, see
:mod:`robotadapt.plant`) and the controller's x.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._array import array_namespace
from ..controllers.base import FiltersTorque, HasProjection, NeedsAcceleration
from ..plant.plant import Plant
from ..trajectories import Reference

Array = Any
CHUNK = 2048  # steps whose reference is evaluated in one vectorized call
MAX_LOG_BYTES = 4e9


@dataclass(frozen=True, eq=False)
class ClosedLoop:
    """The closed-loop vector field dz/dt = f(t, z), z = [s, x]; the plant receives the saturated torque. Controllers
    that need q̈ get the plant's acceleration for the torque they just applied (no algebraic loop: their torque does not
    depend on q̈). A law that filters the torque (FiltersTorque) is given the torque the plant receives."""

    plant: Plant
    controller: Any  # a Controller, or a NeedsAcceleration law (torque, then update with the plant's q̈)
    n: int
    needs_acceleration: bool = field(init=False)
    m: int = field(init=False)  # the plant's state size, 2n + its extra states
    rigid: bool = field(init=False)  # no extra plant states: the fast path
    filters_torque: bool = field(init=False)  # the law filters the applied torque, and an actuator may change it

    def __post_init__(self) -> None:  # a protocol check costs microseconds: once, not per evaluation
        object.__setattr__(self, "needs_acceleration", isinstance(self.controller, NeedsAcceleration))
        object.__setattr__(self, "filters_torque", isinstance(self.controller, FiltersTorque)
                           and self.plant.actuator is not None)
        object.__setattr__(self, "m", 2 * self.n + self.plant.n_extra)
        object.__setattr__(self, "rigid", self.plant.n_extra == 0)

    def split(self, z: Array) -> tuple[Array, Array, Array]:
        n = self.n
        return z[..., :n], z[..., n : 2 * n], z[..., self.m :]

    def torque(self, t: Array, z: Array, ref: Reference) -> Array:
        """The controller's commanded torque (before the actuator's saturation)."""
        q, dq, x = self.split(z)
        if self.needs_acceleration:
            return self.controller.torque(t, x, q, dq, ref)
        return self.controller(t, x, q, dq, ref)[0]

    def _plant(self, t: Array, z: Array, q: Array, dq: Array, u: Array) -> tuple[Array, Array]:
        """(the plant's ds/dt without q̇, q̈) for the applied torque."""
        if self.rigid:
            return dq, self.plant.acceleration(t, q, dq, u)
        ds = self.plant.derivative(t, z[..., : self.m], u)
        return ds, ds[..., self.n : 2 * self.n]

    def __call__(self, t: Array, z: Array, ref: Reference) -> Array:
        q, dq, x = self.split(z)
        if self.needs_acceleration:
            tau = self.controller.torque(t, x, q, dq, ref)
            head, ddq = self._plant(t, z, q, dq, self.plant.saturate(tau))
            dx = self.controller.update(t, x, q, dq, ddq, ref)
        else:
            tau, dx = self.controller(t, x, q, dq, ref)
            u = self.plant.saturate(tau)
            if self.filters_torque:
                dx = self.controller.applied(dx, tau, u)
            head, ddq = self._plant(t, z, q, dq, u)
        return array_namespace(z).concatenate([head, ddq, dx] if self.rigid else [head, dx], axis=-1)

    def project(self, z: Array) -> Array:
        if not isinstance(self.controller, HasProjection):
            return z
        return array_namespace(z).concatenate([z[..., : self.m], self.controller.project(z[..., self.m :])], axis=-1)


REASONS = {1: "non-finite state", 2: "state exceeded {max_state:g} in magnitude"}  # why the divergence guard stopped


def diverged_status(t: float, why: int, max_state: float) -> str:
    """The status of a run the compiled guard stopped at `t` for reason code `why` (a key of `REASONS`; 0: none)."""
    return f"diverged at t={t:.6g} s: " + REASONS[why].format(max_state=max_state) if why else "ok"


def diverged(z: Array, max_state: float) -> str | None:
    if not np.all(np.isfinite(z)):
        return REASONS[1]
    if np.max(np.abs(z)) > max_state:
        return REASONS[2].format(max_state=max_state)
    return None


def take(ref: Reference, i: int) -> Reference:
    return Reference(ref.q_des[i], ref.dq_des[i], ref.ddq_des[i])


@dataclass
class DelayLine:
    """The ring buffer of a controller with a delay line (HasDelayLine), owned here so the controller stays pure.

    The law gets a copy of the slot it reads: a view would let the write that follows change the value it holds."""

    buffer: Array

    def advance(self, controller: Any, k: int, t: float, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """The controller's state for step (or tick) k, reading and writing slot k mod N."""
        slot = k % self.buffer.shape[0]
        x_new, store = controller.sample(t, x, q, dq, ref, self.buffer[slot].copy())
        self.buffer[slot] = store
        return x_new

    def sample(self, loop: ClosedLoop, k: int, t: float, z: Array, ref: Reference) -> Array:
        q, dq, x = loop.split(z)
        return np.concatenate([z[..., : loop.m], self.advance(loop.controller, k, t, x, q, dq, ref)], axis=-1)


def rk4_step(loop: ClosedLoop, t: float, z: Array, dt: float, r0: Reference, rh: Reference, r1: Reference) -> Array:
    k1 = loop(t, z, r0)
    k2 = loop(t + 0.5 * dt, z + 0.5 * dt * k1, rh)
    k3 = loop(t + 0.5 * dt, z + 0.5 * dt * k2, rh)
    k4 = loop(t + dt, z + dt * k3, r1)
    return loop.project(z + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4))
