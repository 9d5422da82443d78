"""The compiled backend: the closed loop's fixed-step RK4 under `jax.jit`, time stepping with `lax.scan` (extra `[jax]`).

Nothing here is a second copy of a model or a controller: the step is :func:`robotadapt.simulation.rk4_step` on the
same `ClosedLoop`, whose models and controllers are written against the array API (`xp = array_namespace(...)`); traced
with JAX arrays they build one XLA program. float64 is switched on, so a run equals the numpy backend's to round-off
(1e-9 is what the tests ask). The reference is sampled by numpy ahead of each chunk of steps and fed to the scan.

The state may carry leading run axes (`(..., m)`, :func:`robotadapt.batch.simulate_batch`): each run has its own
divergence guard and is frozen at its last good state, as in the numpy batch. Compiled programs are cached on disk
(`$ROBOTADAPT_CACHE/jax`, default `~/.cache/robotadapt/jax`), so a second process does not pay the compilation again.
The same code runs on a GPU where `jax[cuda]` is installed (JAX picks the device; nothing here needs one).

What cannot be traced is refused with a ConfigError naming `simulation.backend`: a controller with a delay line (the
repetitive law keeps a host-side ring buffer), one that raises on a state (adaptive computed torque's Cholesky guard),
or any law whose code needs concrete values.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Callable, Iterator
from dataclasses import is_dataclass
from functools import cache, partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..trajectories import Reference
from ..validation import ConfigError
from .loop import rk4_step

if TYPE_CHECKING:
    from .loop import ClosedLoop

Array = Any
CHUNK_STEPS = 16384  # most steps per compiled call (the last call is padded)
REF_BYTES = 64e6  # most bytes of reference samples fed to one call (all runs together)


@cache
def jax_module() -> Any:
    """JAX with float64 on and the persistent compilation cache set up; a ConfigError when it is not installed."""
    try:
        import jax
    except ImportError:
        raise ConfigError("simulation.backend", "the 'jax' backend needs JAX: pip install 'robotadapt[jax]'") from None
    jax.config.update("jax_enable_x64", True)
    root = Path(os.environ.get("ROBOTADAPT_CACHE", Path.home() / ".cache" / "robotadapt"))
    jax.config.update("jax_compilation_cache_dir", str(root / "jax"))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    return jax


def skeleton(obj: Any, leaves: list[Array]) -> Any:
    """A hashable description of `obj` (the closed loop: plant, model, controller, the dataclasses inside) with its
    float arrays moved to `leaves`: two loops with the same skeleton share one compiled program, their gains, true
    parameters and tables passed as arguments. Other values (floats, flags, integer tables) are part of the
    skeleton; an unhashable one is taken by identity."""
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind == "f":
            leaves.append(obj)
            return ("leaf", obj.shape)
        return ("const", obj.shape, obj.dtype.str, obj.tobytes())
    if is_dataclass(obj) and not isinstance(obj, type):
        return (type(obj), tuple((k, skeleton(v, leaves)) for k, v in vars(obj).items()))
    if isinstance(obj, tuple | list):
        return (type(obj), tuple(skeleton(v, leaves) for v in obj))
    try:
        hash(obj)
    except TypeError:
        return ("id", id(obj))
    return obj


def rebuild(obj: Any, leaves: Iterator[Array]) -> Any:
    """`obj` with the arrays `skeleton` took replaced, in the same order, by `leaves` (shallow copies: the
    dataclasses' validation is not run again on traced values)."""
    if isinstance(obj, np.ndarray):
        return next(leaves) if obj.dtype.kind == "f" else obj
    if is_dataclass(obj) and not isinstance(obj, type):
        new = copy.copy(obj)
        for k, v in vars(obj).items():
            object.__setattr__(new, k, rebuild(v, leaves))
        return new
    if isinstance(obj, tuple | list):
        return type(obj)(rebuild(v, leaves) for v in obj)
    return obj


_PROGRAMS: dict[Any, tuple[ClosedLoop, Callable[..., Any]]] = {}
_MAX_PROGRAMS = 16


def _program(loop: ClosedLoop, dt: float, max_state: float) -> tuple[Callable[..., Any], list[Array]]:
    """The jitted scan over blocks of steps for loops shaped like this one, and this loop's arrays to call it with.
    Programs are kept by skeleton (tracing costs about a second; the entry holds its loop, so ids in a key stay
    valid), and compiled ones on disk."""

    leaves: list[Array] = []
    key = (skeleton(loop, leaves), dt, max_state)
    if key in _PROGRAMS:
        return _PROGRAMS[key][1], leaves
    jax = jax_module()
    jnp, lax = jax.numpy, jax.lax
    template = rebuild(loop, iter(leaves))  # a private copy: later caching on `loop` must not change its layout

    def advance(traced: ClosedLoop, carry: Any, xs: Any) -> tuple[Any, None]:
        z, alive, t_bad, why = carry
        t, r0, rh, r1 = xs
        z_new = rk4_step(traced, t, z, dt, Reference(*r0), Reference(*rh), Reference(*r1))
        finite = jnp.all(jnp.isfinite(z_new), axis=-1)
        ok = finite & (jnp.max(jnp.abs(z_new), axis=-1) <= max_state)
        now = alive & ~ok
        return (jnp.where((alive & ok)[..., None], z_new, z), alive & ok, jnp.where(now, t + dt, t_bad),
                jnp.where(now, jnp.where(finite, 2, 1), why)), None

    @jax.jit
    def run(arrays: list[Array], carry: Any, xs: Any) -> Any:
        traced = rebuild(template, iter(arrays))

        def block(carry: Any, xs: Any) -> tuple[Any, Any]:
            carry, _ = lax.scan(partial(advance, traced), carry, xs)
            return carry, (carry[0], carry[1])

        return lax.scan(block, carry, xs)

    if len(_PROGRAMS) >= _MAX_PROGRAMS:
        _PROGRAMS.pop(next(iter(_PROGRAMS)))
    _PROGRAMS[key] = (template, run)
    return run, leaves


def integrate(loop: ClosedLoop, reference: Callable[[Array], Reference], z0: Array, dt: float, n_steps: int,
              log_every: int, max_state: float) -> tuple[Array, Array, Array, Array, Array]:
    """Fixed-step RK4 of `z0` (`(..., m)`) from t = 0 for the logged part of `n_steps` steps (every `log_every`-th
    state; the steps after the last logged one change nothing logged). `reference(times)` samples q_des, q̇_des, q̈_d.

    Returns the logged times `(T,)`, states `(T, ..., m)`, the number of valid samples per run `(...)`, the time of
    each run's divergence (NaN for a run that never diverged) and its reason (0 none, 1 a non-finite state, 2 a state
    beyond `max_state`)."""
    jnp = jax_module().numpy
    blocks = n_steps // log_every  # logged samples after the initial one
    sample_bytes = 48 * sum(np.asarray(a).size for a in reference(np.zeros(1)))  # 2 instants per step, 3 signals
    per_call = max(1, min(blocks, int(min(CHUNK_STEPS, REF_BYTES // sample_bytes)) // log_every))
    run, arrays = _program(loop, dt, max_state)

    batch = z0.shape[:-1]
    carry = (jnp.asarray(z0), jnp.ones(batch, dtype=bool), jnp.full(batch, jnp.nan), jnp.zeros(batch, dtype=int))
    z_log, alive_log = [np.asarray(z0)[None]], [np.ones((1,) + batch, dtype=bool)]
    for first in range(0, blocks, per_call):
        steps = np.arange(first * log_every, (first + per_call) * log_every)
        times = np.minimum(dt * (steps[0] + 0.5 * np.arange(2 * steps.size + 1)), dt * n_steps)  # padding: held
        ref = np.stack([np.asarray(a, dtype=float) for a in reference(times)])  # (3, 2S + 1, ..., n)
        shape = (3, per_call, log_every) + ref.shape[2:]
        stages = tuple(tuple(ref[:, k : k + 2 * steps.size : 2].reshape(shape)) for k in (0, 1, 2))  # r0, r_half, r1
        try:
            carry, (z_blocks, alive_blocks) = run(arrays, carry, (dt * steps.reshape(per_call, log_every), *stages))
        except Exception as exc:  # tracing met code that needs concrete values
            name = f"{type(loop.controller).__name__} on {type(loop.plant.model).__name__}"
            raise ConfigError("simulation.backend", f"{name} cannot be compiled with JAX ({type(exc).__name__}: "
                              f"{(str(exc).splitlines() or [''])[0][:120]}); use backend = 'numpy'") from None
        keep = min(per_call, blocks - first)
        z_log.append(np.asarray(z_blocks)[:keep])
        alive_log.append(np.asarray(alive_blocks)[:keep])
        if not np.any(alive_log[-1][-1]):
            break
    alive = np.concatenate(alive_log)
    stopped = ~alive[-1]
    reasons = np.where(stopped, np.asarray(carry[3]), 0)
    return (dt * log_every * np.arange(alive.shape[0]), np.concatenate(z_log), alive.sum(axis=0),
            np.where(stopped, np.asarray(carry[2]), np.nan), reasons)
