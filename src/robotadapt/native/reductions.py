"""Reductions and contractions in C: reduce_* over axes, the cumulative sums, products and extrema along an axis, and
dot_general (a loop nest per output element over the contracted dimensions)."""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from typing import Any

import numpy as np

from .arithmetic import extremum, is_float
from .lowering import Handler, Lowering
from .values import Aval, Ref, linear


def reduce(t: Lowering, ins: list[Ref], outs: list[Aval], axes: Sequence[int], init: str, update: str) -> Ref:
    """The operand reduced over `axes`: the result set to `init`, then `update` (a format of {acc} and {x}) of each
    element."""
    x, (shape, dtype) = ins[0], outs[0]
    ref = t.em.buffer(shape, dtype)
    t.em.loop([max(ref.size, 1)], lambda ix: [f"{ref.name}[{ix[0]}] = {init};"])
    kept = [d for d in range(len(x.shape)) if d not in axes]

    def body(ix: list[str]) -> list[str]:
        out = f"{ref.name}[{linear(shape, [ix[d] for d in kept])}]"
        return [f"{out} = " + update.format(acc=out, x=x.get(ix)) + ";"]

    t.em.loop(x.shape, body)
    return ref


def reduce_sum(t: Lowering, ins: list[Ref], outs: list[Aval], axes: Sequence[int], **_: Any) -> Ref:
    return reduce(t, ins, outs, axes, "0", "{acc} + {x}")


def reduce_prod(t: Lowering, ins: list[Ref], outs: list[Aval], axes: Sequence[int], **_: Any) -> Ref:
    return reduce(t, ins, outs, axes, "1", "{acc} * {x}")


def reduce_max(t: Lowering, ins: list[Ref], outs: list[Aval], axes: Sequence[int], **_: Any) -> Ref:
    low = "(-INFINITY)" if is_float(ins[0]) else f"{np.iinfo(ins[0].dtype).min}"
    return reduce(t, ins, outs, axes, low, extremum("{acc}", "{x}", ins[0], ">"))


def reduce_min(t: Lowering, ins: list[Ref], outs: list[Aval], axes: Sequence[int], **_: Any) -> Ref:
    high = "INFINITY" if is_float(ins[0]) else f"{np.iinfo(ins[0].dtype).max}"
    return reduce(t, ins, outs, axes, high, extremum("{acc}", "{x}", ins[0], "<"))


def reduce_and(t: Lowering, ins: list[Ref], outs: list[Aval], axes: Sequence[int], **_: Any) -> Ref:
    return reduce(t, ins, outs, axes, "1", "{acc} && {x}")


def reduce_or(t: Lowering, ins: list[Ref], outs: list[Aval], axes: Sequence[int], **_: Any) -> Ref:
    return reduce(t, ins, outs, axes, "0", "{acc} || {x}")


def cumulative(op: str, t: Lowering, ins: list[Ref], outs: list[Aval], axis: int, reverse: bool = False,
               **_: Any) -> Ref:
    """The running `op` ("add", "mul", "max" or "min") along `axis`, from its end if `reverse`."""
    x, (shape, dtype) = ins[0], outs[0]
    ref = t.em.buffer(shape, dtype)
    others = [n if d != axis else 1 for d, n in enumerate(shape)]
    n = shape[axis]

    def body(ix: list[str]) -> list[str]:
        k = t.em.fresh("k")
        pos = f"{n - 1} - {k}" if reverse else k
        prev = f"{pos} + 1" if reverse else f"{pos} - 1"
        here = [pos if d == axis else i for d, i in enumerate(ix)]
        at, value = linear(shape, here), x.get(here)
        before = linear(shape, [prev if d == axis else i for d, i in enumerate(ix)])
        combine = {"add": f"{ref.name}[{before}] + {value}", "mul": f"{ref.name}[{before}] * {value}",
                   "max": extremum(f"{ref.name}[{before}]", value, x, ">"),
                   "min": extremum(f"{ref.name}[{before}]", value, x, "<")}[op]
        return [f"for (int {k} = 0; {k} < {n}; {k}++) {{",
                f"    {ref.name}[{at}] = {k} == 0 ? {value} : {combine};", "}"]

    t.em.loop(others, body)
    return ref


def dot_general(t: Lowering, ins: list[Ref], outs: list[Aval], dimension_numbers: Any, **_: Any) -> Ref:
    (lc, rc), (lb, rb) = dimension_numbers
    a, b, (shape, dtype) = ins[0], ins[1], outs[0]
    ref = t.em.buffer(shape, dtype)
    lfree = [d for d in range(len(a.shape)) if d not in lc and d not in lb]
    rfree = [d for d in range(len(b.shape)) if d not in rc and d not in rb]
    sizes = [a.shape[d] for d in lc]

    def body(ix: list[str]) -> list[str]:
        ks = [t.em.fresh("k") for _ in lc]
        nb = len(lb)
        ai = [ix[list(lb).index(d)] if d in lb else ks[list(lc).index(d)] if d in lc else
              ix[nb + lfree.index(d)] for d in range(len(a.shape))]
        bi = [ix[list(rb).index(d)] if d in rb else ks[list(rc).index(d)] if d in rc else
              ix[nb + len(lfree) + rfree.index(d)] for d in range(len(b.shape))]
        acc = t.em.fresh("s")
        lines = [f"{ref.ctype} {acc} = 0;"]
        lines += [f"{'    ' * j}for (int {k} = 0; {k} < {n}; {k}++) {{" for j, (k, n) in enumerate(zip(ks, sizes,
                                                                                                      strict=True))]
        lines.append(f"{'    ' * len(ks)}{acc} += {a.get(ai)} * {b.get(bi)};")
        lines += [f"{'    ' * j}}}" for j in range(len(ks) - 1, -1, -1)]
        return [*lines, f"{ref.name}[{linear(shape, ix)}] = {acc};"]

    t.em.loop(shape, body)
    return ref


HANDLERS: dict[str, Handler] = {
    "reduce_sum": reduce_sum, "reduce_prod": reduce_prod, "reduce_max": reduce_max, "reduce_min": reduce_min,
    "reduce_and": reduce_and, "reduce_or": reduce_or, "cumsum": partial(cumulative, "add"),
    "cumprod": partial(cumulative, "mul"), "cummax": partial(cumulative, "max"), "cummin": partial(cumulative, "min"),
    "dot_general": dot_general}
