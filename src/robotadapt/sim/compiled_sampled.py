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

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import Any, Protocol

import numpy as np

from ..trajectories import Reference, Trajectory
from ..validation import ConfigError
from .compiled import CHUNK_STEPS, REF_BYTES, float64, jax_module, rebuild, skeleton
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

    def status(self, t: float, why: int, q_bad: Array, x_bad: Array) -> Any:
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


_BATCHED: dict[Any, Callable[..., Any]] = {}


def _unseeded(tick: SampledTick) -> Any:
    """The tick with its sensor's seed set aside: the noise is drawn on the host from each run's own seed, so runs
    that differ only in it share one program."""
    loop, plant = tick.loop, tick.loop.plant
    if plant.sensor is not None:
        loop = replace(loop, plant=replace(plant, sensor=replace(plant.sensor, seed=0)))
    return replace(tick, loop=loop, sensor=replace(tick.sensor, seed=0))  # type: ignore[type-var]


@float64
def integrate_batch(ticks: Sequence[SampledTick], carries: list[Any], traj: Trajectory | list[Trajectory], n_ticks: int,
                    log_every: int) -> tuple[Array, tuple[Array, ...], Array, list[Any]]:
    """N runs' ticks in one program, the single run's program mapped over a leading run axis (`jax.vmap`): the runs'
    ticks must have one skeleton (their float arrays, gains and true parameters, may differ), else a ConfigError
    naming `simulation`. `traj`: one trajectory for every run, or one per run. Returns the logged times, the records
    `(T, N, ...)` (a stopped run's rows after its stop repeat its last one), each run's logged count and its status."""
    jax = jax_module()
    jnp, tree = jax.numpy, jax.tree_util
    N, tick = len(ticks), ticks[0]
    n, Ts = tick.loop.n, tick.opts.control_period
    run, arrays = _program(tick, log_every)
    key = (skeleton(_unseeded(tick), []), log_every)
    per_run = [arrays]
    for other in ticks[1:]:
        leaves: list[Array] = []
        if skeleton(_unseeded(other), leaves) != key[0]:
            raise ConfigError("simulation", "the runs differ in more than their arrays (a law's kind, a flag, a scalar "
                              "setting); one batch of sampled-data runs varies gains, tables and true parameters only")
        per_run.append(leaves)
    shared = not isinstance(traj, list)
    noisy = any(t.sensor.noise_q is not None or t.sensor.noise_dq is not None for t in ticks)
    mapped = (key, shared, noisy)
    if mapped not in _BATCHED:
        if len(_BATCHED) >= _MAX_PROGRAMS:
            _BATCHED.pop(next(iter(_BATCHED)))
        axes = (None, None, None if shared else 0, 0 if noisy else None)  # k, t, the reference, the noise
        _BATCHED[mapped] = jax.jit(jax.vmap(run, in_axes=(0, 0, axes, None, None)))
    batched = _BATCHED[mapped]
    blocks = n_ticks // log_every + 1  # a block per logged tick; the last one runs on to t_final and is padded
    tick_bytes = 8 * (2 + (3 * n) * (1 if shared else N) + 2 * n * (N if noisy else 1))  # k, t, reference, noise
    most = max(1, int(min(CHUNK_STEPS, REF_BYTES // tick_bytes)) // log_every)
    per_call = min(most, 1 << max(0, blocks - 1).bit_length())  # a power of two: fewer shapes, fewer compilations
    rngs = [t.sensor.generator() for t in ticks]
    bad = (jnp.zeros((N, n)), jnp.zeros((N, carries[0][1].size))) if tick.loop.guarded else None
    state = (tree.tree_map(lambda *a: jnp.asarray(np.stack(a)), *carries), jnp.ones(N, bool), jnp.full(N, np.nan),
             jnp.zeros(N, int), bad)
    stacked_arrays = [jnp.asarray(np.stack(parts)) for parts in zip(*per_run, strict=True)]
    blank = tree.tree_map(jnp.asarray, tick.blank(carries[0]))
    records, logged = [], []
    for first in range(0, blocks, per_call):
        ticks_k = np.arange(first * log_every, (first + per_call) * log_every)
        real = int(np.sum(ticks_k <= n_ticks))
        shape = (per_call, log_every)
        times = Ts * np.minimum(ticks_k, n_ticks)
        if not isinstance(traj, list):
            ref = Reference(*(np.asarray(a, dtype=float).reshape(shape + (n,)) for a in traj(times)))
        else:
            ref = Reference(*(np.stack([np.asarray(a, dtype=float).reshape(shape + (n,)) for a in parts]) for parts in
                              zip(*(tr(times) for tr in traj), strict=True)))
        draws = [np.concatenate([t.sensor.noise(rng, real), np.zeros((ticks_k.size - real, 2, n))]).reshape(
            shape + (2, n)) for t, rng in zip(ticks, rngs, strict=True)] if noisy else [np.zeros(shape + (2, n))]
        xs = (ticks_k.reshape(shape), (Ts * ticks_k).reshape(shape), ref, np.stack(draws) if noisy else draws[0])
        try:
            if N == 1:  # the single run's own program: its round-off is the numpy driver's order of operations
                one = tree.tree_map(lambda a: a[0], (stacked_arrays, state, xs[2] if not shared else None,
                                                     xs[3] if noisy else None))
                xs1 = (xs[0], xs[1], xs[2] if shared else one[2], one[3] if noisy else xs[3])
                state, out = run(one[0], one[1], xs1, n_ticks, blank)
                state, (record, alive) = tree.tree_map(lambda a: a[None], (state, out))
            else:
                state, (record, alive) = batched(stacked_arrays, state, xs, n_ticks, blank)
        except Exception as exc:  # tracing met code that needs concrete values
            loop = tick.loop
            name = f"{type(loop.controller).__name__} on {type(loop.plant.model).__name__}"
            raise ConfigError("simulation.backend", f"{name} cannot be compiled with JAX ({type(exc).__name__}: "
                              f"{(str(exc).splitlines() or [''])[0][:120]}); use backend = 'numpy'") from None
        keep = min(per_call, blocks - first)
        records.append([np.moveaxis(np.asarray(a), 0, 1)[:keep] for a in record])
        logged.append(np.moveaxis(np.asarray(alive), 0, 1)[:keep])
        if not bool(np.asarray(state[1]).any()):
            break
    alive_rows = np.concatenate(logged)
    n_logged = alive_rows.sum(axis=0)
    out = tuple(np.concatenate(parts) for parts in zip(*records, strict=True))
    for i, k in enumerate(n_logged):  # a stopped run: its last logged row for the rest of the log
        for a in out:
            a[k:, i] = a[max(k - 1, 0), i]
    T = int(n_logged.max())
    bad_q, bad_x = (None, None) if state[4] is None else (np.asarray(state[4][0]), np.asarray(state[4][1]))
    status = [t.status(float(state[2][i]), int(state[3][i]), None if bad_q is None else bad_q[i],
                       None if bad_x is None else bad_x[i]) for i, t in enumerate(ticks)]
    return Ts * (log_every * np.arange(T)), tuple(a[:T] for a in out), n_logged, status
