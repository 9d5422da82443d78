"""The writer of one C function's body for the translator (:mod:`.c99`): fresh names, declarations, loop nests,
file-scope constants and the functions of nested programs."""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .elements import Scalars, literal
from .values import Ref

STACK_LIMIT = 4096  # a temporary with more elements than this is a static array


@dataclass
class Emitter:
    """Writes the body of one C function: its statements (declarations among them) and, shared with the functions
    nested in it, the file-scope constants and functions."""

    lines: list[str] = field(default_factory=list)
    consts: list[str] = field(default_factory=list)
    counter: itertools.count = field(default_factory=itertools.count)
    depth: int = 1
    tag: str = ""  # the function's name: its file-scope constants are named after it
    functions: list[str] = field(default_factory=list)  # file-scope C functions of nested programs called repeatedly
    defined: dict[Any, tuple[str, list[int]]] = field(default_factory=dict)  # their names and kept outputs, by call
    calls: dict[int, int] = field(default_factory=dict)  # how often each nested program is called (:func:`.c99._calls`)
    hold: bool = True  # whether small values are held as elements (:func:`.c99._body`)
    scalars: Scalars = field(init=False)  # the arithmetic of values held as elements

    def __post_init__(self) -> None:
        self.scalars = Scalars(self.emit, self.fresh)

    def nested(self, hold: bool = True) -> Emitter:
        """An emitter for a function of its own, sharing this one's names, constants and functions."""
        return Emitter(consts=self.consts, counter=self.counter, tag=self.tag, functions=self.functions,
                       defined=self.defined, calls=self.calls, hold=hold)

    @property
    def loops(self) -> int:
        return sum(line.lstrip().startswith("for (") for line in self.lines)

    def fresh(self, prefix: str = "v") -> str:
        return f"{prefix}{next(self.counter)}"

    def buffer(self, shape: Sequence[int], dtype: Any) -> Ref:
        ref = Ref(self.fresh(), tuple(int(s) for s in shape), np.dtype(dtype).name)
        size = max(ref.size, 1)
        storage = "static " if size > STACK_LIMIT else ""
        self.emit(f"{storage}{ref.ctype} {ref.name}[{size}];")
        return ref

    def constant(self, value: Any) -> Ref:
        array = np.asarray(value)
        ref = Ref(self.fresh(f"{self.tag}_c"), array.shape, array.dtype.name)
        if array.ndim == 0:
            return Ref(f"(({ref.ctype}){literal(array, array.dtype)})", (), array.dtype.name, scalar_expr=True,
                       value=array)
        items = ", ".join(literal(x, array.dtype) for x in array.ravel()) or "0"
        self.consts.append(f"static const {ref.ctype} {ref.name}[{max(array.size, 1)}] = {{{items}}};")
        ref.value = array
        return ref

    def emit(self, line: str) -> None:
        self.lines.append("    " * self.depth + line)

    def loop(self, shape: Sequence[int], body: Callable[[list[str]], list[str]]) -> None:
        """A loop nest over `shape` whose innermost statements are `body(index variables)`."""
        names = [self.fresh("i") for _ in shape]
        for name, n in zip(names, shape, strict=True):
            self.emit(f"for (int {name} = 0; {name} < {int(n)}; {name}++) {{")
            self.depth += 1
        for line in body(names):
            self.emit(line)
        for _ in shape:
            self.depth -= 1
            self.emit("}")
