"""A differentiable closed loop: the fixed-step RK4 of :func:`robotadapt.sim.loop.step` under `lax.scan`, so that
`jax.grad` reaches through a whole run to the gains (docs/tuning.md).

The compiled engine (:mod:`robotadapt.sim.compiled`) steps blocks with a `fori_loop` of dynamic length, which reverse
mode cannot differentiate; here the steps are a scan of fixed length over √N blocks of √N steps, each block under
`jax.checkpoint`, so the backward pass keeps only the states at the block boundaries (√N of them) and recomputes each
block's RK4 stages as it goes: memory O(√N) instead of O(N) RK4 residuals, for about one more forward pass.

The step is the same function the other drivers take, on the same `ClosedLoop`: the logged states equal the compiled
forward run's to round-off (tests/test_tune.py asks 1e-9). The loop may hold traced values anywhere (a gain put in by
:func:`replace_at`, the true φ of a sample): they are constants of the step, not of the program.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np

from ..trajectories import Reference, Trajectory
from ..validation import ConfigError
from .compiled import float64, jax_module
from .loop import ClosedLoop, step

Array = Any


def replace_at(obj: Any, path: tuple[str, ...], value: Any) -> Any:
    """`obj` with the attribute at `path` (e.g. ("controller", "law", "F_p")) set to `value`: shallow copies along the
    path, no validation (so `value` may be traced), the copies' cached properties dropped (they may derive from the old
    value); the original is untouched."""
    new = copy.copy(obj)
    for name in [k for k in vars(new) if isinstance(getattr(type(new), k, None), cached_property)]:
        del new.__dict__[name]
    object.__setattr__(new, path[0], value if len(path) == 1 else replace_at(getattr(obj, path[0]), path[1:], value))
    return new


@dataclass(frozen=True, eq=False)
class Rollout:
    """The time grid of a differentiable run: `n_steps` RK4 steps of `dt` from t = 0, the state logged every
    `log_every` steps (as :func:`robotadapt.sim.simulation.simulate` logs it), the reference at every stage instant
    sampled ahead (numpy) and laid out as `(blocks, steps per block, n)`."""

    dt: float
    n_steps: int
    log_every: int
    stages: tuple[Reference, Reference, Reference]  # the reference at t_k, t_k + dt/2, t_k + dt: (B, S, n) each

    @classmethod
    def make(cls, trajectory: Trajectory, dt: float, t_final: float, log_every: int) -> Rollout:
        """The grid of a run to `t_final` with √N steps per checkpointed block (the last block padded)."""
        n_steps = int(np.ceil(t_final / dt - 1e-9))
        per_block = max(1, math.isqrt(n_steps))
        blocks = -(-n_steps // per_block)
        ref = trajectory(dt * 0.5 * np.arange(2 * blocks * per_block + 1))  # padded steps are not taken

        def layout(a: Array, first: int) -> Array:
            return np.asarray(a[first : first + 2 * blocks * per_block : 2]).reshape((blocks, per_block) + a.shape[1:])

        stages = tuple(Reference(*(layout(a, first) for a in ref)) for first in (0, 1, 2))
        return cls(dt, n_steps, log_every, stages)  # type: ignore[arg-type]

    @property
    def times(self) -> Array:
        """The logged instants, `(T,)`."""
        return self.dt * np.arange(0, self.n_steps + 1, self.log_every)

    def states(self, loop: ClosedLoop, z0: Array) -> Array:
        """The logged states `(T, m)` of the run of `loop` from `z0` (traced or not): z at every `log_every`-th step,
        differentiable in everything the loop and `z0` hold."""
        jax = jax_module()
        jnp, lax = jax.numpy, jax.lax
        dt, n_steps = self.dt, self.n_steps

        def one(carry: tuple[Array, Array], refs: tuple[Any, ...]) -> tuple[tuple[Array, Array], Array]:
            z, k = carry
            r0, rh, r1 = (Reference(*r) for r in refs)
            s = step(loop, k, k * dt, z, None, dt, r0, rh, r1)
            return (jnp.where(k < n_steps, s.z, z), k + 1), z

        @jax.checkpoint
        def block(carry: tuple[Array, Array], refs: tuple[Any, ...]) -> tuple[tuple[Array, Array], Array]:
            return lax.scan(one, carry, refs)

        (z_end, _), z_all = lax.scan(block, (jnp.asarray(z0), jnp.asarray(0)), self.stages)
        z_all = jnp.concatenate([z_all.reshape((-1,) + z_all.shape[2:])[:n_steps], z_end[None]])
        return z_all[:: self.log_every]

    @float64
    def signals(self, loop: ClosedLoop, trajectory: Trajectory, z0: Array) -> tuple[Array, Array, Array, Array]:
        """(t, e, τ, z) at the logged instants: the tracking error e = q_d − q and the torque the plant receives,
        recomputed from the logged states by the pure maps as :func:`robotadapt.sim.outputs.outputs` does."""
        t = self.times
        z = self.states(loop, z0)
        ref = Reference(*(jax_module().numpy.asarray(a) for a in trajectory(t)))
        q = loop.split(z)[0]
        tau = loop.plant.saturate(loop.torque(t, z, ref))
        return t, ref.q_des - q, tau, z


@dataclass(frozen=True, eq=False)
class SampledRollout:
    """The differentiable run of a sampled-data loop: the tick of :mod:`robotadapt.sim.sampled`
    (`carry, record, verdict = tick(carry, inputs)`) under a fixed-length `lax.scan` over √N checkpointed blocks of
    ticks, as :class:`Rollout` scans the RK4 step: ticks 0 … `n_ticks`, the last logged, not integrated; the inputs
    (k, t_k, the reference, the sensor's noise drawn from its seed) laid out ahead as `(blocks, ticks per block, …)`."""

    opts: Any  # the Sampled integrator
    n_ticks: int
    log_every: int
    inputs: tuple[Array, Array, Reference, Array]

    @classmethod
    def make(cls, trajectory: Trajectory, opts: Any, t_final: float, log_every: int, sensor: Any) -> SampledRollout:
        Ts = opts.control_period
        n_ticks = int(np.ceil(t_final / Ts - 1e-9))
        per_block = max(1, math.isqrt(n_ticks + 1))
        blocks = -(-(n_ticks + 1) // per_block)
        k = np.arange(blocks * per_block)
        shape = (blocks, per_block)
        ref = Reference(*(np.asarray(a).reshape(shape + a.shape[1:]) for a in trajectory(Ts * np.minimum(k, n_ticks))))
        noise = sensor.noise(sensor.generator(), k.size).reshape(shape + (2, sensor.n))
        return cls(opts, n_ticks, log_every, (k.reshape(shape), (Ts * k).reshape(shape), ref, noise))

    @property
    def times(self) -> Array:
        return self.opts.control_period * np.arange(0, self.n_ticks + 1, self.log_every)

    @float64
    def signals(self, loop: ClosedLoop, trajectory: Trajectory, z0: Array) -> tuple[Array, Array, Array, Array]:
        """(t, e, u, z) at the logged ticks: the error, the applied torque u_k the tick held and the state [s_k, x_k],
        differentiable in everything the loop and `z0` hold."""
        from ..plant.actuators import Actuator
        from ..plant.sensors import Sensor
        from .sampled import Carry, Tick

        jax = jax_module()
        jnp, lax, tree = jax.numpy, jax.lax, jax.tree_util
        n, m, n_ticks = loop.n, loop.m, self.n_ticks
        plant = loop.plant
        tick = Tick(loop, self.opts, plant.sensor or Sensor(n), plant.actuator or Actuator(n), float("inf"), False)
        z0 = jnp.asarray(z0)
        s0 = z0[:m]
        carry = Carry(s0, z0[m:], tick.sensor.start(s0[:n], s0[n : 2 * n], self.opts.control_period),
                      tree.tree_map(jnp.asarray, tick.actuator.start()), jnp.zeros(0), jnp.zeros(0))

        def one(carry: Carry, inputs: Any) -> tuple[Carry, tuple[Array, Array]]:
            new, record, _ = tick(carry, inputs)
            keep = inputs[0] < n_ticks
            return tree.tree_map(lambda a, b: jnp.where(keep, a, b), new, carry), (record.z, record.tau)

        @jax.checkpoint
        def block(carry: Carry, inputs: Any) -> tuple[Carry, tuple[Array, Array]]:
            return lax.scan(one, carry, inputs)

        _, (z, u) = lax.scan(block, carry, self.inputs)
        z, u = (a.reshape((-1,) + a.shape[2:])[: n_ticks + 1 : self.log_every] for a in (z, u))
        t = self.times
        ref = Reference(*(jnp.asarray(a) for a in trajectory(t)))
        return t, ref.q_des - loop.split(z)[0], u, z


def check_differentiable(loop: ClosedLoop) -> None:
    """A ConfigError (field `controller`) for a loop whose run jax.grad cannot go through: a model that JAX cannot
    trace (Pinocchio), a law with a delay line (its ring is written in place) or a switching term (sgn(r): its gradient
    is zero almost everywhere and infinite at the switch)."""
    from ..controllers.base import HasDelayLine

    name = type(loop.controller).__name__
    if not (loop.plant.model.traceable and loop.controller.model.traceable):
        raise ConfigError("controller", f"{name} on {type(loop.plant.model).__name__}: the model cannot be traced by "
                          "JAX, so the run cannot be differentiated; tune on a DH/URDF kinematic tree model")
    if isinstance(loop.controller, HasDelayLine):
        raise ConfigError("controller", f"{name} has a delay line (learning over a period): tuning does not "
                          "differentiate through it; tune another law")
    why = getattr(loop.controller, "not_differentiable", None)  # a law's own hook: why jax.grad cannot go through it
    if why:
        raise ConfigError("controller", f"{name} {why}")
