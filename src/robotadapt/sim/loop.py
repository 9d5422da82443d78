"""The closed loop, defined once (DESIGN "Simulation"): the state layout z = [s, x], the vector field dz/dt = f(t, z)
(:class:`ClosedLoop`), the one fixed step every fixed-step path takes (:func:`step`: numpy, batches, the compiled
engine), the delay line of a law with one (HasDelayLine), the guard of a law with one (HasGuard) and the divergence
guard.

State z = [s, x]: the plant's state s = [q, q̇] (then θ, θ̇ of elastic joints and the motor currents, see
:mod:`robotadapt.plant`) and the controller's x. A fixed-step run carries (z, line, k): the state, the delay line (a
:class:`Ring`, or None) and the step index; :func:`step` maps them to the next ones without writing into any array, so
that the numpy drivers loop over it and the compiled engine scans over it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from .._array import array_namespace
from ..controllers.base import FiltersTorque, HasGuard, HasProjection, NeedsAcceleration
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
    guarded: bool = field(init=False)  # the law has a guard (HasGuard), which traced evaluations read

    def __post_init__(self) -> None:  # a protocol check costs microseconds: once, not per evaluation
        object.__setattr__(self, "needs_acceleration", isinstance(self.controller, NeedsAcceleration))
        object.__setattr__(self, "guarded", isinstance(self.controller, HasGuard))
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

    def rate(self, t: Array, z: Array, ref: Reference) -> tuple[Array, Array | None]:
        """(dz/dt, ok). `ok` is a guarded law's guard (HasGuard) per run on traced arrays, False where its assumption
        fails at z (dz/dt then holds NaN); None otherwise: on numpy arrays such a law raises SimulationStop itself."""
        q, dq, x = self.split(z)
        xp = array_namespace(z)
        ok = self.controller.guard(t, x, q, dq, ref) if self.guarded and xp is not np else None
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
        return xp.concatenate([head, ddq, dx] if self.rigid else [head, dx], axis=-1), ok

    def __call__(self, t: Array, z: Array, ref: Reference) -> Array:
        return self.rate(t, z, ref)[0]

    def stop_reason(self, z: Array) -> str:
        """Why a guarded law stops at the state z (numpy) where its guard fails."""
        q, _, x = self.split(np.asarray(z))
        return str(self.controller.stop_reason(q, x))

    def project(self, z: Array) -> Array:
        if not isinstance(self.controller, HasProjection):
            return z
        return array_namespace(z).concatenate([z[..., : self.m], self.controller.project(z[..., self.m :])], axis=-1)


REASONS = {1: "non-finite state", 2: "state exceeded {max_state:g} in magnitude"}  # why the divergence guard stopped
GUARD = 3  # the reason code of a stop by the law's own guard (HasGuard): the text comes from the law


def diverged_status(t: float, why: int, max_state: float) -> str:
    """The status of a run the compiled guard stopped at `t` for reason code `why` (a key of `REASONS`; 0: none)."""
    return f"diverged at t={t:.6g} s: " + REASONS[why].format(max_state=max_state) if why else "ok"


def within(t: float, dt: float) -> str:
    """Where a run stopped that a law (or the plant) refused inside the step from t to t + dt, at one of its RK4
    stages: the state at t was fine, the one it stopped at is the stage's (the reason names it)."""
    return f"within the step from {t:.6g} to {t + dt:.6g} s"


def stop_status(loop: ClosedLoop, t: float, why: int, max_state: float, z_bad: Array, dt: float) -> str:
    """:func:`diverged_status`, and for `why` = GUARD the law's own reason, from the stage state `z_bad` it failed at
    inside the step from `t` to `t + dt`."""
    if why == GUARD:
        return f"diverged {within(t, dt)}: {loop.stop_reason(z_bad)}"
    return diverged_status(t, why, max_state)


def diverged(z: Array, max_state: float) -> str | None:
    if not np.all(np.isfinite(z)):
        return REASONS[1]
    if np.max(np.abs(z)) > max_state:
        return REASONS[2].format(max_state=max_state)
    return None


def take(ref: Reference, i: int) -> Reference:
    return Reference(ref.q_des[i], ref.dq_des[i], ref.ddq_des[i])


@dataclass(frozen=True)
class DelayLine:
    """The initial contents `(N, ..., n)` of the delay line of a controller with one (HasDelayLine). A run carries the
    line in its state as a :class:`Ring`, written only through :func:`ring_write`, so the controller stays pure."""

    buffer: Array


class Ring(NamedTuple):
    """A delay line as a run carries it: the slots `(N, ..., n)` and `head`, a copy of the slot the next step reads (slot
    k mod N at step k), taken right after the previous step's write. The step then reads no slot of the line it writes
    into, so that XLA updates the line in place inside a compiled loop instead of copying it every step."""

    slots: Array
    head: Array

    @classmethod
    def start(cls, buffer: Array) -> Ring:
        """The line before step 0 from its initial contents."""
        return cls(buffer, ring_read(buffer, 0))


def ring_read(line: Array, slot: Any) -> Array:
    """Row `slot` of `line`, as a copy that no later write can change."""
    if isinstance(line, np.ndarray):
        return line[slot].copy()
    import jax  # only reached with JAX arrays

    return jax.lax.dynamic_index_in_dim(line, slot, 0, keepdims=False)


def ring_write(line: Array, slot: Any, value: Array) -> Array:
    """`line` with row `slot` replaced by `value`, as a new array; `line` itself is never written (numpy: a copy with
    the row set; JAX: `.at[slot].set`, which XLA does in place inside a scan)."""
    if isinstance(line, np.ndarray):
        new = line.copy()
        new[slot] = value
        return new
    return line.at[slot].set(value)


def sample(loop: ClosedLoop, k: Any, t: Any, z: Array, line: Ring, ref: Reference) -> tuple[Array, Ring]:
    """The delay line at the start of step (or the instant) k: the law gets slot k mod N (`line.head`, a copy) and
    returns its state for the step and the value to store in that slot. Returns (z with that state, the line with the
    value stored and the next slot read)."""
    q, dq, x = loop.split(z)
    x_new, store = loop.controller.sample(t, x, q, dq, ref, line.head)
    n = line.slots.shape[0]
    slots = ring_write(line.slots, k % n, store)
    return array_namespace(z, x_new).concatenate([z[..., : loop.m], x_new], axis=-1), Ring(slots,
                                                                                          ring_read(slots, (k + 1) % n))


def rk4_step(loop: ClosedLoop, t: Any, z: Array, dt: float, r0: Reference, rh: Reference,
             r1: Reference) -> tuple[Array, Array | None, Array | None]:
    """One classic RK4 step: (z at t + dt, ok, z_bad). For a guarded law on traced arrays, `ok` per run says its guard
    held in all four stages and `z_bad` is the state of the first stage where it did not (else None, None: on numpy
    arrays the law raises SimulationStop in the stage)."""
    k1, ok1 = loop.rate(t, z, r0)
    z2 = z + 0.5 * dt * k1
    k2, ok2 = loop.rate(t + 0.5 * dt, z2, rh)
    z3 = z + 0.5 * dt * k2
    k3, ok3 = loop.rate(t + 0.5 * dt, z3, rh)
    z4 = z + dt * k3
    k4, ok4 = loop.rate(t + dt, z4, r1)
    z_new = loop.project(z + (dt / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4))
    if ok1 is None or ok2 is None or ok3 is None or ok4 is None:
        return z_new, None, None
    xp = array_namespace(z)
    z_bad = xp.where(ok1[..., None], xp.where(ok2[..., None], xp.where(ok3[..., None], z4, z3), z2), z)
    return z_new, ok1 & ok2 & ok3 & ok4, z_bad


class Step(NamedTuple):
    """What :func:`step` returns (a JAX pytree as it stands; None where the loop has no such part)."""

    applied: Array  # the state applied over step k (x read from a delay line): what a log at t_k holds
    line: Ring | None  # the delay line after step k
    z: Array  # the state at t_{k+1}
    ok: Array | None  # a guarded law's guard held in every stage, per run
    z_bad: Array | None  # the first stage state where it did not


def step(loop: ClosedLoop, k: Any, t: Any, z: Array, line: Ring | None, dt: float, r0: Reference, rh: Reference,
         r1: Reference) -> Step:
    """Fixed step k from t = k·dt: the delay line's sample (if any), then RK4 with the sampled part of x held over the
    step's stages. Pure: the one step function of every fixed-step driver (numpy, batch, compiled)."""
    if line is not None:
        z, line = sample(loop, k, t, z, line, r0)
    z_new, ok, z_bad = rk4_step(loop, t, z, dt, r0, rh, r1)
    return Step(z, line, z_new, ok, z_bad)
