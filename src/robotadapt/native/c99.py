"""A translator from a traced JAX program (a jaxpr) to one C99 function: static shapes, no allocation, libm only
(docs/native.md).

`translate(closed, name)` returns the text of `static void name(const T *in0, …, T *out0, …)`: every input and output
a flat row-major array of its aval's size and C type (float64 → double, int32/int64 → int32_t/int64_t, bool →
uint8_t). Each equation of the jaxpr becomes a loop nest over its output's static shape that reads its operands
through linear index expressions; values that only rename a buffer (reshape, squeeze, expand_dims, a cast to the same
type, copy) share it, nested calls (jit, custom_jvp/custom_vjp, custom_linear_solve's solve) are inlined, and the
outputs are copied out last, so an output may alias an input (a state updated in place). Temporaries are local arrays;
those over `STACK_LIMIT` elements are `static` (the function is then not reentrant: one caller at a time). A small
float64 value is instead held element by element as straight-line C, folded and numbered (:mod:`.elements`).

Every primitive the project's controller ticks and plant steps use is here (:data:`PRIMITIVES`); another raises
:class:`Unsupported`, naming it. Semantics follow XLA's: integer division and remainder truncate, max/min propagate
NaN, dynamic slices clamp their start, gather and scatter clamp (CLIP, PROMISE_IN_BOUNDS) or drop (FILL_OR_DROP)
out-of-range windows as their mode says.
"""

from __future__ import annotations

import itertools
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from ..validation import ConfigError
from . import elements
from .elements import Scalars, literal, text

STACK_LIMIT = 4096  # a temporary with more elements than this is a static array
FUNCTION_MIN = 50  # a nested program of at least this many equations, called more than once, is a C function
CALLS = ("pjit", "jit", "closed_call", "core_call")
C_TYPES = {"float64": "double", "float32": "float", "int64": "int64_t", "int32": "int32_t", "int16": "int16_t",
           "int8": "int8_t", "uint64": "uint64_t", "uint32": "uint32_t", "uint8": "uint8_t", "bool": "uint8_t"}


# primitives whose results may be held as elements (:meth:`Translator.held`), besides the elementwise ones
MOVES = ("reshape", "squeeze", "expand_dims", "copy", "copy_p", "reduce_precision", "convert_element_type",
         "broadcast_in_dim", "slice", "rev", "transpose", "concatenate", "stack", "split", "pad", "tile")
# primitives that pass their operands on to nested programs (which may read held values) rather than loop over them
NESTING = (*CALLS, "custom_jvp_call", "custom_vjp_call", "custom_vjp_call_jaxpr", "remat", "checkpoint",
           "custom_linear_solve", "while", "scan", "cond")


class Unsupported(ConfigError):
    """A primitive (or a form of one) the translator does not have."""

    def __init__(self, what: str) -> None:
        super().__init__("native", f"the C translator has no {what}: run this law with backend = 'jax' (or 'numpy'), "
                         "or add the primitive to robotadapt.native.c99")


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


def _fill(value: Any, dtype: str) -> str:
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
class Emitter:
    """Writes the body of one C function: declarations, then statements; `refs` maps jaxpr variables to values."""

    lines: list[str] = field(default_factory=list)
    decls: list[str] = field(default_factory=list)
    consts: list[str] = field(default_factory=list)
    counter: itertools.count = field(default_factory=itertools.count)
    depth: int = 1
    tag: str = ""  # the function's name: its file-scope constants are named after it
    functions: list[str] = field(default_factory=list)  # file-scope C functions of nested programs called repeatedly
    defined: dict[Any, tuple[str, list[int]]] = field(default_factory=dict)  # their names and kept outputs, by call
    calls: dict[int, int] = field(default_factory=dict)  # how often each nested program is called (:func:`_calls`)
    hold: bool = True  # whether small values are held as elements (:func:`_body`)
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


# -- elementwise -------------------------------------------------------------------------------------------------------

def _float(ref: Ref) -> bool:
    return np.dtype(ref.dtype).kind == "f"


UNARY: dict[str, Callable[[str, Ref], str]] = {
    "neg": lambda x, r: f"-({x})", "sin": lambda x, r: f"sin({x})", "cos": lambda x, r: f"cos({x})",
    "tan": lambda x, r: f"tan({x})", "asin": lambda x, r: f"asin({x})", "acos": lambda x, r: f"acos({x})",
    "atan": lambda x, r: f"atan({x})", "sinh": lambda x, r: f"sinh({x})", "cosh": lambda x, r: f"cosh({x})",
    "tanh": lambda x, r: f"tanh({x})", "exp": lambda x, r: f"exp({x})", "exp2": lambda x, r: f"exp2({x})",
    "log": lambda x, r: f"log({x})", "log1p": lambda x, r: f"log1p({x})", "expm1": lambda x, r: f"expm1({x})",
    "sqrt": lambda x, r: f"sqrt({x})", "rsqrt": lambda x, r: f"(1.0/sqrt({x}))", "cbrt": lambda x, r: f"cbrt({x})",
    "floor": lambda x, r: f"floor({x})", "ceil": lambda x, r: f"ceil({x})",
    "round": lambda x, r: f"round({x})",
    "abs": lambda x, r: f"fabs({x})" if _float(r) else f"(({x}) < 0 ? -({x}) : ({x}))",
    "sign": lambda x, r: f"(({x}) > 0) - (({x}) < 0)" if not _float(r) else
    f"(isnan({x}) ? ({x}) : (double)((({x}) > 0) - (({x}) < 0)))",
    "logistic": lambda x, r: f"(1.0/(1.0 + exp(-({x}))))",
    "not": lambda x, r: f"!({x})" if r.dtype == "bool" else f"~({x})",
    "is_finite": lambda x, r: f"isfinite({x})",
    "square": lambda x, r: f"(({x})*({x}))",
}


def _max(a: str, b: str, ref: Ref, op: str) -> str:
    if not _float(ref):
        return f"(({a}) {op} ({b}) ? ({a}) : ({b}))"
    return f"(isnan({a}) ? ({a}) : isnan({b}) ? ({b}) : ({a}) {op} ({b}) ? ({a}) : ({b}))"


BINARY: dict[str, Callable[[str, str, Ref], str]] = {
    "add": lambda a, b, r: f"({a}) + ({b})", "sub": lambda a, b, r: f"({a}) - ({b})",
    "mul": lambda a, b, r: f"({a}) * ({b})", "div": lambda a, b, r: f"({a}) / ({b})",
    "rem": lambda a, b, r: f"fmod({a}, {b})" if _float(r) else f"({a}) % ({b})",
    "pow": lambda a, b, r: f"pow({a}, {b})", "atan2": lambda a, b, r: f"atan2({a}, {b})",
    "nextafter": lambda a, b, r: f"nextafter({a}, {b})",
    "max": lambda a, b, r: _max(a, b, r, ">"), "min": lambda a, b, r: _max(a, b, r, "<"),
    "eq": lambda a, b, r: f"({a}) == ({b})", "ne": lambda a, b, r: f"({a}) != ({b})",
    "lt": lambda a, b, r: f"({a}) < ({b})", "le": lambda a, b, r: f"({a}) <= ({b})",
    "gt": lambda a, b, r: f"({a}) > ({b})", "ge": lambda a, b, r: f"({a}) >= ({b})",
    "and": lambda a, b, r: f"({a}) && ({b})" if r.dtype == "bool" else f"({a}) & ({b})",
    "or": lambda a, b, r: f"({a}) || ({b})" if r.dtype == "bool" else f"({a}) | ({b})",
    "xor": lambda a, b, r: f"({a}) != ({b})" if r.dtype == "bool" else f"({a}) ^ ({b})",
}
# the total-order comparisons (sorting keys): the plain ones, which agree with them on every number but signed zeros
BINARY.update({f"{op}_to": BINARY[op] for op in ("eq", "lt", "le")})
HELD = frozenset([*UNARY, *BINARY, *MOVES, "dot_general", "reduce_sum", "reduce_max", "reduce_min", "cumsum",
                  "integer_pow", "select_n", "clamp"])


def live(jaxpr: Any, used: Sequence[bool] | None = None) -> list[tuple[Any, list[bool]]]:
    """The equations the `used` outputs (default all) depend on, in order, each with which of its outputs are read (a
    traced program keeps values nothing reads, and C warns of them)."""
    needed = {v for k, v in enumerate(jaxpr.outvars) if not hasattr(v, "val") and (used is None or used[k])}
    kept = []
    for eqn in reversed(jaxpr.eqns):
        mask = [v in needed for v in eqn.outvars]
        if eqn.effects or any(mask):
            kept.append((eqn, mask))
            needed.update(v for v in eqn.invars if not hasattr(v, "val"))
    return kept[::-1]


UNUSED = Ref("0", (), "float64", scalar_expr=True)  # an output nothing reads


def _hashable(value: Any) -> Any:
    """A parameter of an equation as a dictionary key: containers by their items, arrays by their bytes, a value
    without a hash (a nested program) by its identity."""
    if isinstance(value, (tuple, list)):
        return tuple(_hashable(v) for v in value)
    if isinstance(value, dict):
        return tuple(sorted((k, _hashable(v)) for k, v in value.items()))
    if isinstance(value, np.ndarray):
        return (value.dtype.str, value.shape, value.tobytes())
    try:
        hash(value)
    except TypeError:
        return ("id", id(value))
    return value


def _equation_key(eqn: Any, mask: Sequence[bool], env: dict[Any, Ref]) -> Any:
    """What an equation computes: its primitive, parameters and operands (values by identity, literals by value), and
    which outputs are read. Two equations with one key compute the same values (the program is pure), so the second
    is not translated: the duplicate work a program traced from separate calls holds (XLA's CSE does the same)."""
    operands = tuple(("lit", str(a.aval.dtype), np.asarray(a.val).tobytes()) if hasattr(a, "val") else id(env[a])
                     for a in eqn.invars)
    return eqn.primitive.name, _hashable(eqn.params), operands, tuple(mask)


class Translator:
    """Translates one jaxpr (with its constants) into statements of an :class:`Emitter`."""

    def __init__(self, em: Emitter) -> None:
        self.em = em
        self.used: list[bool] = []  # which outputs of the equation being translated are read

    def run(self, jaxpr: Any, consts: Sequence[Any], args: Sequence[Ref], used: Sequence[bool] | None = None) -> list[Ref]:
        """The output values of `jaxpr` on `args`, its constvars bound to `consts` (those not `used`: :data:`UNUSED`)."""
        env: dict[Any, Ref] = {}
        for var, value in zip(jaxpr.constvars, consts, strict=True):
            env[var] = value if isinstance(value, Ref) else self.em.constant(value)
        for var, ref in zip(jaxpr.invars, args, strict=True):
            env[var] = ref

        def read(atom: Any) -> Ref:
            if hasattr(atom, "val"):  # a Literal
                return self.em.constant(np.asarray(atom.val, dtype=atom.aval.dtype))
            return env[atom]

        seen: dict[Any, list[Ref]] = {}  # equations already translated, by what they compute (value numbering)
        for eqn, mask in live(jaxpr, used):
            key = None if eqn.effects else _equation_key(eqn, mask, env)
            if key is not None and key in seen:  # the same primitive on the same values: its results again
                outs = seen[key]
            else:
                self.used = mask
                outs = self.equation(eqn, [read(a) for a in eqn.invars])
                if key is not None:
                    seen[key] = outs
            for var, ref in zip(eqn.outvars, outs, strict=True):
                env[var] = ref
        return [read(v) if used is None or used[k] else UNUSED for k, v in enumerate(jaxpr.outvars)]

    def equation(self, eqn: Any, ins: list[Ref]) -> list[Ref]:
        name = eqn.primitive.name
        handler = getattr(self, "p_" + name.replace("-", "_"), None)
        outs = [(tuple(v.aval.shape), np.dtype(v.aval.dtype).name) for v in eqn.outvars]
        known = self._known(eqn, ins, outs)
        if known is not None:
            return [self.em.constant(v) for v in known]
        if self._held(name, ins, outs, eqn.params):
            values = self.held(name, ins, outs, eqn.params)
            return [Ref("", shape, dtype, elems=np.asarray(v, dtype=object).reshape(shape))
                    for v, (shape, dtype) in zip(values, outs, strict=True)]
        if name not in NESTING:  # a loop nest reads buffers and views: held values are stored first
            ins = [self.materialize(r) if r.elems is not None else r for r in ins]
        if name in UNARY:
            return [self.elementwise(lambda x: UNARY[name](x[0], ins[0]), ins, outs[0])]
        if name in BINARY:
            return [self.elementwise(lambda x: BINARY[name](x[0], x[1], ins[0]), ins, outs[0])]
        if handler is None:
            raise Unsupported(f"primitive '{name}'")
        result = handler(ins, outs, **eqn.params)
        return result if isinstance(result, list) else [result]

    # -- values held as elements (:mod:`.elements`) ---------------------------------------------------------------------

    @staticmethod
    def _known(eqn: Any, ins: list[Ref], outs: list) -> list[np.ndarray] | None:
        """The results of an equation on constants only (an identity matrix built from iota, a mask), small: computed
        now by JAX, so that they fold; None otherwise."""
        if (eqn.primitive.name in NESTING or eqn.effects or sum(int(np.prod(shape)) for shape, _ in outs) > elements.LIMIT
                or any(not (r.value is not None or r.elems is not None and all(map(elements.known, r.elems.flat)))
                       for r in ins)):
            return None
        import jax

        values = [r.value if r.value is not None else r.elements().astype(r.dtype) for r in ins]
        with jax.enable_x64(True):
            got = eqn.primitive.bind(*[np.asarray(v, dtype=r.dtype) for v, r in zip(values, ins, strict=True)],
                                     **eqn.params)
        got = got if eqn.primitive.multiple_results else [got]
        return [np.asarray(v, dtype=dtype).reshape(shape) for v, (shape, dtype) in zip(got, outs, strict=True)]

    def _held(self, name: str, ins: list[Ref], outs: list, params: dict[str, Any]) -> bool:
        """Whether the equation's results are held as elements: a primitive :meth:`held` has, float64 results of at most
        `elements.LIMIT` elements, computed from at most `elements.WORK` terms, in a C function that has declared fewer
        than `elements.BUDGET` variables."""
        if not self.em.hold or self.em.scalars.declared >= elements.BUDGET:
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

    def held(self, name: str, ins: list[Ref], outs: list, params: dict[str, Any]) -> list[np.ndarray]:
        """The results, as elements, of primitive `name` on the operands' elements."""
        sc, shape, xs = self.em.scalars, outs[0][0], [r.elements() for r in ins]
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
                return sc.apply("select", lambda t: self._select(t[0], t[1:]), [pred, *cases])

            return [elements.elementwise(shape, xs, pick)]
        if name == "clamp":
            return [elements.elementwise(shape, xs, lambda lo, v, hi: sc.apply(
                "clamp", lambda t: f"(({t[1]}) < ({t[0]}) ? ({t[0]}) : ({t[1]}) > ({t[2]}) ? ({t[2]}) : ({t[1]}))",
                [lo, v, hi]))]
        raise AssertionError(name)

    # -- helpers ----------------------------------------------------------------------------------------------------------

    def elementwise(self, expr: Callable[[list[str]], str], ins: Sequence[Ref], out: tuple[tuple[int, ...], str]) -> Ref:
        shape, dtype = out
        ref = self.em.buffer(shape, dtype)
        ct = ref.ctype

        def body(ix: list[str]) -> list[str]:
            args = [r.get(ix if r.shape == shape else broadcast(r.shape, ix)) for r in ins]
            return [f"{ref.name}[{linear(shape, ix)}] = ({ct})({expr(args)});"]

        self.em.loop(shape, body)
        return ref

    def alias(self, ref: Ref, out: tuple[tuple[int, ...], str]) -> Ref:
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

    def viewed(self, x: Ref, out: tuple[tuple[int, ...], str], index: Callable[[list[str]], list[str]]) -> Ref:
        """A view of `x`: the element at multi-index ix is x's at `index(ix)`."""
        return Ref(x.name, out[0], out[1], view=lambda ix: x.get(index(ix)))

    def copy(self, ref: Ref) -> Ref:
        if ref.elems is not None:
            return self.stored(ref)
        if ref.view is not None:
            return self.materialize(ref)
        out = self.em.buffer(ref.shape, ref.dtype)
        self.em.loop([max(ref.size, 1)], lambda ix: [f"{out.name}[{ix[0]}] = {ref.at(ix[0])};"])
        return out

    def gathered(self, shape: Sequence[int], dtype: str, source: Callable[[list[str]], str]) -> Ref:
        """A new buffer of `shape` whose element at each multi-index is `source(index variables)` (no elements: none)."""
        if 0 in shape:
            return Ref("", tuple(shape), dtype, elems=np.empty(shape, dtype=object))
        ref = self.em.buffer(shape, dtype)
        self.em.loop(shape, lambda ix: [f"{ref.name}[{linear(shape, ix)}] = ({ref.ctype})({source(ix)});"])
        return ref

    def call(self, closed: Any, ins: Sequence[Ref]) -> list[Ref]:
        jaxpr = getattr(closed, "jaxpr", closed)
        consts = getattr(closed, "consts", [])
        return Translator(self.em).run(jaxpr, consts, ins, self.used)

    # -- shape and data movement --------------------------------------------------------------------------------------

    def p_convert_element_type(self, ins: list[Ref], outs: list, new_dtype: Any, **_: Any) -> Ref:
        if np.dtype(new_dtype).name == ins[0].dtype:
            return self.alias(ins[0], outs[0])
        x = ins[0]
        if np.dtype(new_dtype).kind in "iu" and _float(x):  # XLA truncates toward zero, as C does
            return self.elementwise(lambda a: a[0], ins, outs[0])
        if np.dtype(new_dtype).kind == "b":
            return self.elementwise(lambda a: f"({a[0]}) != 0", ins, outs[0])
        return self.elementwise(lambda a: a[0], ins, outs[0])

    def p_reshape(self, ins: list[Ref], outs: list, **_: Any) -> Ref:
        return self.alias(ins[0], outs[0])

    p_squeeze = p_reshape
    p_expand_dims = p_reshape

    def p_copy(self, ins: list[Ref], outs: list, **_: Any) -> Ref:
        return self.alias(ins[0], outs[0])

    p_copy_p = p_copy
    p_stop_gradient = p_copy
    p_optimization_barrier = p_copy
    p_reduce_precision = p_copy

    def p_broadcast_in_dim(self, ins: list[Ref], outs: list, broadcast_dimensions: Sequence[int], **_: Any) -> Ref:
        x = ins[0]
        if x.scalar_expr:
            return Ref(x.name, outs[0][0], outs[0][1], scalar_expr=True)
        if x.size == int(np.prod(outs[0][0])):
            return self.alias(x, outs[0])
        return self.viewed(x, outs[0], lambda ix: ["0" if x.shape[j] == 1 else ix[d]
                                                   for j, d in enumerate(broadcast_dimensions)])

    def p_slice(self, ins: list[Ref], outs: list, start_indices: Sequence[int], strides: Sequence[int] | None = None,
                **_: Any) -> Ref:
        step = strides or [1] * len(outs[0][0])
        return self.viewed(ins[0], outs[0], lambda ix: [
            f"{int(s)} + ({i})*{int(k)}" if k != 1 else f"{int(s)} + ({i})" if s else i
            for s, i, k in zip(start_indices, ix, step, strict=True)])

    def p_rev(self, ins: list[Ref], outs: list, dimensions: Sequence[int], **_: Any) -> Ref:
        shape = outs[0][0]
        return self.viewed(ins[0], outs[0], lambda ix: [f"{shape[d] - 1} - ({i})" if d in dimensions else i
                                                        for d, i in enumerate(ix)])

    def p_tile(self, ins: list[Ref], outs: list, reps: Sequence[int], **_: Any) -> Ref:
        """The operand repeated `reps` times along each dimension: a view, the index taken modulo its size."""
        x = ins[0]
        lead = len(outs[0][0]) - len(x.shape)  # numpy's rule: the operand's shape padded with ones in front
        return self.viewed(x, outs[0], lambda ix: [f"({i}) % {n}" if n != 1 else "0"
                                                   for i, n in zip(ix[lead:], x.shape, strict=True)])

    def p_transpose(self, ins: list[Ref], outs: list, permutation: Sequence[int], **_: Any) -> Ref:
        inverse = {p: j for j, p in enumerate(permutation)}
        return self.viewed(ins[0], outs[0], lambda ix: [ix[inverse[k]] for k in range(len(ins[0].shape))])

    def p_concatenate(self, ins: list[Ref], outs: list, dimension: int, **_: Any) -> Ref:
        shape, dtype = outs[0]
        ref = self.em.buffer(shape, dtype)
        offset = 0
        for x in ins:
            def body(ix: list[str], x: Ref = x, offset: int = offset) -> list[str]:
                at = [f"{i} + {offset}" if d == dimension else i for d, i in enumerate(ix)]
                return [f"{ref.name}[{linear(shape, at)}] = ({ref.ctype}){x.get(ix)};"]

            self.em.loop(x.shape, body)
            offset += x.shape[dimension]
        return ref

    def p_stack(self, ins: list[Ref], outs: list, axis: int, **_: Any) -> Ref:
        shape, dtype = outs[0]
        ref = self.em.buffer(shape, dtype)
        for k, x in enumerate(ins):
            def body(ix: list[str], x: Ref = x, k: int = k) -> list[str]:
                at = [*ix[:axis], str(k), *ix[axis:]]
                return [f"{ref.name}[{linear(shape, at)}] = ({ref.ctype}){x.get(ix)};"]

            self.em.loop(x.shape, body)
        return ref

    def p_split(self, ins: list[Ref], outs: list, sizes: Sequence[int], axis: int, **_: Any) -> list[Ref]:
        x, result, offset = ins[0], [], 0
        for (shape, dtype), used in zip(outs, self.used, strict=True):
            def source(ix: list[str], offset: int = offset) -> str:
                return x.get([f"{i} + {offset}" if d == axis else i for d, i in enumerate(ix)])

            result.append(self.gathered(shape, dtype, source) if used else UNUSED)
            offset += shape[axis]
        return result

    def p_pad(self, ins: list[Ref], outs: list, padding_config: Sequence[tuple[int, int, int]], **_: Any) -> Ref:
        x, value, (shape, dtype) = ins[0], ins[1], outs[0]
        ref = self.em.buffer(shape, dtype)
        self.em.loop([max(ref.size, 1)], lambda ix: [f"{ref.name}[{ix[0]}] = {value.at('0')};"])

        def body(ix: list[str]) -> list[str]:
            at = [f"{lo} + {i}*{interior + 1}" for (lo, _, interior), i in zip(padding_config, ix, strict=True)]
            checks = " && ".join(f"({a}) >= 0 && ({a}) < {n}" for a, n in zip(at, shape, strict=True)) or "1"
            return [f"if ({checks}) {ref.name}[{linear(shape, at)}] = {x.get(ix)};"]

        self.em.loop(x.shape, body)
        return ref

    def p_iota(self, ins: list[Ref], outs: list, dimension: int, **_: Any) -> Ref:
        shape, dtype = outs[0]
        return self.gathered(shape, dtype, lambda ix: ix[dimension])

    @staticmethod
    def _select(pred: str, cases: Sequence[str]) -> str:
        """case[pred]: a boolean picks case 1 when true, an integer its case."""
        out = cases[-1]
        for k in range(len(cases) - 2, -1, -1):
            out = f"(({pred}) == {k} ? ({cases[k]}) : ({out}))"
        return out

    def p_select_n(self, ins: list[Ref], outs: list, **_: Any) -> Ref:
        return self.elementwise(lambda a: self._select(a[0], a[1:]), ins, outs[0])

    def p_clamp(self, ins: list[Ref], outs: list, **_: Any) -> Ref:
        return self.elementwise(lambda a: f"(({a[1]}) < ({a[0]}) ? ({a[0]}) : ({a[1]}) > ({a[2]}) ? ({a[2]}) : ({a[1]}))",
                                ins, outs[0])

    def p_integer_pow(self, ins: list[Ref], outs: list, y: int, **_: Any) -> Ref:
        def expr(a: list[str]) -> str:
            if y == 0:
                return "1"
            product = "*".join([f"({a[0]})"] * abs(y))
            return product if y > 0 else f"1.0/({product})"

        return self.elementwise(expr, ins, outs[0])

    # -- reductions ---------------------------------------------------------------------------------------------------

    def _reduce(self, ins: list[Ref], outs: list, axes: Sequence[int], init: str, update: str) -> Ref:
        x, (shape, dtype) = ins[0], outs[0]
        ref = self.em.buffer(shape, dtype)
        self.em.loop([max(ref.size, 1)], lambda ix: [f"{ref.name}[{ix[0]}] = {init};"])
        kept = [d for d in range(len(x.shape)) if d not in axes]

        def body(ix: list[str]) -> list[str]:
            out = f"{ref.name}[{linear(shape, [ix[d] for d in kept])}]"
            return [f"{out} = " + update.format(acc=out, x=x.get(ix)) + ";"]

        self.em.loop(x.shape, body)
        return ref

    def p_reduce_sum(self, ins: list[Ref], outs: list, axes: Sequence[int], **_: Any) -> Ref:
        return self._reduce(ins, outs, axes, "0", "{acc} + {x}")

    def p_reduce_prod(self, ins: list[Ref], outs: list, axes: Sequence[int], **_: Any) -> Ref:
        return self._reduce(ins, outs, axes, "1", "{acc} * {x}")

    def p_reduce_max(self, ins: list[Ref], outs: list, axes: Sequence[int], **_: Any) -> Ref:
        low = "(-INFINITY)" if _float(ins[0]) else f"{np.iinfo(ins[0].dtype).min}"
        return self._reduce(ins, outs, axes, low, _max("{acc}", "{x}", ins[0], ">"))

    def p_reduce_min(self, ins: list[Ref], outs: list, axes: Sequence[int], **_: Any) -> Ref:
        high = "INFINITY" if _float(ins[0]) else f"{np.iinfo(ins[0].dtype).max}"
        return self._reduce(ins, outs, axes, high, _max("{acc}", "{x}", ins[0], "<"))

    def p_reduce_and(self, ins: list[Ref], outs: list, axes: Sequence[int], **_: Any) -> Ref:
        return self._reduce(ins, outs, axes, "1", "{acc} && {x}")

    def p_reduce_or(self, ins: list[Ref], outs: list, axes: Sequence[int], **_: Any) -> Ref:
        return self._reduce(ins, outs, axes, "0", "{acc} || {x}")

    def _cumulative(self, ins: list[Ref], outs: list, axis: int, reverse: bool, op: str) -> Ref:
        x, (shape, dtype) = ins[0], outs[0]
        ref = self.em.buffer(shape, dtype)
        others = [n if d != axis else 1 for d, n in enumerate(shape)]
        n = shape[axis]

        def body(ix: list[str]) -> list[str]:
            k = self.em.fresh("k")
            pos = f"{n - 1} - {k}" if reverse else k
            prev = f"{pos} + 1" if reverse else f"{pos} - 1"
            here = [pos if d == axis else i for d, i in enumerate(ix)]
            at, value = linear(shape, here), x.get(here)
            before = linear(shape, [prev if d == axis else i for d, i in enumerate(ix)])
            combine = {"add": f"{ref.name}[{before}] + {value}", "mul": f"{ref.name}[{before}] * {value}",
                       "max": _max(f"{ref.name}[{before}]", value, x, ">"),
                       "min": _max(f"{ref.name}[{before}]", value, x, "<")}[op]
            return [f"for (int {k} = 0; {k} < {n}; {k}++) {{",
                    f"    {ref.name}[{at}] = {k} == 0 ? {value} : {combine};", "}"]

        self.em.loop(others, body)
        return ref

    def p_cumsum(self, ins: list[Ref], outs: list, axis: int, reverse: bool = False, **_: Any) -> Ref:
        return self._cumulative(ins, outs, axis, reverse, "add")

    def p_cumprod(self, ins: list[Ref], outs: list, axis: int, reverse: bool = False, **_: Any) -> Ref:
        return self._cumulative(ins, outs, axis, reverse, "mul")

    def p_cummax(self, ins: list[Ref], outs: list, axis: int, reverse: bool = False, **_: Any) -> Ref:
        return self._cumulative(ins, outs, axis, reverse, "max")

    def p_cummin(self, ins: list[Ref], outs: list, axis: int, reverse: bool = False, **_: Any) -> Ref:
        return self._cumulative(ins, outs, axis, reverse, "min")

    def p_dot_general(self, ins: list[Ref], outs: list, dimension_numbers: Any, **_: Any) -> Ref:
        (lc, rc), (lb, rb) = dimension_numbers
        a, b, (shape, dtype) = ins[0], ins[1], outs[0]
        ref = self.em.buffer(shape, dtype)
        lfree = [d for d in range(len(a.shape)) if d not in lc and d not in lb]
        rfree = [d for d in range(len(b.shape)) if d not in rc and d not in rb]
        sizes = [a.shape[d] for d in lc]

        def body(ix: list[str]) -> list[str]:
            ks = [self.em.fresh("k") for _ in lc]
            nb = len(lb)
            ai = [ix[list(lb).index(d)] if d in lb else ks[list(lc).index(d)] if d in lc else
                  ix[nb + lfree.index(d)] for d in range(len(a.shape))]
            bi = [ix[list(rb).index(d)] if d in rb else ks[list(rc).index(d)] if d in rc else
                  ix[nb + len(lfree) + rfree.index(d)] for d in range(len(b.shape))]
            acc = self.em.fresh("s")
            lines = [f"{ref.ctype} {acc} = 0;"]
            lines += [f"{'    ' * j}for (int {k} = 0; {k} < {n}; {k}++) {{" for j, (k, n) in enumerate(zip(ks, sizes,
                                                                                                          strict=True))]
            lines.append(f"{'    ' * len(ks)}{acc} += {a.get(ai)} * {b.get(bi)};")
            lines += [f"{'    ' * j}}}" for j in range(len(ks) - 1, -1, -1)]
            return [*lines, f"{ref.name}[{linear(shape, ix)}] = {acc};"]

        self.em.loop(shape, body)
        return ref

    # -- dynamic indexing ---------------------------------------------------------------------------------------------

    def _start(self, start: Ref, dim: int, size: int) -> str:
        s = start.at("0")
        return f"(({s}) < 0 ? 0 : ({s}) > {dim - size} ? {dim - size} : ({s}))"

    def p_dynamic_slice(self, ins: list[Ref], outs: list, slice_sizes: Sequence[int], **_: Any) -> Ref:
        x, starts, (shape, dtype) = ins[0], ins[1:], outs[0]
        names = []
        for d, s in enumerate(starts):
            name = self.em.fresh("o")
            self.em.emit(f"const int64_t {name} = {self._start(s, x.shape[d], slice_sizes[d])};")
            names.append(name)
        return self.gathered(shape, dtype, lambda ix: x.get([f"{o} + {i}" for o, i in zip(names, ix,
                                                                                                         strict=True)]))

    def p_dynamic_update_slice(self, ins: list[Ref], outs: list, **_: Any) -> Ref:
        x, update, starts = ins[0], ins[1], ins[2:]
        ref = self.copy(x)
        names = []
        for d, s in enumerate(starts):
            name = self.em.fresh("o")
            self.em.emit(f"const int64_t {name} = {self._start(s, x.shape[d], update.shape[d])};")
            names.append(name)
        self.em.loop(update.shape, lambda ix: [
            f"{ref.name}[{linear(x.shape, [f'{o} + {i}' for o, i in zip(names, ix, strict=True)])}] = "
            f"{update.get(ix)};"])
        return ref

    def _operand_index(self, x: Ref, indices: Ref, batch: list[str], offsets: dict[int, str], batching: dict[int, int],
                       mapped: Sequence[int], sizes: Sequence[int], drop: bool) -> tuple[list[str], list[str], list[str]]:
        """One element of a gather's or scatter's window in the operand `x`: (declarations of the window's starts, the
        operand's multi-index, the conditions that the window is in range). `batch`: the position in the indices'
        batch dimensions (index_vector_dim last); `offsets`: the element's offset per window dimension; `batching`:
        operand dimension → the indices' batch dimension it follows; `mapped`: the operand dimensions the index vector
        starts; `sizes`: the window's size per operand dimension; `drop`: out-of-range windows are dropped (a condition)
        rather than clamped."""
        lines, at, inside = [], [], []
        for d in range(len(x.shape)):
            offset = offsets.get(d, "0")
            if d in batching:
                at.append(batch[batching[d]])
            elif d in mapped:
                s = self.em.fresh("o")
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

    def p_gather(self, ins: list[Ref], outs: list, dimension_numbers: Any, slice_sizes: Sequence[int], mode: Any,
                 fill_value: Any = None, **_: Any) -> Ref:
        x, indices, (shape, dtype) = ins[0], ins[1], outs[0]
        dn = dimension_numbers
        offset_dims, collapsed, start_map = list(dn.offset_dims), list(dn.collapsed_slice_dims), list(dn.start_index_map)
        batching = dict(zip(dn.operand_batching_dims, dn.start_indices_batching_dims, strict=True))
        fill = "FILL_OR_DROP" in str(mode)
        window = [d for d in range(len(x.shape)) if d not in collapsed and d not in batching]
        ref = self.em.buffer(shape, dtype)

        def body(ix: list[str]) -> list[str]:
            batch = [i for d, i in enumerate(ix) if d not in offset_dims]
            offs = {window[j]: ix[d] for j, d in enumerate(offset_dims)}
            lines, at, inside = self._operand_index(x, indices, batch, offs, batching, start_map, slice_sizes, fill)
            value = x.get(at)
            if inside:
                value = f"({' && '.join(inside)}) ? {value} : {_fill(fill_value, dtype)}"
            return [*lines, f"{ref.name}[{linear(shape, ix)}] = {value};"]

        self.em.loop(shape, body)
        return ref

    def _scatter(self, ins: list[Ref], outs: list, dimension_numbers: Any, mode: Any, combine: str) -> Ref:
        x, indices, updates = ins[0], ins[1], ins[2]
        dn = dimension_numbers
        window_dims, inserted, to_operand = list(dn.update_window_dims), list(dn.inserted_window_dims), list(
            dn.scatter_dims_to_operand_dims)
        batching = dict(zip(dn.operand_batching_dims, dn.scatter_indices_batching_dims, strict=True))
        drop = "FILL_OR_DROP" in str(mode) or "PROMISE" not in str(mode) and "CLIP" not in str(mode)
        ref = self.copy(x)
        window = [d for d in range(len(x.shape)) if d not in inserted and d not in batching]
        window_size = {window[j]: updates.shape[d] for j, d in enumerate(window_dims)}

        sizes = [window_size.get(d, 1) for d in range(len(x.shape))]

        def body(ix: list[str]) -> list[str]:
            batch = [i for d, i in enumerate(ix) if d not in window_dims]
            offs = {window[j]: ix[d] for j, d in enumerate(window_dims)}
            lines, at, inside = self._operand_index(x, indices, batch, offs, batching, to_operand, sizes, drop)
            target = f"{ref.name}[{linear(x.shape, at)}]"
            value = updates.get(ix)
            statement = f"{target} = {combine.format(acc=target, x=value)};"
            return [*lines, f"if ({' && '.join(inside)}) {statement}" if inside else statement]

        self.em.loop(updates.shape, body)
        return ref

    def p_scatter(self, ins: list[Ref], outs: list, dimension_numbers: Any, mode: Any, **_: Any) -> Ref:
        return self._scatter(ins, outs, dimension_numbers, mode, "{x}")

    def p_scatter_add(self, ins: list[Ref], outs: list, dimension_numbers: Any, mode: Any, **_: Any) -> Ref:
        return self._scatter(ins, outs, dimension_numbers, mode, "{acc} + {x}")

    # -- nested programs ----------------------------------------------------------------------------------------------

    def p_jit(self, ins: list[Ref], outs: list, jaxpr: Any, **_: Any) -> list[Ref]:
        """Inlined; a program called more than once (an RK4 step's rate) and not small is a C function of its own,
        translated once: a quarter of the text for gcc, the same arithmetic."""
        if self.em.calls.get(id(jaxpr), 0) < 2 or len(jaxpr.jaxpr.eqns) < FUNCTION_MIN:
            return self.call(jaxpr, ins)
        key = (id(jaxpr), tuple(self.used), tuple((r.shape, r.dtype, r.name if _inside(r) else None,
                                                   None if r.zeros is None else r.zeros.tobytes()) for r in ins))
        if key not in self.em.defined:
            self.em.defined[key] = self._function(jaxpr, ins, outs)
        name, kept = self.em.defined[key]
        pointers = [self._pointer(r) for r in ins if not _inside(r)]
        results = [self.em.buffer(*outs[k]) for k in kept]
        self.em.emit(f"{name}({', '.join(pointers + [r.name for r in results])});")
        found = dict(zip(kept, results, strict=True))
        return [found.get(k, UNUSED) for k in range(len(outs))]

    def _function(self, closed: Any, ins: list[Ref], outs: list) -> tuple[str, list[int]]:
        """`static void NAME(const T *a0, …, T *r0, …)` computing `closed` on arguments shaped like `ins`, written to the
        emitter's functions: (NAME, the outputs it writes: those read)."""
        name = self.em.fresh(f"{self.em.tag}_f")  # unique: a function defined inside this one is named first
        args = [r if _inside(r) else Ref(f"a{k}", r.shape, r.dtype, zeros=r.zeros) for k, r in enumerate(ins)]
        used = self.used

        def fill(sub: Emitter) -> tuple[list[int], list[Ref]]:
            values = Translator(sub).run(closed.jaxpr, closed.consts, args, used)
            kept = [k for k, v in enumerate(values) if v is not UNUSED]
            returns = [Ref(f"r{k}", *outs[k]) for k in kept]
            for target, k in zip(returns, kept, strict=True):
                Translator(sub)._copy_into(target, values[k], "0", max(target.size, 1))
            return kept, returns

        sub, (kept, returns) = _body(self.em.nested, fill)
        params = [f"const {a.ctype} *{a.name}" for a in args if not _inside(a)] + [f"{r.ctype} *{r.name}"
                                                                                    for r in returns]
        self.em.functions.append("\n".join([f"static void {name}({', '.join(params)}) {{", *elements.prune(sub.lines),
                                            "}", ""]))
        return name, kept

    def _pointer(self, ref: Ref) -> str:
        """A pointer to `ref`'s elements: a buffer as it is, a view or a scalar expression stored first."""
        if ref.scalar_expr:
            ref = self.gathered(ref.shape, ref.dtype, lambda ix: ref.name)
        return self.materialize(ref).name

    p_pjit = p_jit
    p_closed_call = p_jit
    p_core_call = p_jit

    def p_custom_jvp_call(self, ins: list[Ref], outs: list, call_jaxpr: Any, **_: Any) -> list[Ref]:
        return self.call(call_jaxpr, ins)

    def p_custom_vjp_call(self, ins: list[Ref], outs: list, **params: Any) -> list[Ref]:
        return self.call(params.get("call_jaxpr", params.get("fun_jaxpr")), ins)

    p_custom_vjp_call_jaxpr = p_custom_vjp_call

    def p_remat(self, ins: list[Ref], outs: list, jaxpr: Any, **_: Any) -> list[Ref]:
        return self.call(jaxpr, ins)

    p_checkpoint = p_remat

    def p_custom_linear_solve(self, ins: list[Ref], outs: list, const_lengths: Any, jaxprs: Any, **_: Any) -> list[Ref]:
        """x = solve(b): the `solve` program with its constants (matvec's and the transposes' are for derivatives)."""
        lengths = [const_lengths.matvec, const_lengths.vecmat, const_lengths.solve, const_lengths.transpose_solve]
        start = sum(lengths[:2])
        consts, b = ins[start : start + lengths[2]], ins[sum(lengths):]
        return self.call(jaxprs.solve, [*consts, *b])

    # -- control flow -------------------------------------------------------------------------------------------------

    def _assign(self, targets: Sequence[Ref], values: Sequence[Ref]) -> None:
        """targets ← values, every value read before any target is written (a value may alias another target)."""
        staged = [self.copy(v) for v in values]
        for target, value in zip(targets, staged, strict=True):
            self._copy_into(target, value, "0", max(target.size, 1))

    def _copy_into(self, target: Ref, value: Ref, offset: str, size: int) -> None:
        """target[offset + i] = value[i] for i < size."""
        if value.elems is not None:
            for i, e in enumerate(value.elems.flat):
                self.em.emit(f"{target.name}[{offset} + {i}] = {text(e)};")
            return

        def body(ix: list[str]) -> list[str]:
            return [f"{target.name}[{offset} + {ix[0]}] = {value.at(ix[0])};"]

        self.em.loop([size], body)

    def _block(self, opening: str, fill: Callable[[], None]) -> None:
        self.em.emit(opening)
        self.em.depth += 1
        self.em.scalars.open()
        fill()
        self.em.scalars.close()
        self.em.depth -= 1
        self.em.emit("}")

    def p_while(self, ins: list[Ref], outs: list, cond_jaxpr: Any, body_jaxpr: Any, cond_nconsts: int,
                body_nconsts: int, **_: Any) -> list[Ref]:
        """`for (;;)`: the condition on the carry, break when false, the body, the carry replaced."""
        cond_consts, body_consts = ins[:cond_nconsts], ins[cond_nconsts : cond_nconsts + body_nconsts]
        carry = [self.copy(r) for r in ins[cond_nconsts + body_nconsts :]]

        def fill() -> None:
            pred = Translator(self.em).run(cond_jaxpr.jaxpr, cond_jaxpr.consts, [*cond_consts, *carry])[0]
            self.em.emit(f"if (!({pred.at('0')})) break;")
            self._assign(carry, Translator(self.em).run(body_jaxpr.jaxpr, body_jaxpr.consts, [*body_consts, *carry]))

        self._block("for (;;) {", fill)
        return carry

    def p_scan(self, ins: list[Ref], outs: list, jaxpr: Any, length: int, reverse: bool, num_consts: int,
               num_carry: int, **_: Any) -> list[Ref]:
        """A loop of `length` iterations: the body on the consts, the carry and the i-th slices of xs; the carry
        replaced, the i-th slices of ys written."""
        consts, xs = ins[:num_consts], [self.materialize(x) for x in ins[num_consts + num_carry :]]
        carry = [self.copy(r) for r in ins[num_consts : num_consts + num_carry]]
        ys = [self.em.buffer(shape, dtype) for shape, dtype in outs[num_carry:]]
        it, at = self.em.fresh("t"), self.em.fresh("j")

        def fill() -> None:
            self.em.emit(f"const int64_t {at} = {f'{length - 1} - {it}' if reverse else it};")
            slices = [Ref(f"({x.name} + {at}*{max(int(np.prod(x.shape[1:])), 1)})", x.shape[1:], x.dtype) for x in xs]
            new = Translator(self.em).run(jaxpr.jaxpr, jaxpr.consts, [*consts, *carry, *slices])
            for y, value in zip(ys, new[num_carry:], strict=True):  # before the carry moves: a y may alias it
                size = max(int(np.prod(y.shape[1:])), 1)
                self._copy_into(y, value, f"{at}*{size}", size)
            self._assign(carry, new[:num_carry])

        self._block(f"for (int64_t {it} = 0; {it} < {int(length)}; {it}++) {{", fill)
        return [*carry, *ys]

    def p_cond(self, ins: list[Ref], outs: list, branches: Sequence[Any], **_: Any) -> list[Ref]:
        """The branch of the (clamped) index, its outputs copied into buffers declared before."""
        index, operands = ins[0].at("0"), ins[1:]
        results = [self.em.buffer(shape, dtype) for shape, dtype in outs]
        for k, branch in enumerate(branches):
            test = f"if (({index}) <= 0) {{" if k == 0 else f"}} else if (({index}) == {k}) {{" if k < len(
                branches) - 1 else "} else {"
            self.em.emit(test)
            self.em.depth += 1
            self.em.scalars.open()
            self._assign(results, Translator(self.em).run(branch.jaxpr, branch.consts, operands))
            self.em.scalars.close()
            self.em.depth -= 1
        self.em.emit("}")
        return results

    # -- small dense linear algebra -----------------------------------------------------------------------------------

    def p_cholesky(self, ins: list[Ref], outs: list, **_: Any) -> Ref:
        """L with A = L Lᵀ (lower; zeros above the diagonal), per leading batch index; NaN where A is not positive
        definite (as XLA)."""
        a, (shape, dtype) = ins[0], outs[0]
        n = shape[-1]
        ref = self.em.buffer(shape, dtype)
        batch = int(np.prod(shape[:-2], dtype=np.int64))
        b, i, j, k, s = (self.em.fresh(p) for p in "bijks")
        base = f"{b}*{n * n}"
        for line in [
            f"for (int {b} = 0; {b} < {batch}; {b}++) {{",
            f"    for (int {i} = 0; {i} < {n * n}; {i}++) {ref.name}[{base} + {i}] = 0;",
            f"    for (int {j} = 0; {j} < {n}; {j}++) {{",
            f"        double {s} = {a.at(f'{base} + {j}*{n} + {j}')};",
            f"        for (int {k} = 0; {k} < {j}; {k}++) {s} -= {ref.name}[{base} + {j}*{n} + {k}] * "
            f"{ref.name}[{base} + {j}*{n} + {k}];",
            f"        {ref.name}[{base} + {j}*{n} + {j}] = sqrt({s});",
            f"        for (int {i} = {j} + 1; {i} < {n}; {i}++) {{",
            f"            double t_ = {a.at(f'{base} + {i}*{n} + {j}')};",
            f"            for (int {k} = 0; {k} < {j}; {k}++) t_ -= {ref.name}[{base} + {i}*{n} + {k}] * "
            f"{ref.name}[{base} + {j}*{n} + {k}];",
            f"            {ref.name}[{base} + {i}*{n} + {j}] = t_ / {ref.name}[{base} + {j}*{n} + {j}];",
            "        }",
            "    }",
            "}",
        ]:
            self.em.emit(line)
        return ref

    def p_triangular_solve(self, ins: list[Ref], outs: list, left_side: bool, lower: bool, transpose_a: bool,
                           unit_diagonal: bool, conjugate_a: bool = False, **_: Any) -> Ref:
        """X with op(A) X = B (left_side) or X op(A) = B, op(A) = A or Aᵀ, A triangular; per leading batch index."""
        a, b, (shape, _) = ins[0], ins[1], outs[0]
        n = a.shape[-1]
        ref = self.copy(b)
        m, r = shape[-2], shape[-1]
        batch = int(np.prod(shape[:-2], dtype=np.int64))
        # the system is solved column by column of X (left) or row by row (right: X op(A) = B ⇔ op(A)ᵀ Xᵀ = Bᵀ)
        effective_lower = lower != transpose_a  # op(A) lower triangular?
        transposed = transpose_a
        if not left_side:
            effective_lower, transposed = not effective_lower, not transpose_a
        count, stride_e, stride_c = (r, r, 1) if left_side else (m, 1, r)  # elements of one system: stride_e apart
        bi, c, i, k, s = (self.em.fresh(p) for p in "bciks")

        def A(row: str, col: str) -> str:  # element of the matrix M = op(A) or op(A)ᵀ actually solved: M x = y
            return a.at(f"{bi}*{n * n} + ({col})*{n} + ({row})" if transposed else f"{bi}*{n * n} + ({row})*{n} + ({col})")

        order = f"int {i} = 0; {i} < {n}; {i}++" if effective_lower else f"int {i} = {n - 1}; {i} >= 0; {i}--"
        inner = f"int {k} = 0; {k} < {i}; {k}++" if effective_lower else f"int {k} = {i} + 1; {k} < {n}; {k}++"
        x = f"{ref.name}[{bi}*{m * r} + {c}*{stride_c} + ({{}})*{stride_e}]"
        for line in [
            f"for (int {bi} = 0; {bi} < {batch}; {bi}++) for (int {c} = 0; {c} < {count}; {c}++) {{",
            f"    for ({order}) {{",
            f"        double {s} = {x.format(i)};",
            f"        for ({inner}) {s} -= {A(i, k)} * {x.format(k)};",
            f"        {x.format(i)} = {s if unit_diagonal else f'{s} / {A(i, i)}'};",
            "    }",
            "}",
        ]:
            self.em.emit(line)
        return ref

    def p_lu(self, ins: list[Ref], outs: list, **_: Any) -> list[Ref]:
        """P A = L U with partial pivoting (LAPACK getrf: the largest |a| first): the packed LU, the pivots (row
        swapped with at each step) and the permutation."""
        a = ins[0]
        (shape, dtype), (pshape, pdtype), (qshape, qdtype) = outs
        n = shape[-1]
        if shape[-2] != n:
            raise Unsupported("LU of a non-square matrix")
        batch = int(np.prod(shape[:-2], dtype=np.int64))
        lu, piv, perm = self.copy(a), self.em.buffer(pshape, pdtype), self.em.buffer(qshape, qdtype)
        b, i, j, k, p = (self.em.fresh(x) for x in "bijkp")
        A = lambda r, c: f"{lu.name}[{b}*{n * n} + ({r})*{n} + ({c})]"  # noqa: E731
        P = lambda r: f"{perm.name}[{b}*{n} + ({r})]"  # noqa: E731
        for line in [
            f"for (int {b} = 0; {b} < {batch}; {b}++) {{",
            f"for (int {i} = 0; {i} < {n}; {i}++) {P(i)} = {i};",
            f"for (int {k} = 0; {k} < {n}; {k}++) {{",
            f"    int {p} = {k};",
            f"    for (int {i} = {k} + 1; {i} < {n}; {i}++) if (fabs({A(i, k)}) > fabs({A(p, k)})) {p} = {i};",
            f"    {piv.name}[{b}*{n} + {k}] = {p};",
            f"    if ({p} != {k}) {{",
            f"        for (int {j} = 0; {j} < {n}; {j}++) {{ double t_ = {A(k, j)}; {A(k, j)} = {A(p, j)}; "
            f"{A(p, j)} = t_; }}",
            f"        {{ {perm.ctype} t_ = {P(k)}; {P(k)} = {P(p)}; {P(p)} = t_; }}",
            "    }",
            f"    for (int {i} = {k} + 1; {i} < {n}; {i}++) {{",
            f"        {A(i, k)} /= {A(k, k)};",
            f"        for (int {j} = {k} + 1; {j} < {n}; {j}++) {A(i, j)} -= {A(i, k)} * {A(k, j)};",
            "    }",
            "}",
            "}",
        ]:
            self.em.emit(line)
        return [lu, piv, perm]

    def p_sort(self, ins: list[Ref], outs: list, dimension: int, is_stable: bool, num_keys: int, **_: Any) -> list[Ref]:
        """A stable insertion sort along `dimension` by the first `num_keys` operands (lexicographic), every operand
        permuted alike."""
        if num_keys != 1:
            raise Unsupported("sort by several keys")
        refs = [self.copy(x) for x in ins]
        shape = ins[0].shape
        n = shape[dimension]
        others = [s if d != dimension else 1 for d, s in enumerate(shape)]

        def body(ix: list[str]) -> list[str]:
            a, b = self.em.fresh("a"), self.em.fresh("b")
            at = lambda e: linear(shape, [e if d == dimension else i for d, i in enumerate(ix)])  # noqa: E731
            key = refs[0].name
            swap = " ".join(f"{{ {r.ctype} t_ = {r.name}[{at(b)}]; {r.name}[{at(b)}] = {r.name}[{at(f'{b} - 1')}]; "
                            f"{r.name}[{at(f'{b} - 1')}] = t_; }}" for r in refs)
            return [f"for (int {a} = 1; {a} < {n}; {a}++)",
                    f"    for (int {b} = {a}; {b} > 0 && {key}[{at(b)}] < {key}[{at(f'{b} - 1')}]; {b}--) {swap}"]

        self.em.loop(others, body)
        return refs


PRIMITIVES = tuple(sorted({*UNARY, *BINARY, *(name[2:] for name in dir(Translator) if name.startswith("p_"))}))


def translate(closed: Any, name: str, arg_names: Sequence[str] | None = None,
              out_names: Sequence[str] | None = None, zeros: Sequence[np.ndarray | None] = ()) -> str:
    """The C99 text of `static void name(const T *in…, T *out…)` computing the ClosedJaxpr `closed` (module
    docstring); its constants become static arrays before the function. `zeros[k]`, where given, marks the elements of
    input k that are zero in every call (the program is then valid only for such inputs)."""
    jaxpr = closed.jaxpr
    first = Emitter(tag=name, calls=_calls(jaxpr, {}))
    masks: list[np.ndarray | None] = [None if z is None or not np.any(z) else np.asarray(z, bool) for z in zeros]
    masks += [None] * (len(jaxpr.invars) - len(masks))
    args = [Ref(arg_names[k] if arg_names else f"in{k}", tuple(v.aval.shape), np.dtype(v.aval.dtype).name,
                zeros=None if mask is None else mask.reshape(v.aval.shape))
            for k, (v, mask) in enumerate(zip(jaxpr.invars, masks, strict=True))]
    outs = [Ref(out_names[k] if out_names else f"out{k}", tuple(v.aval.shape), np.dtype(v.aval.dtype).name)
            for k, v in enumerate(jaxpr.outvars)]

    def fill(em: Emitter) -> None:
        translator = Translator(em)
        # a view may read an input that an output overwrites: views are stored before any output is written
        results = [translator.materialize(r) for r in translator.run(jaxpr, closed.consts, args)]
        for out, value in zip(outs, results, strict=True):  # last: an output may alias an input
            def copy(ix: list[str], out: Ref = out, value: Ref = value) -> list[str]:
                return [f"{out.name}[{ix[0]}] = ({out.ctype}){value.at(ix[0])};"]

            em.loop([max(out.size, 1)], copy)

    em, _ = _body(lambda hold=True: first if hold else first.nested(hold=False), fill)
    params = [f"const {a.ctype} *{a.name}" for a in args] + [f"{o.ctype} *{o.name}" for o in outs]
    body = "\n".join([*em.functions, f"static void {name}({', '.join(params)}) {{", *elements.prune(em.lines), "}",
                      ""])
    used = set(re.findall(rf"\b{re.escape(name)}_c\d+\b", body))  # a constant read only as elements is not declared
    return "\n".join([*(c for c in em.consts if c.split()[3].split("[")[0] in used), body])


T = TypeVar("T")


def _body(make: Callable[..., Emitter], fill: Callable[[Emitter], T]) -> tuple[Emitter, T]:
    """A C function's body: `fill` on `make()`, an emitter that holds small values as elements, and again on
    `make(hold=False)` where that gave a function gcc builds slowly (:func:`robotadapt.native.elements.crowded`)."""
    em = make()
    out = fill(em)
    if elements.crowded(em.scalars.declared, em.loops):
        em = make(hold=False)
        out = fill(em)
    return em, out


def _inside(ref: Ref) -> bool:
    """Whether an operand of a nested program's C function is a constant array it reads in place (the model's
    geometry, which JAX hoists out of the program as an operand) rather than an argument: its elements fold."""
    return ref.value is not None and ref.shape != ()


def _calls(jaxpr: Any, counts: dict[int, int]) -> dict[int, int]:
    """How many call sites each nested program (a jit's jaxpr) has in `jaxpr` and the programs inside it."""
    for eqn in jaxpr.eqns:
        if eqn.primitive.name in CALLS:
            counts[id(eqn.params["jaxpr"])] = counts.get(id(eqn.params["jaxpr"]), 0) + 1
        for value in eqn.params.values():
            for sub in value if isinstance(value, (tuple, list)) else [value]:
                inner = getattr(sub, "jaxpr", sub)
                if hasattr(inner, "eqns"):
                    _calls(inner, counts)
    return counts
