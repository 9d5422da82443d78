"""Small values as C scalars: a small float64 array held element by element, folded and numbered (docs/native.md).

The translator (:mod:`.c99`) writes an equation as a loop nest over buffers. Where an equation's result is float64 and
small (at most :data:`LIMIT` elements, at most :data:`WORK` terms to compute), it holds the result instead as its
elements, a numpy object array: each a known double (a constant of the program) or the C text of one (a variable
`e12`, a load `in0[3]`). An operation on elements

- folds: known operands are computed (add, sub, mul, div, neg, max, min, integer powers), x·0 = 0, 0/x = 0, x·1 = x,
  x·(−1) = −x, x + 0 = x, x − 0 = x, a select on a known predicate is its case. These are exact for finite x but for
  the sign of a zero; for x infinite or NaN they give 0 where IEEE gives NaN — the state of such a run is no longer
  finite anyway, and the run stops on it;
- is numbered: the same operation on the same operands (commuted, for + and ·), in the C block that declared it or
  one around it, is the same variable;
- otherwise declares one `const double`.

Shapes move by numpy on the object arrays (reshape, broadcast, slice, transpose, reversal, concatenation, padding).
A model written with arrays for XLA (0/1 masks, zero padding, broadcasts of constants, products with a geometry
full of zeros) thereby loses its zeros, and gcc receives straight-line code whose values live in registers.
"""

from __future__ import annotations

import operator
import re
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import numpy as np

LIMIT = 4096  # a float64 result with at most this many elements is held as elements
WORK = 16384  # … if computing it takes at most this many terms (a reduction's or a contraction's inputs)
BUDGET = 10_000  # … in a C function of fewer variables than this (gcc's time grows faster than the function)
CROWD = 1_000_000  # variables × loop nests above which gcc's loop passes dominate its time (each updates the SSA form)

Elem = Any  # a known number (float; int or bool for other dtypes' constants) or the C text of a double


def crowded(declared: int, loops: int) -> bool:
    """Whether a C function that holds `declared` variables and has `loops` loop nests is one gcc builds slowly, so
    that it is translated with loops only: its variables times its loops (loop statements) exceed CROWD. Measured:
    the Panda's Slotine–Li rate (7 000 × 8) builds in 3 s; a batch of 16 Panda runs (10 000, the BUDGET, × 3 000) did
    not build in 10 minutes, and as loops builds in 8 s; the Panda's composite rate (10 000 × 1 400) is loops too."""
    return declared * loops > CROWD


def known(e: Elem) -> bool:
    return not isinstance(e, str)


def literal(value: Any, dtype: Any) -> str:
    """A C literal of `value` in `dtype` (exact for doubles: 17 significant digits)."""
    kind = np.dtype(dtype).kind
    if kind == "b":
        return "1" if bool(value) else "0"
    if kind in "iu":
        whole = int(value)
        return f"INT64_C({whole})" if abs(whole) > 2**31 - 1 else str(whole)
    v = float(value)
    if np.isnan(v):
        return "NAN"
    if np.isinf(v):
        return "INFINITY" if v > 0 else "(-INFINITY)"
    text = repr(v)
    return text if any(c in text for c in ".en") else text + ".0"


def text(e: Elem) -> str:
    """The C text of an element (a negative literal in parentheses)."""
    if isinstance(e, str):
        return e
    if isinstance(e, (bool, np.bool_)):
        return "1" if e else "0"
    if isinstance(e, (int, np.integer)):
        return literal(e, "int64")
    t = literal(e, "float64")
    return f"({t})" if t.startswith("-") else t


def number(f: Callable[..., Any], *args: Elem) -> float:
    with np.errstate(all="ignore"):
        return float(f(*(np.float64(a) for a in args)))


_FOLD: dict[str, Callable[..., Any]] = {"add": operator.add, "sub": operator.sub, "mul": operator.mul,
                                        "div": operator.truediv, "max": np.maximum, "min": np.minimum}


class Scalars:
    """The elements' arithmetic of one C function: folding, numbering by block, declarations through `emit`."""

    def __init__(self, emit: Callable[[str], None], fresh: Callable[[str], str]) -> None:
        self.emit, self.fresh = emit, fresh
        self.scopes: list[dict[Any, Any]] = [{}]
        self.declared = 0

    def open(self) -> None:
        """A C block begins: what is declared in it is not seen after it."""
        self.scopes.append({})

    def close(self) -> None:
        self.scopes.pop()

    def find(self, key: Any) -> Any:
        for scope in reversed(self.scopes):
            if key in scope:
                return scope[key]
        return None

    def keep(self, key: Any, value: Any) -> None:
        self.scopes[-1][key] = value

    def define(self, expr: str, key: Any) -> str:
        """The variable holding `expr` (numbered by `key`)."""
        name = self.find(key)
        if name is None:
            name = self.fresh("e")
            self.emit(f"const double {name} = {expr};")
            self.keep(key, name)
            self.declared += 1
        return str(name)

    def neg(self, a: Elem) -> Elem:
        return number(operator.neg, a) if known(a) else self.define(f"-{a}", ("neg", a))

    def binary(self, name: str, expr: Callable[[str, str], str], a: Elem, b: Elem) -> Elem:
        """a (name) b, `expr` its C text of the operands' texts."""
        if name in _FOLD and known(a) and known(b):
            return number(_FOLD[name], a, b)
        if name == "mul":
            for x, y in ((a, b), (b, a)):
                if known(x):
                    if x == 0.0:
                        return 0.0
                    if x == 1.0:
                        return y
                    if x == -1.0:
                        return self.neg(y)
        elif name == "add":
            for x, y in ((a, b), (b, a)):
                if known(x) and x == 0.0:
                    return y
        elif name == "sub":
            if known(b) and b == 0.0:
                return a
            if known(a) and a == 0.0:
                return self.neg(b)
        elif name == "div":
            if known(b) and b == 1.0:
                return a
            if known(a) and a == 0.0:
                return 0.0
        ta, tb = text(a), text(b)
        if name in ("add", "mul"):
            ta, tb = sorted((ta, tb))
        return self.define(expr(ta, tb), (name, ta, tb))

    def total(self, terms: Iterable[tuple[Elem, Elem]]) -> Elem:
        """Σ a·b over the terms (b None: the term is a): zero products dropped, known ones summed."""
        constant, parts = 0.0, []
        for a, b in terms:
            if b is not None:
                if known(a) and known(b):
                    constant = number(operator.add, constant, number(operator.mul, a, b))
                    continue
                if (known(a) and a == 0.0) or (known(b) and b == 0.0):
                    continue
                x, y = (a, b) if known(b) or not known(a) else (b, a)  # a known factor second
                if known(y) and y == 1.0:
                    parts.append(text(x))
                elif known(y) and y == -1.0:
                    parts.append(f"-{x}")
                else:
                    parts.append(f"{text(x)}*{text(y)}")
            elif known(a):
                constant = number(operator.add, constant, a)
            else:
                parts.append(a)
        if not parts:
            return constant
        if constant != 0.0:
            parts.append(text(constant))
        if len(parts) == 1 and parts[0].isidentifier():
            return parts[0]
        return self.define(" + ".join(parts), ("sum", tuple(parts)))

    def apply(self, name: str, expr: Callable[[list[str]], str], args: Sequence[Elem]) -> Elem:
        """Any other operation: its C text of the operands' texts, numbered."""
        texts = [text(a) for a in args]
        return self.define(expr(texts), (name, *texts))


# -- results of equations, on object arrays -----------------------------------------------------------------------------

def elementwise(shape: Sequence[int], xs: Sequence[np.ndarray], fn: Callable[..., Elem]) -> np.ndarray:
    """fn on the operands' elements, broadcast to `shape`."""
    args = [np.broadcast_to(x, shape) for x in xs]
    out = np.empty(shape, dtype=object)
    for ix in np.ndindex(*shape):
        out[ix] = fn(*(a[ix] for a in args))
    return out


def broadcast_in_dim(x: np.ndarray, shape: Sequence[int], broadcast_dimensions: Sequence[int]) -> np.ndarray:
    dims = [1] * len(shape)
    for j, d in enumerate(broadcast_dimensions):
        dims[d] = x.shape[j]
    return np.broadcast_to(x.reshape(dims), shape)


def pad(x: np.ndarray, value: Elem, shape: Sequence[int], padding_config: Sequence[tuple[int, int, int]]) -> np.ndarray:
    out = np.full(shape, value, dtype=object)
    for ix in np.ndindex(*x.shape):
        at = tuple(lo + i * (interior + 1) for (lo, _, interior), i in zip(padding_config, ix, strict=True))
        if all(0 <= a < n for a, n in zip(at, shape, strict=True)):
            out[at] = x[ix]
    return out


def dot_general(sc: Scalars, a: np.ndarray, b: np.ndarray, shape: Sequence[int], dimension_numbers: Any) -> np.ndarray:
    """Σ over the contracted dimensions, batch dimensions first, then a's free ones, then b's (XLA's order)."""
    (lc, rc), (lb, rb) = dimension_numbers
    lfree = [d for d in range(a.ndim) if d not in lc and d not in lb]
    rfree = [d for d in range(b.ndim) if d not in rc and d not in rb]
    def size(x: np.ndarray, dims: Sequence[int]) -> int:
        return int(np.prod([x.shape[d] for d in dims], dtype=np.int64))

    batch, k = size(a, lb), size(a, lc)
    A = a.transpose([*lb, *lfree, *lc]).reshape(batch, size(a, lfree), k)
    B = b.transpose([*rb, *rfree, *rc]).reshape(batch, size(b, rfree), k)
    out = np.empty((batch, A.shape[1], B.shape[1]), dtype=object)
    for ix in np.ndindex(*out.shape):
        out[ix] = sc.total(zip(A[ix[0], ix[1]], B[ix[0], ix[2]], strict=True))
    return out.reshape(shape)


def reduce(x: np.ndarray, axes: Sequence[int], shape: Sequence[int], fn: Callable[[np.ndarray], Elem]) -> np.ndarray:
    """fn on each group of elements the reduction over `axes` combines."""
    kept = [d for d in range(x.ndim) if d not in axes]
    rows = x.transpose([*kept, *axes]).reshape(int(np.prod(shape, dtype=np.int64)),
                                               int(np.prod([x.shape[d] for d in axes], dtype=np.int64)))
    out = np.empty(len(rows), dtype=object)
    for k, row in enumerate(rows):
        out[k] = fn(row)
    return out.reshape(shape)


def cumulative(x: np.ndarray, axis: int, reverse: bool, combine: Callable[[Elem, Elem], Elem]) -> np.ndarray:
    y = np.moveaxis(np.flip(x, axis) if reverse else x, axis, -1)
    out = np.empty(y.shape, dtype=object)
    if y.shape[-1] == 0:
        return np.moveaxis(out, -1, axis)
    for ix in np.ndindex(*y.shape[:-1]):
        acc = y[ix][0]
        out[ix + (0,)] = acc
        for k in range(1, y.shape[-1]):
            acc = combine(acc, y[ix][k])
            out[ix + (k,)] = acc
    out = np.moveaxis(out, -1, axis)
    return np.flip(out, axis) if reverse else out


_DEFINITION = re.compile(r"^\s*const double (e\d+) = (.*);$")
_NAME = re.compile(r"\be\d+\b")


def prune(lines: list[str]) -> list[str]:
    """The lines of a C function without the element variables nothing reads (a product folded to zero, say, leaves
    its factors unread), removed until none is left: C compilers warn of them."""
    defined = {}
    uses: Counter[str] = Counter()
    for k, line in enumerate(lines):
        m = _DEFINITION.match(line)
        names = _NAME.findall(m.group(2) if m else line)
        uses.update(names)
        if m:
            defined[m.group(1)] = (k, names)
    dead, stack = set(), [name for name in defined if uses[name] == 0]
    while stack:
        name = stack.pop()
        dead.add(defined[name][0])
        for used in defined[name][1]:
            uses[used] -= 1
            if uses[used] == 0 and used in defined:
                stack.append(used)
    return [line for k, line in enumerate(lines) if k not in dead]
