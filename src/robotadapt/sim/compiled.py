"""JAX for the project's programs: the module itself (:func:`jax_module`, with the persistent compilation cache), the
float64 scope (:func:`float64`), the skeleton of an object whose float arrays become a program's arguments
(:func:`skeleton`, :func:`rebuild`), one-off compiled maps (:func:`compiled_map`) and the pass that writes short sums
out (:func:`lean`). The compiled loop itself is the one driver's (:mod:`robotadapt.sim.driver`).

Nothing here is a second copy of a model or a controller: the models and controllers are written against the array API
(`xp = array_namespace(...)`); traced with JAX arrays they build one XLA program. float64 is on for the project's
programs only (:func:`float64`, a thread-local scope around each entry point: the user's `jax_enable_x64` stays as it
was), so a run equals the numpy backend's to round-off (1e-9 is what the tests ask). Compiled programs are cached on
disk (`$ROBOTADAPT_CACHE/jax`, default `~/.cache/robotadapt/jax`), so a second process does not pay the compilation
again; the cache directory is set only where the user has set none (JAX has one per process). The same code runs on a
GPU where `jax[cuda]` is installed (JAX picks the device; nothing here needs one).
"""

from __future__ import annotations

import copy
import os
from collections.abc import Callable, Iterator
from dataclasses import is_dataclass
from functools import cache, wraps
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from ..validation import ConfigError

Array = Any
F = TypeVar("F", bound=Callable[..., Any])
_MAX_PROGRAMS = 16


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
        items = [rebuild(v, leaves) for v in obj]
        return type(obj)(*items) if hasattr(obj, "_fields") else type(obj)(items)  # a NamedTuple takes its fields
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
