"""What the translator's primitive handlers build on (:class:`Lowering`): loop nests over an output, buffers, views,
copies, and nested programs translated in place. The walk of a jaxpr itself is :class:`.c99.Translator`'s.

A handler is a function `handler(t, ins, outs, **params)` of the translator `t`, the operands' values `ins`, the results'
shapes and dtypes `outs` and the equation's parameters; it emits C through `t.em` and returns the result's value (or
a list of them)."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .elements import text
from .emitter import Emitter
from .values import Aval, Ref, broadcast, linear

Handler = Callable[..., Ref | list[Ref]]


def equations(jaxpr: Any) -> int:
    """Equations of a jaxpr, those of nested programs included."""
    total = 0
    for eqn in jaxpr.eqns:
        total += 1
        for value in eqn.params.values():
            for item in value if isinstance(value, list | tuple) else [value]:
                inner = getattr(item, "jaxpr", item)
                if hasattr(inner, "eqns"):
                    total += equations(inner)
    return total


class Lowering(ABC):
    """Translates into statements of an :class:`Emitter`; `used`: which outputs of the equation being translated are
    read."""

    def __init__(self, em: Emitter) -> None:
        self.em = em
        self.used: list[bool] = []

    @abstractmethod
    def run(self, jaxpr: Any, consts: Sequence[Any], args: Sequence[Ref], used: Sequence[bool] | None = None) -> list[Ref]:
        """The output values of `jaxpr` on `args`, its constvars bound to `consts` (those not `used`: unused)."""

    def call(self, closed: Any, ins: Sequence[Ref], used: Sequence[bool] | None = None) -> list[Ref]:
        """The outputs of a nested program (a ClosedJaxpr, or a Jaxpr without constants) on `ins`, translated here by a
        translator of its own."""
        jaxpr = getattr(closed, "jaxpr", closed)
        consts = getattr(closed, "consts", [])
        return type(self)(self.em).run(jaxpr, consts, ins, used)

    @abstractmethod
    def apart(self, closed: Any, ins: Sequence[Ref], outs: Sequence[Aval]) -> list[Ref]:
        """The outputs of a nested program from a call of a C function of its own, translated once."""

    def elementwise(self, expr: Callable[[list[str]], str], ins: Sequence[Ref], out: Aval) -> Ref:
        """A new buffer of `out` whose element is `expr` of the operands' elements there (broadcast)."""
        shape, dtype = out
        ref = self.em.buffer(shape, dtype)
        ct = ref.ctype

        def body(ix: list[str]) -> list[str]:
            args = [r.get(ix if r.shape == shape else broadcast(r.shape, ix)) for r in ins]
            return [f"{ref.name}[{linear(shape, ix)}] = ({ct})({expr(args)});"]

        self.em.loop(shape, body)
        return ref

    def alias(self, ref: Ref, out: Aval) -> Ref:
        """The same elements under another shape (no copy): a buffer renamed, a view whose dimensions other than size 1
        are kept re-indexed, another view materialised first."""
        shape, dtype = out
        if ref.elems is not None:
            return Ref("", shape, dtype, elems=ref.elems.reshape(shape))
        if ref.scalar_expr:
            return Ref(ref.name, shape, dtype, scalar_expr=True)
        if ref.view is None:
            return Ref(ref.name, shape, dtype)
        kept_in = [d for d, n in enumerate(ref.shape) if n != 1]
        kept_out = [d for d, n in enumerate(shape) if n != 1]
        if [ref.shape[d] for d in kept_in] != [shape[d] for d in kept_out]:
            return self.alias(self.materialize(ref), out)

        def view(ix: list[str]) -> str:
            index = ["0"] * len(ref.shape)
            for d_in, d_out in zip(kept_in, kept_out, strict=True):
                index[d_in] = ix[d_out]
            return ref.get(index)

        return Ref(ref.name, shape, dtype, view=view)

    def materialize(self, ref: Ref) -> Ref:
        """A buffer holding a view's elements or held elements (stored once in a block), a buffer or scalar as it is."""
        if ref.elems is not None:
            key = ("buffer", id(ref))
            found = self.em.scalars.find(key)
            if found is None:
                found = (self.stored(ref), ref)  # the ref kept alive: its id is not reused
                self.em.scalars.keep(key, found)
            return found[0]
        return ref if ref.view is None else self.gathered(ref.shape, ref.dtype, ref.get)

    def stored(self, ref: Ref) -> Ref:
        """A new buffer initialised with held elements."""
        out = Ref(self.em.fresh(), ref.shape, ref.dtype)
        items = ", ".join(text(e) for e in ref.elements().flat) if ref.size else "0"
        self.em.emit(f"{out.ctype} {out.name}[{max(ref.size, 1)}] = {{{items}}};")
        return out

    def viewed(self, x: Ref, out: Aval, index: Callable[[list[str]], list[str]]) -> Ref:
        """A view of `x`: the element at multi-index ix is x's at `index(ix)`."""
        return Ref(x.name, out[0], out[1], view=lambda ix: x.get(index(ix)))

    def copy(self, ref: Ref) -> Ref:
        """A new buffer holding `ref`'s elements."""
        if ref.elems is not None:
            return self.stored(ref)
        if ref.view is not None:
            return self.materialize(ref)
        out = self.em.buffer(ref.shape, ref.dtype)
        self.em.loop([max(ref.size, 1)], lambda ix: [f"{out.name}[{ix[0]}] = {ref.at(ix[0])};"])
        return out

    def copy_into(self, target: Ref, value: Ref, offset: str, size: int) -> None:
        """target[offset + i] = value[i] for i < size."""
        if value.elems is not None:
            for i, e in enumerate(value.elems.flat):
                self.em.emit(f"{target.name}[{offset} + {i}] = {text(e)};")
            return

        def body(ix: list[str]) -> list[str]:
            return [f"{target.name}[{offset} + {ix[0]}] = {value.at(ix[0])};"]

        self.em.loop([size], body)

    def gathered(self, shape: Sequence[int], dtype: str, source: Callable[[list[str]], str]) -> Ref:
        """A new buffer of `shape` whose element at each multi-index is `source(index variables)` (no elements: none)."""
        if 0 in shape:
            return Ref("", tuple(shape), dtype, elems=np.empty(shape, dtype=object))
        ref = self.em.buffer(shape, dtype)
        self.em.loop(shape, lambda ix: [f"{ref.name}[{linear(shape, ix)}] = ({ref.ctype})({source(ix)});"])
        return ref
