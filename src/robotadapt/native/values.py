"""Values of the C translator (:mod:`.c99`): a jaxpr variable's value in C (:class:`Ref`: a buffer, a scalar
expression, a view or elements held one by one), its C type, and the row-major index arithmetic its reads use."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..validation import ConfigError
from .elements import text

C_TYPES = {"float64": "double", "float32": "float", "int64": "int64_t", "int32": "int32_t", "int16": "int16_t",
           "int8": "int8_t", "uint64": "uint64_t", "uint32": "uint32_t", "uint8": "uint8_t", "bool": "uint8_t"}
Aval = tuple[tuple[int, ...], str]  # a result's shape and dtype name


class Unsupported(ConfigError):
    """A primitive (or a form of one) the translator does not have."""

    def __init__(self, what: str) -> None:
        super().__init__("native", f"the C translator has no {what}: run this law with backend = 'jax' (or 'numpy'), "
                         "or add the primitive to robotadapt.native.c99")


def c_type(dtype: Any) -> str:
    name = np.dtype(dtype).name
    if name not in C_TYPES:
        raise Unsupported(f"C type for dtype {name}")
    return C_TYPES[name]


def strides(shape: Sequence[int]) -> list[int]:
    out, acc = [0] * len(shape), 1
    for i in range(len(shape) - 1, -1, -1):
        out[i] = acc
        acc *= int(shape[i])
    return out


def linear(shape: Sequence[int], index: Sequence[str]) -> str:
    """The flat row-major index of the multi-index `index` (C expressions) in `shape`."""
    terms = [f"({e})*{s}" if s != 1 else f"({e})" for e, s, n in zip(index, strides(shape), shape, strict=True)
             if n != 1]  # a size-1 dimension's index is 0
    return " + ".join(terms) or "0"


def broadcast(shape: Sequence[int], index: Sequence[str]) -> list[str]:
    """The multi-index in an operand of `shape` broadcast (numpy's rules: aligned right, size-1 dimensions repeated)
    to the output position `index`."""
    tail = list(index[len(index) - len(shape):]) if shape else []
    return ["0" if n == 1 else i for n, i in zip(shape, tail, strict=True)]


@dataclass
class Ref:
    """A value in C: a buffer `name` (indexed), for a scalar literal an expression `name`, or a view — an element
    expression of the multi-index (`view`: a broadcast, slice, transpose or reversal of another value, never stored) —
    with its shape and dtype."""

    name: str
    shape: tuple[int, ...]
    dtype: str
    scalar_expr: bool = False
    view: Callable[[list[str]], str] | None = None
    value: np.ndarray | None = None  # a constant's value
    zeros: np.ndarray | None = None  # an argument's elements known to be zero (a structural zero of a gain or table)
    elems: np.ndarray | None = None  # a value held as elements (:mod:`.elements`): no buffer, no view

    @property
    def size(self) -> int:
        return int(np.prod(self.shape, dtype=np.int64))

    @property
    def ctype(self) -> str:
        return c_type(self.dtype)

    def get(self, index: Sequence[str]) -> str:
        """The element at the multi-index `index` (C expressions, one per dimension)."""
        if self.elems is not None:  # a static position only: the translator stores elements before a loop reads them
            return text(self.elems[tuple(int(i) for i in index)])
        if self.scalar_expr:
            return self.name
        if self.view is not None:
            return self.view(list(index))
        return f"{self.name}[{linear(self.shape, index) if self.shape else '0'}]"

    def elements(self) -> np.ndarray:
        """The elements (:mod:`.elements`): held ones, a constant's values, else the C text of each."""
        if self.elems is not None:
            return self.elems
        if self.value is not None:
            return np.broadcast_to(np.asarray(self.value).astype(object), self.shape).copy()
        out = np.empty(self.shape, dtype=object)
        plain = self.view is None and not self.scalar_expr
        for flat, ix in enumerate(np.ndindex(*self.shape)):
            out[ix] = f"{self.name}[{flat}]" if plain else self.get([str(i) for i in ix])
        if self.zeros is not None:
            out[self.zeros] = 0.0
        return out

    def at(self, index: str) -> str:
        """The element at the flat `index` (a rank-0 value ignores it)."""
        if self.elems is not None:
            return text(self.elems.flat[int(index)])
        if self.scalar_expr:
            return self.name
        if self.view is not None:
            return self.view([f"(({index}) / {s}) % {n}" for s, n in zip(strides(self.shape), self.shape, strict=True)])
        return f"{self.name}[{index if self.shape else '0'}]"


UNUSED = Ref("0", (), "float64", scalar_expr=True)  # an output nothing reads
