"""Data-dependent positions in C: dynamic slices and updates (their starts clamped), gather and scatter (windows
clamped for CLIP and PROMISE_IN_BOUNDS, dropped out of range for FILL_OR_DROP, as XLA) and sort."""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
from typing import Any

import numpy as np

from .elements import literal
from .lowering import Handler, Lowering
from .values import Aval, Ref, Unsupported, linear


def fill(value: Any, dtype: str) -> str:
    """What a FILL_OR_DROP gather gives out of range: `value`, else JAX's default (NaN, the most negative integer, the
    largest unsigned, true)."""
    kind = np.dtype(dtype).kind
    if value is not None:
        return literal(value, dtype)
    if kind == "f":
        return "NAN"
    if kind == "b":
        return "1"
    return literal(np.iinfo(dtype).min if kind == "i" else np.iinfo(dtype).max, dtype)


def window_starts(t: Lowering, shape: Sequence[int], starts: Sequence[Ref], sizes: Sequence[int]) -> list[str]:
    """Constants declared for a window's start in each dimension of an operand of `shape`: the start clamped so that a
    window of `sizes` fits."""
    names = []
    for d, start in enumerate(starts):
        name, s, limit = t.em.fresh("o"), start.at("0"), shape[d] - sizes[d]
        t.em.emit(f"const int64_t {name} = (({s}) < 0 ? 0 : ({s}) > {limit} ? {limit} : ({s}));")
        names.append(name)
    return names


def dynamic_slice(t: Lowering, ins: list[Ref], outs: list[Aval], slice_sizes: Sequence[int], **_: Any) -> Ref:
    x, (shape, dtype) = ins[0], outs[0]
    names = window_starts(t, x.shape, ins[1:], slice_sizes)
    return t.gathered(shape, dtype, lambda ix: x.get([f"{o} + {i}" for o, i in zip(names, ix, strict=True)]))


def dynamic_update_slice(t: Lowering, ins: list[Ref], outs: list[Aval], **_: Any) -> Ref:
    x, update = ins[0], ins[1]
    ref = t.copy(x)
    names = window_starts(t, x.shape, ins[2:], update.shape)
    t.em.loop(update.shape, lambda ix: [
        f"{ref.name}[{linear(x.shape, [f'{o} + {i}' for o, i in zip(names, ix, strict=True)])}] = {update.get(ix)};"])
    return ref


def operand_index(t: Lowering, x: Ref, indices: Ref, batch: list[str], offsets: dict[int, str],
                  batching: dict[int, int], mapped: Sequence[int], sizes: Sequence[int],
                  drop: bool) -> tuple[list[str], list[str], list[str]]:
    """One element of a gather's or scatter's window in the operand `x`: (declarations of the window's starts, the
    operand's multi-index, the conditions that the window is in range). `batch`: the position in the indices' batch
    dimensions (index_vector_dim last); `offsets`: the element's offset per window dimension; `batching`: operand
    dimension → the indices' batch dimension it follows; `mapped`: the operand dimensions the index vector starts;
    `sizes`: the window's size per operand dimension; `drop`: out-of-range windows are dropped (a condition) rather
    than clamped."""
    lines, at, inside = [], [], []
    for d in range(len(x.shape)):
        offset = offsets.get(d, "0")
        if d in batching:
            at.append(batch[batching[d]])
        elif d in mapped:
            s = t.em.fresh("o")
            component = [*batch]
            component.insert(len(indices.shape) - 1, str(list(mapped).index(d)))
            raw, limit = indices.get(component), x.shape[d] - sizes[d]
            if drop:
                lines.append(f"const int64_t {s} = {raw};")
                inside.append(f"{s} >= 0 && {s} <= {limit}")
            else:
                lines.append(f"const int64_t {s} = ({raw}) < 0 ? 0 : ({raw}) > {limit} ? {limit} : ({raw});")
            at.append(f"{s} + {offset}")
        else:
            at.append(offset)
    return lines, at, inside


def gather(t: Lowering, ins: list[Ref], outs: list[Aval], dimension_numbers: Any, slice_sizes: Sequence[int],
           mode: Any, fill_value: Any = None, **_: Any) -> Ref:
    x, indices, (shape, dtype) = ins[0], ins[1], outs[0]
    dn = dimension_numbers
    offset_dims, collapsed, start_map = list(dn.offset_dims), list(dn.collapsed_slice_dims), list(dn.start_index_map)
    batching = dict(zip(dn.operand_batching_dims, dn.start_indices_batching_dims, strict=True))
    drop = "FILL_OR_DROP" in str(mode)
    window = [d for d in range(len(x.shape)) if d not in collapsed and d not in batching]
    ref = t.em.buffer(shape, dtype)

    def body(ix: list[str]) -> list[str]:
        batch = [i for d, i in enumerate(ix) if d not in offset_dims]
        offs = {window[j]: ix[d] for j, d in enumerate(offset_dims)}
        lines, at, inside = operand_index(t, x, indices, batch, offs, batching, start_map, slice_sizes, drop)
        value = x.get(at)
        if inside:
            value = f"({' && '.join(inside)}) ? {value} : {fill(fill_value, dtype)}"
        return [*lines, f"{ref.name}[{linear(shape, ix)}] = {value};"]

    t.em.loop(shape, body)
    return ref


def scatter(combine: str, t: Lowering, ins: list[Ref], outs: list[Aval], dimension_numbers: Any, mode: Any,
            **_: Any) -> Ref:
    """The operand with each window of updates written into it: `combine` (a format of {acc} and {x}) of the element
    there and the update."""
    x, indices, updates = ins[0], ins[1], ins[2]
    dn = dimension_numbers
    window_dims, inserted, to_operand = list(dn.update_window_dims), list(dn.inserted_window_dims), list(
        dn.scatter_dims_to_operand_dims)
    batching = dict(zip(dn.operand_batching_dims, dn.scatter_indices_batching_dims, strict=True))
    drop = "FILL_OR_DROP" in str(mode) or "PROMISE" not in str(mode) and "CLIP" not in str(mode)
    ref = t.copy(x)
    window = [d for d in range(len(x.shape)) if d not in inserted and d not in batching]
    window_size = {window[j]: updates.shape[d] for j, d in enumerate(window_dims)}
    sizes = [window_size.get(d, 1) for d in range(len(x.shape))]

    def body(ix: list[str]) -> list[str]:
        batch = [i for d, i in enumerate(ix) if d not in window_dims]
        offs = {window[j]: ix[d] for j, d in enumerate(window_dims)}
        lines, at, inside = operand_index(t, x, indices, batch, offs, batching, to_operand, sizes, drop)
        target = f"{ref.name}[{linear(x.shape, at)}]"
        statement = f"{target} = {combine.format(acc=target, x=updates.get(ix))};"
        return [*lines, f"if ({' && '.join(inside)}) {statement}" if inside else statement]

    t.em.loop(updates.shape, body)
    return ref


def sort(t: Lowering, ins: list[Ref], outs: list[Aval], dimension: int, is_stable: bool, num_keys: int,
         **_: Any) -> list[Ref]:
    """A stable insertion sort along `dimension` by the first `num_keys` operands (lexicographic), every operand
    permuted alike."""
    if num_keys != 1:
        raise Unsupported("sort by several keys")
    refs = [t.copy(x) for x in ins]
    shape = ins[0].shape
    n = shape[dimension]
    others = [s if d != dimension else 1 for d, s in enumerate(shape)]

    def body(ix: list[str]) -> list[str]:
        a, b = t.em.fresh("a"), t.em.fresh("b")
        at = lambda e: linear(shape, [e if d == dimension else i for d, i in enumerate(ix)])  # noqa: E731
        key = refs[0].name
        swap = " ".join(f"{{ {r.ctype} t_ = {r.name}[{at(b)}]; {r.name}[{at(b)}] = {r.name}[{at(f'{b} - 1')}]; "
                        f"{r.name}[{at(f'{b} - 1')}] = t_; }}" for r in refs)
        return [f"for (int {a} = 1; {a} < {n}; {a}++)",
                f"    for (int {b} = {a}; {b} > 0 && {key}[{at(b)}] < {key}[{at(f'{b} - 1')}]; {b}--) {swap}"]

    t.em.loop(others, body)
    return refs


HANDLERS: dict[str, Handler] = {
    "dynamic_slice": dynamic_slice, "dynamic_update_slice": dynamic_update_slice, "gather": gather,
    "scatter": partial(scatter, "{x}"), "scatter_add": partial(scatter, "{acc} + {x}"), "sort": sort}
