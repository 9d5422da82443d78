"""Equations whose results the translator (:mod:`.c99`) holds as elements (:mod:`.elements`) instead of writing a loop
nest: which ones (:func:`holds`) and their results computed on the operands' elements (:func:`held`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from . import elements
from .arithmetic import BINARY, UNARY, choice, clamped
from .elements import Scalars
from .emitter import Emitter
from .values import Aval, Ref

# primitives whose results may be held as elements, besides the elementwise ones
MOVES = ("reshape", "squeeze", "expand_dims", "copy", "copy_p", "reduce_precision", "convert_element_type",
         "broadcast_in_dim", "slice", "rev", "transpose", "concatenate", "stack", "split", "pad", "tile")
HELD = frozenset([*UNARY, *BINARY, *MOVES, "dot_general", "reduce_sum", "reduce_max", "reduce_min", "cumsum",
                  "integer_pow", "select_n", "clamp"])


def holds(em: Emitter, name: str, ins: list[Ref], outs: list[Aval], params: dict[str, Any]) -> bool:
    """Whether the equation's results are held as elements: a primitive :func:`held` has, float64 results of at most
    `elements.LIMIT` elements, computed from at most `elements.WORK` terms, in a C function that has declared fewer
    than `elements.BUDGET` variables."""
    if not em.hold or em.scalars.declared >= elements.BUDGET:
        return False
    # a move of a constant or of an argument with structural zeros (a gain transposed) keeps them up to WORK
    limit = elements.WORK if name in MOVES and (ins[0].value is not None or ins[0].zeros is not None) \
        else elements.LIMIT
    if name not in HELD or any(dtype != "float64" or int(np.prod(shape)) > limit for shape, dtype in outs):
        return False
    if name == "dot_general":
        (lc, _), _ = params["dimension_numbers"]
        work = int(np.prod(outs[0][0])) * int(np.prod([ins[0].shape[d] for d in lc]))
    else:
        work = max([int(np.prod(r.shape)) for r in ins] + [int(np.prod(shape)) for shape, _ in outs])
    return work <= elements.WORK


def held(sc: Scalars, name: str, ins: list[Ref], outs: list[Aval], params: dict[str, Any]) -> list[np.ndarray]:
    """The results, as elements, of primitive `name` on the operands' elements (`sc`: the arithmetic on them)."""
    shape, xs = outs[0][0], [r.elements() for r in ins]
    ref = Ref("", shape, "float64")
    if name in UNARY:
        if name == "neg":
            return [elements.elementwise(shape, xs, sc.neg)]
        return [elements.elementwise(shape, xs, lambda a: sc.apply(name, lambda t: UNARY[name](t[0], ref), [a]))]
    if name in BINARY:
        return [elements.elementwise(shape, xs, lambda a, b: sc.binary(name, lambda x, y: BINARY[name](x, y, ref),
                                                                      a, b))]
    x = xs[0]
    if name in ("reshape", "squeeze", "expand_dims", "copy", "copy_p", "reduce_precision"):
        if params.get("dimensions") is not None and name == "reshape":
            x = x.transpose(params["dimensions"])
        return [x.reshape(shape)]
    if name == "convert_element_type":  # to float64 (a held result is float64)
        return [x if ins[0].dtype == "float64" else elements.elementwise(shape, [x], lambda a: float(a) if
                elements.known(a) else sc.apply("double", lambda t: f"(double)({t[0]})", [a]))]
    if name == "broadcast_in_dim":
        return [elements.broadcast_in_dim(x, shape, params["broadcast_dimensions"])]
    if name == "slice":
        step = params.get("strides") or [1] * x.ndim
        return [x[tuple(slice(s, e, k) for s, e, k in zip(params["start_indices"], params["limit_indices"], step,
                                                          strict=True))]]
    if name == "rev":
        return [np.flip(x, tuple(params["dimensions"]))]
    if name == "transpose":
        return [x.transpose(params["permutation"])]
    if name == "concatenate":
        return [np.concatenate(xs, axis=params["dimension"])]
    if name == "stack":
        return [np.stack(xs, axis=params["axis"])]
    if name == "tile":
        return [np.tile(x, params["reps"])]
    if name == "split":
        cuts = np.cumsum(params["sizes"])[:-1]
        return list(np.split(x, cuts, axis=params["axis"]))
    if name == "pad":
        return [elements.pad(x, xs[1].item(), shape, params["padding_config"])]
    if name == "dot_general":
        return [elements.dot_general(sc, x, xs[1], shape, params["dimension_numbers"])]
    if name == "reduce_sum":
        return [elements.reduce(x, params["axes"], shape, lambda row: sc.total((e, None) for e in row))]
    if name in ("reduce_max", "reduce_min"):
        op = name[7:]

        def fold(row: np.ndarray) -> Any:
            acc = row[0] if len(row) else (-np.inf if op == "max" else np.inf)
            for e in row[1:]:
                acc = sc.binary(op, lambda a, b: BINARY[op](a, b, ref), acc, e)
            return acc

        return [elements.reduce(x, params["axes"], shape, fold)]
    if name == "cumsum":
        return [elements.cumulative(x, params["axis"], params.get("reverse", False),
                                    lambda a, b: sc.binary("add", lambda p, q: BINARY["add"](p, q, ref), a, b))]
    if name == "integer_pow":
        y = params["y"]
        return [elements.elementwise(shape, [x], lambda a: elements.number(lambda v: v ** y, a)
                                     if elements.known(a) else sc.apply(f"pow{y}", lambda t: "*".join(
                                         [f"{t[0]}"] * y) if y > 0 else f"1.0/({'*'.join([t[0]] * -y) or '1.0'})",
                                         [a]))]
    if name == "select_n":
        def pick(pred: Any, *cases: Any) -> Any:
            if elements.known(pred):
                return cases[min(max(int(pred), 0), len(cases) - 1)]
            return sc.apply("select", lambda t: choice(t[0], t[1:]), [pred, *cases])

        return [elements.elementwise(shape, xs, pick)]
    if name == "clamp":
        return [elements.elementwise(shape, xs, lambda lo, v, hi: sc.apply("clamp", lambda t: clamped(t[0], t[1], t[2]),
                                                                           [lo, v, hi]))]
    raise AssertionError(name)
