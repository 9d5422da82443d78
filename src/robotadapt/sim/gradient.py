"""A differentiable closed loop: a transition of the one driver (the continuous RK4 step or the sampled-data tick) under
`lax.scan`, so that `jax.grad` reaches through a whole run to the gains (docs/tuning.md).

The driver's compiled loop (:mod:`robotadapt.sim.driver`) steps blocks with a `fori_loop` of dynamic length, which
reverse mode cannot differentiate; here the steps are a scan of fixed length over √N blocks of √N steps, each block
under `jax.checkpoint`, so the backward pass keeps only the carries at the block boundaries (√N of them) and recomputes
each block's steps as it goes: memory O(√N) instead of O(N) residuals, for about one more forward pass.

The transition is the one the driver runs, on the same `ClosedLoop`: the logged signals equal the compiled forward
run's to round-off (tests/test_tune.py asks 1e-9). The loop may hold traced values anywhere (a gain put in by
:func:`robotadapt.pytree.replace`, the true φ of a sample): they are constants of the step, not of the program. A law
with a delay line (the repetitive law, (7.2.32)) carries it in the scan's carry as the forward engines do, written by
`.at[slot].set`, so the gradient reaches back through every period's û_d(t − T) (tests/test_tune_repetitive.py).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

from ..grid import Grid, steps
from ..tracing import float64, jax_module
from ..trajectories import Reference, Trajectory
from ..validation import ConfigError
from .driver import map_tree, take_run
from .loop import ClosedLoop

Array = Any


@dataclass(frozen=True, eq=False)
class Rollout:
    """A differentiable run: the steps 0 … n of a transition of the one driver (:class:`~robotadapt.sim.loop.RK4Step`,
    or the sampled-data :class:`~robotadapt.sim.sampled.Tick`), logged every `log_every` steps as the driver logs
    them, under a fixed-length `lax.scan` over √N checkpointed blocks of √N steps; the inputs (the reference, the
    sensor's noise drawn from its seed) laid out ahead as `(blocks, steps per block, ...)` by the transition's feed;
    the delay line of a law with one in the carry (:meth:`line`)."""

    transition: Any  # RK4Step or Tick on the untraced loop: what `signals` rebuilds on the traced one
    h: float  # the step: dt, or the control period
    n: int
    log_every: int
    inputs: Any

    @classmethod
    def make(cls, loop: ClosedLoop, trajectory: Trajectory, integrator: Any, t_final: float,
             log_every: int) -> Rollout:
        """The grid of a run of `loop` to `t_final` with `integrator` (RK4 or Sampled), √N steps per block (the last
        block padded: its steps after n are not kept)."""
        from ..plant.actuators import Actuator
        from ..plant.sensors import Sensor
        from .integrators import Sampled
        from .loop import RK4Step
        from .sampled import Tick, feed

        if isinstance(integrator, Sampled):
            h, n = integrator.control_period, loop.n
            step: Any = Tick(loop, integrator, loop.plant.sensor or Sensor(n), loop.plant.actuator or Actuator(n),
                             float("inf"), loop.controller.has("delay_line"))
            per_run, mapped = feed([step], [trajectory], True)

            def inputs(first: int, count: int) -> Any:
                return take_run(per_run(first, count), 0, mapped)
        else:
            h = integrator.dt
            step = RK4Step(loop, h, float("inf"), rolled=True)
            inputs = step.feed(trajectory)
        n_steps = steps(t_final, h)
        per_block = max(1, math.isqrt(n_steps + 1))
        blocks = -(-(n_steps + 1) // per_block)
        laid = inputs(0, blocks * per_block)  # the padding after n is fed, computed and not kept
        return cls(step, h, n_steps, log_every, map_tree(lambda a: a.reshape((blocks, per_block) + a.shape[1:]), laid))

    @property
    def times(self) -> Array:
        """The logged instants, `(T,)`, on the run grid (:mod:`robotadapt.grid`)."""
        return Grid(self.h, self.n * self.h, self.log_every).times()

    def line(self, loop: ClosedLoop, z0: Array) -> Array | None:
        """The delay line's initial contents for a law with one (Law.delay_line), as the forward engines build it:
        `delay_line(h, q0, q̇0)` at the (q0, q̇0) of `z0` (û_d = 0 on [−T, 0) for the repetitive law); None
        without."""
        q0, dq0, _ = loop.split(z0)
        return loop.controller.delay_line(self.h, q0, dq0)

    def records(self, loop: ClosedLoop, z0: Array, keep: Callable[[Any], Any] | None = None) -> Any:
        """The logged records `(T, ...)` of the run of `loop` from `z0` (traced or not), differentiable in everything
        the loop and `z0` hold (through the delay line too); `keep`: what of a step's record is logged (default: the
        record, without its sample)."""
        jax = jax_module()
        jnp, lax = jax.numpy, jax.lax
        step = replace(self.transition, loop=loop)
        n = self.n
        kept = keep or (lambda record: record._replace(sample=None))

        def one(carry: Any, inputs: Any) -> tuple[Any, Any]:
            new, record, _ = step(carry, inputs)
            return map_tree(lambda a, b: jnp.where(inputs.k < n, a, b), new, carry), kept(record)

        @jax.checkpoint
        def block(carry: Any, inputs: Any) -> tuple[Any, Any]:
            return lax.scan(one, carry, inputs)

        z0 = jnp.asarray(z0)
        _, out = lax.scan(block, step.start(z0, self.line(loop, z0)), self.inputs)
        return map_tree(lambda a: a.reshape((-1,) + a.shape[2:])[: n + 1 : self.log_every], out)

    @float64
    def signals(self, loop: ClosedLoop, trajectory: Trajectory, z0: Array) -> tuple[Array, Array, Array, Array]:
        """(t, e, τ, z) at the logged instants: the tracking error e = q_d − q, the torque the plant receives (held,
        in sampled time) and the state, as the forward run logs them."""
        t = self.times
        ref = Reference(*(jax_module().numpy.asarray(a) for a in trajectory(t)))
        z, tau = replace(self.transition, loop=loop).signals(self.records(loop, z0), t, ref)
        q, dq, _ = loop.split(z)
        return t, loop.controller.tracking_error(q, dq, ref)[0], tau, z

    @float64
    def scores(self, loop: ClosedLoop, z0: Array, max_state: float) -> tuple[Array, Array, Array, Array]:
        """(t, e, τ, ok) at the logged instants: e and τ as :meth:`signals` gives them (each step's sample, as the
        running metrics take it), and whether every logged state stayed finite and within `max_state`, without
        logging the states: the composite law's on the Panda holds 5481 numbers (P is 70 × 70), so a batched screen of
        64 runs over 2000 steps would keep 5.6 GB of them."""
        jnp = jax_module().numpy

        def keep(record: Any) -> tuple[Array, Array, Array]:
            z = record.z
            return record.sample.e, record.sample.tau, jnp.all(jnp.isfinite(z)) & (jnp.max(jnp.abs(z)) <= max_state)

        e, tau, ok = self.records(loop, z0, keep)
        return self.times, e, tau, jnp.all(ok)


def check_differentiable(loop: ClosedLoop) -> None:
    """A ConfigError (field `controller`) for a loop whose run jax.grad cannot go through: a model that JAX cannot
    trace (Pinocchio). A delay line (the repetitive law, (7.2.32)) is differentiated: the rollout carries it
    (:meth:`Rollout.line`); a switching law (k_d sgn r) through its smooth surrogate (robotadapt.studies.tune)."""
    name = type(loop.controller).__name__
    if not (loop.plant.model.traceable and loop.controller.model.traceable):
        raise ConfigError("controller", f"{name} on {type(loop.plant.model).__name__}: the model cannot be traced by "
                          "JAX, so the run cannot be differentiated; tune on a DH/URDF kinematic tree model")
