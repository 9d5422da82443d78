"""The sampled-data loop compiled: the tick of :mod:`robotadapt.sim.sampled` under `jax.jit`, ticks in `lax` loops.

Nothing here is a second copy of the tick: the program loops over the same pure `tick(carry, inputs)` that the numpy
driver loops over, traced with JAX arrays (float64). As in the continuous engine (:mod:`robotadapt.sim.compiled`, whose
`skeleton`/`rebuild` program cache and reference chunking this follows), a call scans blocks of `log_every` ticks and
keeps the first tick's record of each block; ticks past t_final (padding of the last call, whose length is a power of
two) are not computed. numpy samples the reference and draws the sensor's noise (from the run's seed, in the numpy
driver's order) ahead of each call and feeds them as per-tick inputs, so both drivers see the same numbers.

A tick that trips the divergence guard, or whose law's own guard fails (HasGuard), ends the run as the numpy driver
does: an `alive` flag freezes the carry, the log keeps the ticks before, and the status names the same time and reason
(a guard's reason is the law's, from the (q, x) it failed at, kept in the program's state). Tracing failures (a law
whose code needs concrete values) become a ConfigError naming `simulation.backend`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from ..trajectories import Reference, Trajectory
from ..validation import ConfigError
from .compiled import CHUNK_STEPS, REF_BYTES, jax_module, rebuild, skeleton
from .loop import GUARD

Array = Any


class SampledTick(Protocol):
    """What this driver needs of :class:`robotadapt.sim.sampled.Tick` (a protocol: that module imports this one)."""

    @property
    def loop(self) -> Any:
        """The closed loop (plant, controller) the tick steps."""

    @property
    def opts(self) -> Any:
        """The Sampled integrator: control period, plant sub-steps, discretisation."""

    @property
    def sensor(self) -> Any:
        """The measurement path (its seed draws the noise fed to the ticks)."""

    def __call__(self, carry: Any, inputs: Any) -> tuple[Any, Any, Any]:
        """(next carry, record, verdict (held, why, q_bad, x_bad)) of one tick."""

    def blank(self, carry: Any) -> Any:
        """A record of zeros shaped like the tick's (what a compiled block starts from)."""

    def status(self, t: float, why: int, q_bad: Array, x_bad: Array) -> str:
        """The run's status for a stop at `t` with reason code `why` (0: ok)."""


_PROGRAMS: dict[Any, tuple[Any, Callable[..., Any]]] = {}
_MAX_PROGRAMS = 16


def _program(tick: SampledTick, log_every: int) -> tuple[Callable[..., Any], list[Array]]:
    """The jitted scan over blocks of ticks for ticks shaped like this one, and this tick's arrays to call it with
    (programs kept by skeleton, as in :mod:`robotadapt.sim.compiled`)."""
    leaves: list[Array] = []
    key = (skeleton(tick, leaves), log_every)
    if key in _PROGRAMS:
        return _PROGRAMS[key][1], leaves
    jax = jax_module()
    jnp, lax, tree = jax.numpy, jax.lax, jax.tree_util
    template = rebuild(tick, iter(leaves))
    Ts = tick.opts.control_period

    def one(traced: SampledTick, n_ticks: Array, state: Any, inputs: Any) -> tuple[Any, Any]:
        carry, alive, t_bad, why, bad = state
        new, record, verdict = traced(carry, inputs)
        k, t = inputs[0], inputs[1]
        exists, active = k <= n_ticks, k < n_ticks  # the tick at t_final is logged, not integrated; padding: nothing
        held = jnp.asarray(True) if verdict.held is None else verdict.held  # if not: stop at t, the tick unlogged
        at_sample = alive & exists & ~held
        after = alive & active & held & (verdict.why != 0)
        code = jnp.where(at_sample, GUARD, verdict.why).astype(why.dtype)
        now = at_sample | after
        keep = alive & active & held & (verdict.why == 0)
        carry = tree.tree_map(lambda a, b: jnp.where(keep, a, b), new, carry)
        if bad is not None:
            bad = tree.tree_map(lambda a, b: jnp.where(now, a, b), (verdict.q_bad, verdict.x_bad), bad)
        state = (carry, alive & ~now, jnp.where(now, jnp.where(code == GUARD, t, t + Ts), t_bad),
                 jnp.where(now, code, why), bad)
        return state, (record, alive & exists & held)

    @jax.jit
    def run(arrays: list[Array], state: Any, xs: Any, n_ticks: Array, blank: Any) -> Any:
        traced = rebuild(template, iter(arrays))
        plant = traced.loop.plant
        for name in ("acceleration", "derivative"):  # traced once, called by every RK4 stage of every plant sub-step
            object.__setattr__(plant, name, jax.jit(getattr(plant, name)))  # (an n-DOF arm's: thousands of operations)

        def block(state: Any, xs: Any) -> tuple[Any, Any]:
            """The block's ticks that exist (none of the padding after t_final), keeping the first one's record."""
            def body(i: Array, carried: Any) -> Any:
                state, kept = carried
                state, out = one(traced, n_ticks, state, tree.tree_map(lambda a: a[i], xs))
                return state, tree.tree_map(lambda a, b: jnp.where(i == 0, a, b), out, kept)

            count = jnp.clip(n_ticks + 1 - xs[0][0], 0, xs[0].shape[0])
            return lax.fori_loop(0, count, body, (state, (blank, jnp.asarray(False))))

        return lax.scan(block, state, xs)

    if len(_PROGRAMS) >= _MAX_PROGRAMS:
        _PROGRAMS.pop(next(iter(_PROGRAMS)))
    _PROGRAMS[key] = (template, run)
    return run, leaves


def integrate(tick: SampledTick, carry: Any, traj: Trajectory, n_ticks: int,
              log_every: int) -> tuple[Array, tuple[Array, ...], str]:
    """Ticks 0 … `n_ticks` of `tick` from `carry` (:meth:`robotadapt.sim.sampled.Tick.start`): the logged times, the
    logged records (each field stacked over the logged ticks) and the status, as the numpy driver gives them."""
    jax = jax_module()
    jnp = jax.numpy
    n, Ts = tick.loop.n, tick.opts.control_period
    blocks = n_ticks // log_every + 1  # a block per logged tick; the last one runs on to t_final and is padded
    tick_bytes = 8 * (5 * n + 2)  # reference (3n), noise (2n), k and t
    most = max(1, int(min(CHUNK_STEPS, REF_BYTES // tick_bytes)) // log_every)
    per_call = min(most, 1 << max(0, blocks - 1).bit_length())  # a power of two: fewer shapes, fewer compilations
    run, arrays = _program(tick, log_every)
    rng = tick.sensor.generator()

    bad = (jnp.zeros(n), jnp.zeros(carry[1].size)) if tick.loop.guarded else None  # where a guard failed: (q, x)
    state = (jax.tree_util.tree_map(jnp.asarray, carry), jnp.asarray(True), jnp.asarray(np.nan), jnp.asarray(0), bad)
    blank = jax.tree_util.tree_map(jnp.asarray, tick.blank(carry))
    records, logged = [], []
    for first in range(0, blocks, per_call):
        ticks = np.arange(first * log_every, (first + per_call) * log_every)
        real = int(np.sum(ticks <= n_ticks))
        ref = traj(Ts * np.minimum(ticks, n_ticks))
        noise = np.concatenate([tick.sensor.noise(rng, real), np.zeros((ticks.size - real, 2, n))])
        shape = (per_call, log_every)
        xs = (ticks.reshape(shape), (Ts * ticks).reshape(shape),
              Reference(*(np.asarray(a, dtype=float).reshape(shape + (n,)) for a in ref)), noise.reshape(shape + (2, n)))
        try:
            state, (record, alive) = run(arrays, state, xs, n_ticks, blank)
        except Exception as exc:  # tracing met code that needs concrete values
            loop = tick.loop
            name = f"{type(loop.controller).__name__} on {type(loop.plant.model).__name__}"
            raise ConfigError("simulation.backend", f"{name} cannot be compiled with JAX ({type(exc).__name__}: "
                              f"{(str(exc).splitlines() or [''])[0][:120]}); use backend = 'numpy'") from None
        keep = min(per_call, blocks - first)
        records.append([np.asarray(a)[:keep] for a in record])
        logged.append(np.asarray(alive)[:keep])
        if not bool(state[1]):
            break
    count = int(np.concatenate(logged).sum())
    stacked = tuple(np.concatenate(parts)[:count] for parts in zip(*records, strict=True))
    bad = (None, None) if state[4] is None else state[4]
    status = tick.status(float(state[2]), int(state[3]), *bad)
    return Ts * (log_every * np.arange(count)), stacked, status
