"""A translator from a traced JAX program (a jaxpr) to one C99 function: static shapes, no allocation, libm only
(docs/native.md).

`translate(closed, name)` returns the text of `static void name(const T *in0, …, T *out0, …)`: every input and output
a flat row-major array of its aval's size and C type (float64 → double, int32/int64 → int32_t/int64_t, bool →
uint8_t). Each equation of the jaxpr becomes a loop nest over its output's static shape that reads its operands
through linear index expressions; values that only rename a buffer (reshape, squeeze, expand_dims, a cast to the same
type, copy) share it, nested calls (jit, custom_jvp/custom_vjp, custom_linear_solve's solve) are inlined, and the
outputs are copied out last, so an output may alias an input (a state updated in place). Temporaries are local arrays;
those over :data:`.emitter.STACK_LIMIT` elements are `static` (the function is then not reentrant: one caller at a
time). A small float64 value is instead held element by element as straight-line C, folded and numbered
(:mod:`.elements`, :mod:`.held`).

Every primitive the project's controller ticks and plant steps use is here (:data:`PRIMITIVES`); another raises
:class:`Unsupported`, naming it. Semantics follow XLA's: integer division and remainder truncate, max/min propagate
NaN, dynamic slices clamp their start, gather and scatter clamp (CLIP, PROMISE_IN_BOUNDS) or drop (FILL_OR_DROP)
out-of-range windows as their mode says.

This module is the core: the walk of a jaxpr (:class:`Translator`), nested programs (inlined, or a C function of
their own) and :func:`translate`. The primitives' handlers are by family: :mod:`.arithmetic`, :mod:`.shapes`,
:mod:`.indexing`, :mod:`.reductions`, :mod:`.control`, :mod:`.linalg`, on what they share (:mod:`.lowering`,
:mod:`.emitter`, :mod:`.values`).
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import numpy as np

from ..tracing import CALLS
from . import arithmetic, control, elements, indexing, linalg, reductions, shapes
from .arithmetic import BINARY, UNARY
from .emitter import Emitter
from .held import held, holds
from .lowering import Handler, Lowering
from .values import UNUSED, Aval, Ref, Unsupported, c_type

__all__ = ["FUNCTION_MIN", "PRIMITIVES", "Translator", "Unsupported", "c_type", "translate"]

FUNCTION_MIN = 50  # a nested program of at least this many equations, called more than once, is a C function
# primitives that pass their operands on to nested programs (which may read held values) rather than loop over them
NESTING = (*CALLS, "custom_jvp_call", "custom_vjp_call", "custom_vjp_call_jaxpr", "remat", "checkpoint",
           "custom_linear_solve", "while", "scan", "cond")


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


def _known(eqn: Any, ins: list[Ref], outs: list[Aval]) -> list[np.ndarray] | None:
    """The results of an equation on constants only (an identity matrix built from iota, a mask), small: computed now
    by JAX, so that they fold; None otherwise."""
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


class Translator(Lowering):
    """Translates one jaxpr (with its constants) into statements of an :class:`Emitter`. Primitive `name`'s handler
    (:data:`HANDLERS`) is its attribute `p_name`: one taken away, the translator names the primitive it lacks."""

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

    def apart(self, closed: Any, ins: Sequence[Ref], outs: Sequence[Aval]) -> list[Ref]:
        """A nested program's outputs from a call of its C function, defined once per program and operands' layout
        (:func:`_function`); the outputs this translator's `used` marks, the others :data:`UNUSED`."""
        key = (id(closed), tuple(self.used), tuple((r.shape, r.dtype, r.name if _inside(r) else None,
                                                    None if r.zeros is None else r.zeros.tobytes()) for r in ins))
        if key not in self.em.defined:
            self.em.defined[key] = _function(self, closed, list(ins), list(outs))
        name, kept = self.em.defined[key]
        pointers = [_pointer(self, r) for r in ins if not _inside(r)]
        results = [self.em.buffer(*outs[k]) for k in kept]
        self.em.emit(f"{name}({', '.join(pointers + [r.name for r in results])});")
        found = dict(zip(kept, results, strict=True))
        return [found.get(k, UNUSED) for k in range(len(outs))]

    def equation(self, eqn: Any, ins: list[Ref]) -> list[Ref]:
        """The values of one equation's outputs: computed now (constants), held as elements (:mod:`.held`), else
        written by its primitive's expression or handler."""
        name = eqn.primitive.name
        handler = getattr(self, "p_" + name.replace("-", "_"), None)
        outs = [(tuple(v.aval.shape), np.dtype(v.aval.dtype).name) for v in eqn.outvars]
        known = _known(eqn, ins, outs)
        if known is not None:
            return [self.em.constant(v) for v in known]
        if holds(self.em, name, ins, outs, eqn.params):
            values = held(self.em.scalars, name, ins, outs, eqn.params)
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
        result = handler(self, ins, outs, **eqn.params)
        return result if isinstance(result, list) else [result]


# -- nested programs ----------------------------------------------------------------------------------------------------

def jit(t: Translator, ins: list[Ref], outs: list[Aval], jaxpr: Any, **_: Any) -> list[Ref]:
    """Inlined; a program called more than once (an RK4 step's rate) and not small is a C function of its own,
    translated once: a quarter of the text for gcc, the same arithmetic."""
    if t.em.calls.get(id(jaxpr), 0) < 2 or len(jaxpr.jaxpr.eqns) < FUNCTION_MIN:
        return t.call(jaxpr, ins, t.used)
    return t.apart(jaxpr, ins, outs)


def _function(t: Translator, closed: Any, ins: list[Ref], outs: list[Aval]) -> tuple[str, list[int]]:
    """`static void NAME(const T *a0, …, T *r0, …)` computing `closed` on arguments shaped like `ins`, written to the
    emitter's functions: (NAME, the outputs it writes: those read)."""
    name = t.em.fresh(f"{t.em.tag}_f")  # unique: a function defined inside this one is named first
    args = [r if _inside(r) else Ref(f"a{k}", r.shape, r.dtype, zeros=r.zeros) for k, r in enumerate(ins)]
    used = t.used

    def fill(sub: Emitter) -> tuple[list[int], list[Ref]]:
        values = Translator(sub).run(closed.jaxpr, closed.consts, args, used)
        kept = [k for k, v in enumerate(values) if v is not UNUSED]
        returns = [Ref(f"r{k}", *outs[k]) for k in kept]
        for target, k in zip(returns, kept, strict=True):
            Translator(sub).copy_into(target, values[k], "0", max(target.size, 1))
        return kept, returns

    sub, (kept, returns) = _body(t.em.nested, fill)
    params = [f"const {a.ctype} *{a.name}" for a in args if not _inside(a)] + [f"{r.ctype} *{r.name}" for r in returns]
    t.em.functions.append("\n".join([f"static void {name}({', '.join(params)}) {{", *elements.prune(sub.lines), "}",
                                     ""]))
    return name, kept


def _pointer(t: Translator, ref: Ref) -> str:
    """A pointer to `ref`'s elements: a buffer as it is, a view or a scalar expression stored first."""
    if ref.scalar_expr:
        ref = t.gathered(ref.shape, ref.dtype, lambda ix: ref.name)
    return t.materialize(ref).name


def _inside(ref: Ref) -> bool:
    """Whether an operand of a nested program's C function is a constant array it reads in place (the model's
    geometry, which JAX hoists out of the program as an operand) rather than an argument: its elements fold."""
    return ref.value is not None and ref.shape != ()


def custom_jvp_call(t: Translator, ins: list[Ref], outs: list[Aval], call_jaxpr: Any, **_: Any) -> list[Ref]:
    return t.call(call_jaxpr, ins, t.used)


def custom_vjp_call(t: Translator, ins: list[Ref], outs: list[Aval], **params: Any) -> list[Ref]:
    return t.call(params.get("call_jaxpr", params.get("fun_jaxpr")), ins, t.used)


def remat(t: Translator, ins: list[Ref], outs: list[Aval], jaxpr: Any, **_: Any) -> list[Ref]:
    return t.call(jaxpr, ins, t.used)


def custom_linear_solve(t: Translator, ins: list[Ref], outs: list[Aval], const_lengths: Any, jaxprs: Any,
                        **_: Any) -> list[Ref]:
    """x = solve(b): the `solve` program with its constants (matvec's and the transposes' are for derivatives)."""
    lengths = [const_lengths.matvec, const_lengths.vecmat, const_lengths.solve, const_lengths.transpose_solve]
    start = sum(lengths[:2])
    consts, b = ins[start : start + lengths[2]], ins[sum(lengths):]
    return t.call(jaxprs.solve, [*consts, *b], t.used)


HANDLERS: dict[str, Handler] = {
    **arithmetic.HANDLERS, **shapes.HANDLERS, **indexing.HANDLERS, **reductions.HANDLERS, **control.HANDLERS,
    **linalg.HANDLERS, **dict.fromkeys(CALLS, jit), "custom_jvp_call": custom_jvp_call,
    "custom_vjp_call": custom_vjp_call, "custom_vjp_call_jaxpr": custom_vjp_call, "remat": remat, "checkpoint": remat,
    "custom_linear_solve": custom_linear_solve}
for _primitive, _handler in HANDLERS.items():
    setattr(Translator, f"p_{_primitive}", staticmethod(_handler))
PRIMITIVES = tuple(sorted({*UNARY, *BINARY, *HANDLERS}))


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
            if value.elems is not None:  # held elements (a folded constant): written one by one, no loop index
                for i in range(out.size):
                    em.emit(f"{out.name}[{i}] = ({out.ctype}){value.at(str(i))};")
                continue

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
