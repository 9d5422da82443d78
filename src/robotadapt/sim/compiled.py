"""One-off compiled maps (:func:`compiled_map`) and the pass that writes short sums out (:func:`lean`). The compiled
loop itself is the one driver's (:mod:`robotadapt.sim.driver`); JAX and its float64 scope are
:mod:`robotadapt.tracing`'s, the objects' leaves and structure :mod:`robotadapt.pytree`'s.

Nothing here is a second copy of a model or a controller: the models and controllers are written against the array API
(`xp = array_namespace(...)`); traced with JAX arrays they build one XLA program. The same code runs on a GPU where
`jax[cuda]` is installed (JAX picks the device; nothing here needs one).
"""

from __future__ import annotations

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
