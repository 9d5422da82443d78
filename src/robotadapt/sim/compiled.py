"""The compiled backend: the closed loop's fixed-step RK4 under `jax.jit`, time stepping with `lax.scan` (JAX, float64).

Nothing here is a second copy of a model or a controller: the step is :func:`robotadapt.sim.loop.step` on the same
`ClosedLoop`, whose models and controllers are written against the array API (`xp = array_namespace(...)`); traced
with JAX arrays they build one XLA program. float64 is on for the project's programs only (:func:`float64`, a
thread-local scope around each entry point: the user's `jax_enable_x64` stays as it was), so a run equals the numpy
backend's to round-off (1e-9 is what the tests ask). The reference is sampled by numpy ahead of each chunk of steps
and fed to the scan.

The scan carries (z, line, k) and the guards' flags (:class:`Carry`): the state, the delay line of a law with one (the
repetitive law; written by :func:`robotadapt.sim.loop.ring_write`, in place inside the program) and the step index.
The log at t_k holds the state applied over step k, as in the numpy drivers. A law with a guard (adaptive computed
torque: M̂(q) positive definite, :class:`robotadapt.controllers.base.HasGuard`) stops its run inside the program, at
the step and with the status the numpy run gives (the law's message, from the RK4 stage where the guard failed).

The state may carry leading run axes (`(..., m)`, :func:`robotadapt.sim.batch.simulate_batch`): each run has its own
guards and is frozen at its last good state, as in the numpy batch. Compiled programs are cached on disk
(`$ROBOTADAPT_CACHE/jax`, default `~/.cache/robotadapt/jax`), so a second process does not pay the compilation again;
the cache directory is set only where the user has set none (JAX has one per process).
The same code runs on a GPU where `jax[cuda]` is installed (JAX picks the device; nothing here needs one).

What cannot be traced (a law or model whose code needs concrete values: a Pinocchio arm, a host-side check) is refused
with a ConfigError naming `simulation.backend` and the law.
"""

from __future__ import annotations

import copy
import os
from collections.abc import Callable, Iterator
from dataclasses import is_dataclass
from functools import cache, partial, wraps
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple, TypeVar

import numpy as np

from ..trajectories import Reference
from ..validation import ConfigError
from .loop import GUARD, Ring, Step, sample, step

if TYPE_CHECKING:
    from .loop import ClosedLoop

Array = Any
F = TypeVar("F", bound=Callable[..., Any])
CHUNK_STEPS = 16384  # most steps per compiled call (the last call is padded)
REF_BYTES = 64e6  # most bytes of reference samples fed to one call (all runs together)


@cache
def jax_module() -> Any:
    """JAX, with the persistent compilation cache set up where the user has set none; a ConfigError when it is not
    installed. float64 is not switched on here: :func:`float64` scopes it."""
    try:
        import jax
    except ImportError:
        raise ConfigError("simulation.backend", "the 'jax' backend needs JAX: pip install 'robotadapt[jax]'") from None
    if jax.config.jax_compilation_cache_dir is None:  # type: ignore[attr-defined]
        root = Path(os.environ.get("ROBOTADAPT_CACHE", Path.home() / ".cache" / "robotadapt"))
        jax.config.update("jax_compilation_cache_dir", str(root / "jax"))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    return jax


def float64(fn: F) -> F:
    """`fn` run with JAX's float64 on for the calling thread, within the call only (`jax.enable_x64`): the project's
    programs are traced and called in float64, and the user's `jax_enable_x64` is as it was afterwards."""
    @wraps(fn)
    def scoped(*args: Any, **kwargs: Any) -> Any:
        with jax_module().enable_x64(True):
            return fn(*args, **kwargs)

    return scoped  # type: ignore[return-value]


def skeleton(obj: Any, leaves: list[Array]) -> Any:
    """A hashable description of `obj` (the closed loop: plant, model, controller, the dataclasses inside) with its
    float arrays moved to `leaves`: two loops with the same skeleton share one compiled program, their gains, true
    parameters and tables passed as arguments. Other values (floats, flags, integer tables, the arrays of a dict of
    constants) are part of the skeleton; an unhashable one is taken by identity."""
    if isinstance(obj, np.ndarray):
        if obj.dtype.kind == "f":
            leaves.append(obj)
            return ("leaf", obj.shape)
        return ("const", obj.shape, obj.dtype.str, obj.tobytes())
    if is_dataclass(obj) and not isinstance(obj, type):
        return (type(obj), tuple((k, skeleton(v, leaves)) for k, v in vars(obj).items()))
    if isinstance(obj, tuple | list):
        return (type(obj), tuple(skeleton(v, leaves) for v in obj))
    if isinstance(obj, dict):  # a model's table of structural constants (a kinematic tree's `_const`): by value
        return (dict, tuple((k, _constant(v)) for k, v in sorted(obj.items())))
    return _constant(obj)


def _constant(obj: Any) -> Any:
    """`obj` as a hashable constant of a skeleton: arrays by their bytes, an unhashable object by its identity."""
    if isinstance(obj, np.ndarray):
        return ("const", obj.shape, obj.dtype.str, obj.tobytes())
    if isinstance(obj, tuple | list):
        return (type(obj), tuple(_constant(v) for v in obj))
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


_MAPS: dict[Any, Callable[..., Any]] = {}


@float64
def compiled_map(fn: Callable[..., Any], obj: Any, static: Any, *args: Any) -> Any:
    """`fn(obj, static, *args)` evaluated by JAX, numpy arrays out: `obj` (a closed loop) with its float arrays passed as
    arguments (:func:`skeleton`), so objects of one shape share one program; `static` (hashable) is part of the
    program. A ConfigError when `fn` meets code that needs concrete values (numpy-only code)."""
    jax = jax_module()
    leaves: list[Array] = []
    key = (fn, skeleton(obj, leaves), static)
    if key not in _MAPS:
        template = rebuild(obj, iter(leaves))
        if len(_MAPS) >= _MAX_PROGRAMS:
            _MAPS.pop(next(iter(_MAPS)))
        _MAPS[key] = jax.jit(lambda arrays, *a: fn(rebuild(template, iter(arrays)), static, *a))
    try:
        out = _MAPS[key](leaves, *args)
    except Exception as exc:  # tracing met code that needs concrete values
        raise ConfigError("simulation.backend", f"{type(exc).__name__}: {str(exc)[:120]}") from None
    return jax.tree_util.tree_map(np.asarray, out)


SMALL = 8  # dot products and sums over at most this many terms are written out in the compiled step (`lean`)
LEAN_MAX = 3000  # ... in steps of at most this many operations (the two-link arm's RK4 step: 820; the PUMA 560's: 6080)


def lean(fn: Callable[..., Any]) -> Callable[..., Any]:
    """`fn`, a pure function of JAX arrays (pytrees), with its short contractions written out: a dot product or a sum
    over at most `SMALL` terms becomes multiplies and adds, in order. XLA on the CPU runs every dot and every reduction
    as a kernel of its own, a few tens of nanoseconds each, and the two-link arm's RK4 step has some fifty of them for
    a few hundred flops; written out, they fuse with the arithmetic around them (Example 6.3.1: 2.6 → 1.7 µs a step).
    The same numbers up to the order of the additions. Longer contractions (an n-DOF regressor times φ̂) are kept, and
    a step of more than `LEAN_MAX` operations is left as it is: its time goes to arithmetic, and writing its sums out
    would only lengthen its compilation (the PUMA 560's by half)."""
    jax = jax_module()

    def wrapped(*args: Any) -> Any:
        closed, shape = jax.make_jaxpr(fn, return_shape=True)(*args)
        if _size(closed.jaxpr) > LEAN_MAX:
            return fn(*args)
        out = _evaluate(closed.jaxpr, closed.consts, jax.tree_util.tree_leaves(args), SMALL)
        return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(shape), out)

    return wrapped


def _size(jaxpr: Any) -> int:
    """The number of operations of a jaxpr, calls counted by their bodies."""
    return sum(_size(e.params["jaxpr"].jaxpr) if _is_call(e) else 1 for e in jaxpr.eqns)


def _is_call(eqn: Any) -> bool:
    return eqn.primitive.name in ("pjit", "jit", "closed_call") and hasattr(eqn.params.get("jaxpr"), "jaxpr")


def _evaluate(jaxpr: Any, consts: list[Any], args: list[Any], small: int) -> list[Any]:
    """Evaluate a jaxpr (tracing it again), `dot_general`s and `reduce_sum`s over at most `small` terms written out,
    calls inlined."""
    from jax.extend.core import Literal

    env: dict[Any, Any] = dict(zip(jaxpr.constvars, consts, strict=True)) | dict(zip(jaxpr.invars, args, strict=True))

    def read(v: Any) -> Any:
        return v.val if isinstance(v, Literal) else env[v]

    for eqn in jaxpr.eqns:
        ins, name, params = [read(v) for v in eqn.invars], eqn.primitive.name, eqn.params
        floats = all(np.issubdtype(a.dtype, np.floating) for a in ins) and len({a.dtype for a in ins}) == 1
        if name == "dot_general" and floats and 0 < _terms(ins[0].shape, params["dimension_numbers"][0][0]) <= small:
            out = [_dot(ins[0], ins[1], params["dimension_numbers"])]
        elif name == "reduce_sum" and floats and 0 < _terms(ins[0].shape, params["axes"]) <= small:
            out = [_sum(ins[0], params["axes"])]
        elif _is_call(eqn) and small:
            out = _evaluate(params["jaxpr"].jaxpr, params["jaxpr"].consts, ins, small)
        else:
            bind = eqn.primitive.get_bind_params(params)  # older JAX: (subfunctions, params)
            subfuns, bind = bind if isinstance(bind, tuple) else ((), bind)
            out = eqn.primitive.bind(*subfuns, *ins, **bind)
            out = out if eqn.primitive.multiple_results else [out]
        env.update(zip(eqn.outvars, out, strict=True))
    return [read(v) for v in jaxpr.outvars]


def _terms(shape: tuple[int, ...], axes: Any) -> int:
    return int(np.prod([shape[a] for a in axes]))


def _sum(x: Array, axes: Any) -> Array:
    """x summed over `axes`, term by term (slices and adds)."""
    lax = jax_module().lax
    for axis in sorted(axes, reverse=True):
        total = lax.index_in_dim(x, 0, axis, keepdims=False)
        for i in range(1, x.shape[axis]):
            total = total + lax.index_in_dim(x, i, axis, keepdims=False)
        x = total
    return x


def _dot(lhs: Array, rhs: Array, numbers: Any) -> Array:
    """`lax.dot_general(lhs, rhs, numbers)` as a broadcast product summed term by term: the output's axes are (batch,
    lhs free, rhs free), as dot_general's."""
    jnp = jax_module().numpy
    (lc, rc), (lb, rb) = numbers
    lf = [d for d in range(lhs.ndim) if d not in lc and d not in lb]
    rf = [d for d in range(rhs.ndim) if d not in rc and d not in rb]
    a = jnp.transpose(lhs, (*lb, *lf, *lc))
    b = jnp.transpose(rhs, (*rb, *rf, *rc))
    a = a.reshape(a.shape[: len(lb) + len(lf)] + (1,) * len(rf) + a.shape[len(lb) + len(lf) :])
    b = b.reshape(b.shape[: len(rb)] + (1,) * len(lf) + b.shape[len(rb) :])
    product = a * b
    return _sum(product, tuple(range(product.ndim - len(lc), product.ndim)))


_PROGRAMS: dict[Any, tuple[ClosedLoop, Callable[..., Any]]] = {}
_MAX_PROGRAMS = 16


class Carry(NamedTuple):
    """What the scan carries from step to step (a JAX pytree; None where the loop has no such part)."""

    z: Array  # the state [s, x] at t_k, (..., d); a stopped run keeps its last good state
    line: Ring | None  # the delay line of a law with one: slots (N, ..., n) and the slot the next step reads
    k: Array  # the step index, () int
    alive: Array  # (...) the run goes on
    t_bad: Array  # (...) when it stopped (NaN: it did not)
    why: Array  # (...) why: 0 not, 1 non-finite, 2 beyond max_state (REASONS), 3 the law's guard (GUARD)
    z_bad: Array | None  # (..., d) a guarded law: the stage state its guard failed at


def _program(loop: ClosedLoop, dt: float, max_state: float) -> tuple[Callable[..., Any], list[Array]]:
    """The jitted scan over blocks of steps for loops shaped like this one, and this loop's arrays to call it with.
    Programs are kept by skeleton (tracing costs about a second; the entry holds its loop, so ids in a key stay
    valid), and compiled ones on disk.

    `run(arrays, carry, xs, n_active)` scans blocks of steps; `xs` holds each step's reference at its three stage
    instants, `(blocks, log_every, ...)`. Each block yields the state applied at its first step (what the log at that
    instant holds) and whether the run was alive then. Steps from `n_active` on (padding of the last call) are not
    taken."""

    leaves: list[Array] = []
    key = (skeleton(loop, leaves), dt, max_state)
    if key in _PROGRAMS:
        return _PROGRAMS[key][1], leaves
    jax = jax_module()
    jnp, lax, tree = jax.numpy, jax.lax, jax.tree_util
    template = rebuild(loop, iter(leaves))  # a private copy: later caching on `loop` must not change its layout

    @jax.jit
    def rate(arrays: list[Array], t: Array, z: Array, ref: Reference) -> tuple[Array, Array | None]:
        """dz/dt as a function of its own: traced once, called by the step's four RK4 stages (an n-DOF arm's
        dynamics are thousands of operations: tracing and lowering them once, not four times, is most of the
        difference between a PUMA 560 program from the cache in 1 s or in 3 s)."""
        return rebuild(template, iter(arrays)).rate(t, z, ref)

    def traced_loop(arrays: list[Array]) -> ClosedLoop:
        traced = rebuild(template, iter(arrays))
        object.__setattr__(traced, "rate", partial(rate, arrays))
        return traced

    def stepper(traced: ClosedLoop, k: Array, t: Array, z: Array, line: Ring | None, r0: Reference, rh: Reference,
                r1: Reference) -> Step:
        return step(traced, k, t, z, line, dt, r0, rh, r1)

    def advance(traced: ClosedLoop, c: Carry, refs: Any) -> Carry:
        r0, rh, r1 = (Reference(*r) for r in refs)
        t = c.k * dt
        s = lean(partial(stepper, traced))(c.k, t, c.z, c.line, r0, rh, r1)
        guard = c.alive if s.ok is None else c.alive & s.ok
        guarded = traced.guarded_part(s.z)
        finite = jnp.all(jnp.isfinite(guarded), axis=-1)
        keep = guard & finite & (jnp.max(jnp.abs(guarded), axis=-1) <= max_state)
        stopped, diverged = c.alive & ~guard, guard & ~keep
        why = jnp.where(stopped, GUARD, jnp.where(diverged, jnp.where(finite, 2, 1), c.why))
        z_bad = None if s.z_bad is None else jnp.where(stopped[..., None], s.z_bad, c.z_bad)
        t_bad = jnp.where(stopped, t, jnp.where(diverged, t + dt, c.t_bad))
        return Carry(jnp.where(keep[..., None], s.z, c.z), s.line, c.k + 1, keep, t_bad, why, z_bad)

    def applied(traced: ClosedLoop, c: Carry, r0: Reference) -> Array:
        """The state applied over the step the carry is at (a live run with a delay line: x read from it)."""
        if c.line is None:
            return c.z
        return jnp.where(c.alive[..., None], sample(traced, c.k, c.k * dt, c.z, c.line, r0)[0], c.z)

    @jax.jit
    def run(arrays: list[Array], carry: Carry, xs: Any, n_active: Array) -> Any:
        traced = traced_loop(arrays)

        def block(c: Carry, refs: Any) -> tuple[Carry, Any]:
            logged = applied(traced, c, Reference(*(a[0] for a in refs[0])))
            alive = c.alive
            count = jnp.clip(n_active - c.k, 0, refs[0][0].shape[0])  # padding after n_active: not stepped

            def one(i: Array, c: Carry) -> Carry:
                return advance(traced, c, tree.tree_map(lambda a: a[i], refs))

            return lax.fori_loop(0, count, one, c), (logged, alive)

        return lax.scan(block, carry, xs)

    if len(_PROGRAMS) >= _MAX_PROGRAMS:
        _PROGRAMS.pop(next(iter(_PROGRAMS)))
    _PROGRAMS[key] = (template, run)
    return run, leaves


@float64
def integrate(loop: ClosedLoop, reference: Callable[[Array], Reference], z0: Array, dt: float, n_steps: int,
              log_every: int, max_state: float,
              line: Ring | None = None) -> tuple[Array, Array, Array, Array, Array, Array]:
    """Fixed-step RK4 of `z0` (`(..., m)`) from t = 0 for the logged part of `n_steps` steps (every `log_every`-th
    state; the steps after the last logged one change nothing logged), with the delay line `line` (a law with one).
    `reference(times)` samples q_des, q̇_des, q̈_d. The log at t_k holds the state applied over step k, as in the numpy
    drivers.

    Returns the logged times `(T,)`, states `(T, ..., m)`, the number of valid samples per run `(...)`, the time of
    each run's stop (NaN for a run that never stopped), its reason (0 none, 1 a non-finite state, 2 a state beyond
    `max_state`, 3 the law's guard: :data:`robotadapt.sim.loop.GUARD`) and the stage state its guard failed at
    (`(..., m)`, meaningful where the reason is 3)."""
    jnp = jax_module().numpy
    blocks = n_steps // log_every  # logged samples after the initial one
    sample_bytes = 48 * sum(np.asarray(a).size for a in reference(np.zeros(1)))  # 2 instants per step, 3 signals
    most = max(1, int(min(CHUNK_STEPS, REF_BYTES // sample_bytes)) // log_every)
    per_call = min(most, 1 << max(0, blocks - 1).bit_length())  # a power of two: fewer shapes, fewer compilations
    run, arrays = _program(loop, dt, max_state)

    batch = z0.shape[:-1]
    carry = Carry(jnp.asarray(z0), None if line is None else Ring(*(jnp.asarray(a) for a in line)), jnp.asarray(0),
                  jnp.ones(batch, dtype=bool), jnp.full(batch, jnp.nan), jnp.zeros(batch, dtype=int),
                  jnp.zeros(z0.shape) if loop.guarded else None)
    n_active = jnp.asarray(blocks * log_every)
    z_log, alive_log = [], []
    for first in range(0, blocks, per_call):
        size, real = per_call * log_every, min(per_call, blocks - first) * log_every  # steps: all, not padding
        times = dt * (first * log_every + 0.5 * np.arange(2 * real + 1))
        ref = np.stack([np.asarray(a, dtype=float) for a in reference(times)])  # (3, 2R + 1, ..., n)
        ref = np.concatenate([ref, np.zeros((3, 2 * (size - real)) + ref.shape[2:])], axis=1)  # padding: not stepped
        shape = (3, per_call, log_every) + ref.shape[2:]
        stages = tuple(tuple(ref[:, k : k + 2 * size : 2].reshape(shape)) for k in (0, 1, 2))  # r0, r_half, r1
        try:
            carry, (z_blocks, alive_blocks) = run(arrays, carry, stages, n_active)
        except Exception as exc:  # tracing met code that needs concrete values
            name = f"{type(loop.controller).__name__} on {type(loop.plant.model).__name__}"
            raise ConfigError("simulation.backend", f"{name} cannot be compiled with JAX ({type(exc).__name__}: "
                              f"{(str(exc).splitlines() or [''])[0][:120]}); use backend = 'numpy'") from None
        keep = min(per_call, blocks - first)
        z_log.append(np.asarray(z_blocks)[:keep])
        alive_log.append(np.asarray(alive_blocks)[:keep])
        if not np.any(carry.alive):
            break
    alive_end = np.asarray(carry.alive)
    z_end = np.asarray(carry.z)
    if carry.line is not None and np.any(alive_end):  # the last logged instant: the state applied there (numpy)
        k_end = blocks * log_every
        at = reference(np.array([dt * k_end]))
        ring = Ring(*(np.asarray(a) for a in carry.line))
        z_end = np.where(alive_end[..., None], sample(loop, k_end, dt * k_end, z_end, ring,
                                                      Reference(*(np.asarray(a)[0] for a in at)))[0], z_end)
    alive = np.concatenate([*alive_log, alive_end[None]])
    reasons = np.asarray(carry.why)
    stopped = reasons != 0
    z_bad = np.zeros(z0.shape) if carry.z_bad is None else np.asarray(carry.z_bad)
    return (dt * (log_every * np.arange(alive.shape[0])), np.concatenate([*z_log, z_end[None]]), alive.sum(axis=0),
            np.where(stopped, np.asarray(carry.t_bad), np.nan), reasons, z_bad)
