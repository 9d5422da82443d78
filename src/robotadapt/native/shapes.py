"""Shapes and data movement in C: renames (reshape, squeeze, copies: the same buffer), views (broadcast, slice,
reversal, tile, transpose: an index expression, never stored), and the primitives that write a new buffer
(concatenate, stack, split, pad, iota)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .lowering import Handler, Lowering
from .values import UNUSED, Aval, Ref, linear


def rename(t: Lowering, ins: list[Ref], outs: list[Aval], **_: Any) -> Ref:
    """The operand's elements under the result's shape (reshape, squeeze, copy, …): no copy."""
    return t.alias(ins[0], outs[0])


def broadcast_in_dim(t: Lowering, ins: list[Ref], outs: list[Aval], broadcast_dimensions: Sequence[int],
                     **_: Any) -> Ref:
    x = ins[0]
    if x.scalar_expr:
        return Ref(x.name, outs[0][0], outs[0][1], scalar_expr=True)
    if x.size == int(np.prod(outs[0][0])):
        return t.alias(x, outs[0])
    return t.viewed(x, outs[0], lambda ix: ["0" if x.shape[j] == 1 else ix[d] for j, d in enumerate(broadcast_dimensions)])


def slice_(t: Lowering, ins: list[Ref], outs: list[Aval], start_indices: Sequence[int],
           strides: Sequence[int] | None = None, **_: Any) -> Ref:
    step = strides or [1] * len(outs[0][0])
    return t.viewed(ins[0], outs[0], lambda ix: [
        f"{int(s)} + ({i})*{int(k)}" if k != 1 else f"{int(s)} + ({i})" if s else i
        for s, i, k in zip(start_indices, ix, step, strict=True)])


def rev(t: Lowering, ins: list[Ref], outs: list[Aval], dimensions: Sequence[int], **_: Any) -> Ref:
    shape = outs[0][0]
    return t.viewed(ins[0], outs[0], lambda ix: [f"{shape[d] - 1} - ({i})" if d in dimensions else i
                                                 for d, i in enumerate(ix)])


def tile(t: Lowering, ins: list[Ref], outs: list[Aval], reps: Sequence[int], **_: Any) -> Ref:
    """The operand repeated `reps` times along each dimension: a view, the index taken modulo its size."""
    x = ins[0]
    lead = len(outs[0][0]) - len(x.shape)  # numpy's rule: the operand's shape padded with ones in front
    return t.viewed(x, outs[0], lambda ix: [f"({i}) % {n}" if n != 1 else "0"
                                            for i, n in zip(ix[lead:], x.shape, strict=True)])


def transpose(t: Lowering, ins: list[Ref], outs: list[Aval], permutation: Sequence[int], **_: Any) -> Ref:
    inverse = {p: j for j, p in enumerate(permutation)}
    return t.viewed(ins[0], outs[0], lambda ix: [ix[inverse[k]] for k in range(len(ins[0].shape))])


def concatenate(t: Lowering, ins: list[Ref], outs: list[Aval], dimension: int, **_: Any) -> Ref:
    shape, dtype = outs[0]
    ref = t.em.buffer(shape, dtype)
    offset = 0
    for x in ins:
        def body(ix: list[str], x: Ref = x, offset: int = offset) -> list[str]:
            at = [f"{i} + {offset}" if d == dimension else i for d, i in enumerate(ix)]
            return [f"{ref.name}[{linear(shape, at)}] = ({ref.ctype}){x.get(ix)};"]

        t.em.loop(x.shape, body)
        offset += x.shape[dimension]
    return ref


def stack(t: Lowering, ins: list[Ref], outs: list[Aval], axis: int, **_: Any) -> Ref:
    shape, dtype = outs[0]
    ref = t.em.buffer(shape, dtype)
    for k, x in enumerate(ins):
        def body(ix: list[str], x: Ref = x, k: int = k) -> list[str]:
            at = [*ix[:axis], str(k), *ix[axis:]]
            return [f"{ref.name}[{linear(shape, at)}] = ({ref.ctype}){x.get(ix)};"]

        t.em.loop(x.shape, body)
    return ref


def split(t: Lowering, ins: list[Ref], outs: list[Aval], sizes: Sequence[int], axis: int, **_: Any) -> list[Ref]:
    x, result, offset = ins[0], [], 0
    for (shape, dtype), used in zip(outs, t.used, strict=True):
        def source(ix: list[str], offset: int = offset) -> str:
            return x.get([f"{i} + {offset}" if d == axis else i for d, i in enumerate(ix)])

        result.append(t.gathered(shape, dtype, source) if used else UNUSED)
        offset += shape[axis]
    return result


def pad(t: Lowering, ins: list[Ref], outs: list[Aval], padding_config: Sequence[tuple[int, int, int]], **_: Any) -> Ref:
    x, value, (shape, dtype) = ins[0], ins[1], outs[0]
    ref = t.em.buffer(shape, dtype)
    t.em.loop([max(ref.size, 1)], lambda ix: [f"{ref.name}[{ix[0]}] = {value.at('0')};"])

    def body(ix: list[str]) -> list[str]:
        at = [f"{lo} + {i}*{interior + 1}" for (lo, _, interior), i in zip(padding_config, ix, strict=True)]
        checks = " && ".join(f"({a}) >= 0 && ({a}) < {n}" for a, n in zip(at, shape, strict=True)) or "1"
        return [f"if ({checks}) {ref.name}[{linear(shape, at)}] = {x.get(ix)};"]

    t.em.loop(x.shape, body)
    return ref


def iota(t: Lowering, ins: list[Ref], outs: list[Aval], dimension: int, **_: Any) -> Ref:
    shape, dtype = outs[0]
    return t.gathered(shape, dtype, lambda ix: ix[dimension])


RENAMES = ("reshape", "squeeze", "expand_dims", "copy", "copy_p", "stop_gradient", "optimization_barrier",
           "reduce_precision")
HANDLERS: dict[str, Handler] = {
    **dict.fromkeys(RENAMES, rename), "broadcast_in_dim": broadcast_in_dim, "slice": slice_, "rev": rev, "tile": tile,
    "transpose": transpose, "concatenate": concatenate, "stack": stack, "split": split, "pad": pad, "iota": iota}
