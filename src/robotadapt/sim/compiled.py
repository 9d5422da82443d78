"""One-off compiled maps (:func:`compiled_map`) and the pass that writes short sums out (:func:`lean`). The compiled
loop itself is the one driver's (:mod:`robotadapt.sim.driver`); JAX and its float64 scope are
:mod:`robotadapt.tracing`'s, the objects' leaves and structure :mod:`robotadapt.pytree`'s.

Nothing here is a second copy of a model or a controller: the models and controllers are written against the array API
(`xp = array_namespace(...)`); traced with JAX arrays they build one XLA program. The same code runs on a GPU where
`jax[cuda]` is installed (JAX picks the device; nothing here needs one).
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import numpy as np

from .. import pytree
from ..tracing import PROGRAMS, float64, is_call, jax_module
from ..validation import ConfigError

Array = Any


@float64
def compiled_map(fn: Callable[..., Any], obj: Any, static: Any, *args: Any) -> Any:
    """`fn(obj, static, *args)` evaluated by JAX, numpy arrays out: `obj` (a closed loop, a pytree) with its leaves
    passed as arguments, so objects of one structure share one program; `static` (hashable) is part of the program. A
    ConfigError when `fn` meets code that needs concrete values (numpy-only code)."""
    jax = jax_module()
    leaves, structure = pytree.flatten(obj)
    program = PROGRAMS.get(("map", fn, structure, static),
                           lambda: jax.jit(lambda arrays, *a: fn(pytree.unflatten(structure, arrays), static, *a)))
    try:
        out = program(leaves, *args)
    except Exception as exc:  # tracing met code that needs concrete values
        raise ConfigError("simulation.backend", f"{type(exc).__name__}: {str(exc)[:120]}") from None
    return jax.tree_util.tree_map(np.asarray, out)


RECORD_CHUNK = 2048  # logged instants per call of a native map: one program whatever the run's length


def native_map(fn: Callable[..., dict[str, Any]], obj: Any, static: Any, samples: tuple[Any, ...]) -> dict[str, Any]:
    """`fn(obj, static, *samples)` evaluated by C (docs/native.md): `samples` arrays with the logged instants along
    their first axis (or None), taken `RECORD_CHUNK` at a time (the last chunk padded with its last row); `fn`
    returns a dict of arrays (or None) with the instants first. The program is traced and built once per structure and
    chunk shape, and found again on disk by another process (:func:`stable_key`)."""
    from ..native import build

    count = next(np.shape(a)[0] for a in samples if a is not None)
    chunks = -(-count // RECORD_CHUNK)

    def padded(a: Any) -> Any:
        if a is None:
            return None
        a = np.asarray(a, dtype=float)
        return np.concatenate([a, np.repeat(a[-1:], chunks * RECORD_CHUNK - count, axis=0)])

    leaves, structure = pytree.flatten(obj)
    whole = [padded(a) for a in samples]
    first = tuple(None if a is None else a[:RECORD_CHUNK] for a in whole)
    shapes = tuple(None if a is None else (np.shape(a), "f8") for a in first)
    key = ("records", fn.__module__, fn.__qualname__, structure, static, shapes,
           tuple((np.shape(a), np.asarray(a).dtype.str) for a in leaves))

    def program(arrays: Any, *args: Any) -> tuple[Any, ...]:
        """The maps at one instant, looped over the chunk's (a C loop of scalar code: the maps on whole columns would
        keep hundreds of 2048-long temporaries, out of the cache)."""
        obj = pytree.unflatten(structure, arrays)

        def instant(row: tuple[Any, ...]) -> tuple[Any, ...]:
            out = fn(obj, static, *row)
            return tuple(out[k] for k in sorted(out) if out[k] is not None)

        return jax_module().lax.map(instant, args)

    @float64
    def build_it() -> tuple[Any, Any] | None:  # None: the maps hold host-side code (remembered, not traced again)
        try:
            out = jax_module().eval_shape(lambda a, *r: fn(pytree.unflatten(structure, a), static, *r), leaves, *first)
            names = [k for k in sorted(out) if out[k] is not None]
            native, layout = build.compiled(program, tuple(leaves), *first, name="records", key=key)
        except build.Building:  # built in the background: numpy or JAX this time, C once it is there
            raise
        except Exception:  # tracing met code that needs concrete values, or the translator a form it lacks
            return None
        return native, (layout, names)

    def found() -> tuple[Any, Any] | None:  # from the disk store without JAX (a warm process imports none), else built
        stable = stable_key(key)
        stored = build.remembered(stable) if stable is not None else None
        if stored is None:
            stored = build_it()
            if stored is not None and stable is not None:
                build.remember(stable, *stored)
        return stored

    found_program = PROGRAMS.get(("records", key), found)
    if found_program is None:
        raise ConfigError("simulation.backend", "the records hold code C cannot run: evaluated by numpy")
    native, (layout, names) = found_program

    results = [np.empty((chunks * RECORD_CHUNK,) + s[1:], d) for s, d in native.outs]  # each call writes its rows
    for i in range(chunks):
        rows = slice(i * RECORD_CHUNK, (i + 1) * RECORD_CHUNK)
        native(*leaves, *(a[rows] for a in whole if a is not None), out=[r[rows] for r in results])
    return {name: results[layout[j]][:count] for j, name in enumerate(names)}


def stable_key(key: Any) -> str | None:
    """`key` as text that means the same program in another process: None where it holds an object known only by its
    identity here. A class from outside the package carries its module's source (a user's law, edited, is traced
    again); the package's own source is in the store's fingerprint."""
    text = repr(key)
    if "('id', " in text:
        return None
    sources = []
    for kind in sorted(_types(key), key=lambda t: f"{t.__module__}.{t.__qualname__}"):
        if kind.__module__.split(".")[0] in ("robotadapt", "builtins", "numpy"):
            continue
        module = sys.modules.get(kind.__module__)
        path = getattr(module, "__file__", None)
        if path is None:
            return None
        with open(path, "rb") as f:
            sources.append(f.read())
    return text + repr(sources)


def _types(key: Any) -> set[type]:
    """The classes named in a structure."""
    if isinstance(key, type):
        return {key}
    if isinstance(key, pytree.Static):
        return _types(key.key)
    if isinstance(key, tuple):
        return set().union(*(_types(k) for k in key))
    return set()


SMALL = 8  # dot products and sums over at most this many terms are written out in the compiled step (`lean`)
LEAN_MAX = 3000  # ... in steps of at most this many operations (the two-link arm's RK4 step: 820; the PUMA 560's: 6080)


def lean(fn: Callable[..., Any], large: Callable[..., Any] | None = None) -> Callable[..., Any]:
    """`fn`, a pure function of JAX arrays (pytrees), with its short contractions written out: a dot product or a sum
    over at most `SMALL` terms becomes multiplies and adds, in order. XLA on the CPU runs every dot and every reduction
    as a kernel of its own, a few tens of nanoseconds each, and the two-link arm's RK4 step has some fifty of them for
    a few hundred flops; written out, they fuse with the arithmetic around them (Example 6.3.1: 2.6 → 1.7 µs a step).
    The same numbers up to the order of the additions. Longer contractions (an n-DOF regressor times φ̂) are kept, and
    a step of more than `LEAN_MAX` operations is left as it is, or `large` (the same step, written to compile faster) is
    traced in its place: its time goes to arithmetic, and writing its sums out would only lengthen its compilation (the
    PUMA 560's by half)."""
    jax = jax_module()

    def wrapped(*args: Any) -> Any:
        closed, shape = jax.make_jaxpr(fn, return_shape=True)(*args)
        if _size(closed.jaxpr) > LEAN_MAX:
            return (large or fn)(*args)
        out = _evaluate(closed.jaxpr, closed.consts, jax.tree_util.tree_leaves(args), SMALL)
        return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(shape), out)

    return wrapped


def _size(jaxpr: Any) -> int:
    """The number of operations of a jaxpr, calls counted by their bodies."""
    return sum(_size(e.params["jaxpr"].jaxpr) if is_call(e) else 1 for e in jaxpr.eqns)


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
        elif is_call(eqn) and small:
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
