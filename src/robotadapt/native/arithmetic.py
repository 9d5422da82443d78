"""Elementwise arithmetic and math functions in C: each unary and binary primitive's expression (:data:`UNARY`,
:data:`BINARY`, XLA's semantics: integer division and remainder truncate, max/min propagate NaN) and the handlers of
the elementwise primitives with parameters or several operands (casts, select, clamp, integer powers)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .lowering import Handler, Lowering
from .values import Aval, Ref


def is_float(ref: Ref) -> bool:
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
    "abs": lambda x, r: f"fabs({x})" if is_float(r) else f"(({x}) < 0 ? -({x}) : ({x}))",
    "sign": lambda x, r: f"(({x}) > 0) - (({x}) < 0)" if not is_float(r) else
    f"(isnan({x}) ? ({x}) : (double)((({x}) > 0) - (({x}) < 0)))",
    "logistic": lambda x, r: f"(1.0/(1.0 + exp(-({x}))))",
    "not": lambda x, r: f"!({x})" if r.dtype == "bool" else f"~({x})",
    "is_finite": lambda x, r: f"isfinite({x})",
    "square": lambda x, r: f"(({x})*({x}))",
}


def extremum(a: str, b: str, ref: Ref, op: str) -> str:
    """The larger (`op` ">") or smaller ("<") of `a` and `b`, of `ref`'s dtype: NaN if either is NaN."""
    if not is_float(ref):
        return f"(({a}) {op} ({b}) ? ({a}) : ({b}))"
    return f"(isnan({a}) ? ({a}) : isnan({b}) ? ({b}) : ({a}) {op} ({b}) ? ({a}) : ({b}))"


BINARY: dict[str, Callable[[str, str, Ref], str]] = {
    "add": lambda a, b, r: f"({a}) + ({b})", "sub": lambda a, b, r: f"({a}) - ({b})",
    "mul": lambda a, b, r: f"({a}) * ({b})", "div": lambda a, b, r: f"({a}) / ({b})",
    "rem": lambda a, b, r: f"fmod({a}, {b})" if is_float(r) else f"({a}) % ({b})",
    "pow": lambda a, b, r: f"pow({a}, {b})", "atan2": lambda a, b, r: f"atan2({a}, {b})",
    "nextafter": lambda a, b, r: f"nextafter({a}, {b})",
    "max": lambda a, b, r: extremum(a, b, r, ">"), "min": lambda a, b, r: extremum(a, b, r, "<"),
    "eq": lambda a, b, r: f"({a}) == ({b})", "ne": lambda a, b, r: f"({a}) != ({b})",
    "lt": lambda a, b, r: f"({a}) < ({b})", "le": lambda a, b, r: f"({a}) <= ({b})",
    "gt": lambda a, b, r: f"({a}) > ({b})", "ge": lambda a, b, r: f"({a}) >= ({b})",
    "and": lambda a, b, r: f"({a}) && ({b})" if r.dtype == "bool" else f"({a}) & ({b})",
    "or": lambda a, b, r: f"({a}) || ({b})" if r.dtype == "bool" else f"({a}) | ({b})",
    "xor": lambda a, b, r: f"({a}) != ({b})" if r.dtype == "bool" else f"({a}) ^ ({b})",
}
# the total-order comparisons (sorting keys): the plain ones, which agree with them on every number but signed zeros
BINARY.update({f"{op}_to": BINARY[op] for op in ("eq", "lt", "le")})


def choice(pred: str, cases: Sequence[str]) -> str:
    """case[pred]: a boolean picks case 1 when true, an integer its case."""
    out = cases[-1]
    for k in range(len(cases) - 2, -1, -1):
        out = f"(({pred}) == {k} ? ({cases[k]}) : ({out}))"
    return out


def clamped(lo: str, x: str, hi: str) -> str:
    """`x` clamped to [lo, hi]."""
    return f"(({x}) < ({lo}) ? ({lo}) : ({x}) > ({hi}) ? ({hi}) : ({x}))"


def convert_element_type(t: Lowering, ins: list[Ref], outs: list[Aval], new_dtype: Any, **_: Any) -> Ref:
    if np.dtype(new_dtype).name == ins[0].dtype:
        return t.alias(ins[0], outs[0])
    x = ins[0]
    if np.dtype(new_dtype).kind in "iu" and is_float(x):  # XLA truncates toward zero, as C does
        return t.elementwise(lambda a: a[0], ins, outs[0])
    if np.dtype(new_dtype).kind == "b":
        return t.elementwise(lambda a: f"({a[0]}) != 0", ins, outs[0])
    return t.elementwise(lambda a: a[0], ins, outs[0])


def select_n(t: Lowering, ins: list[Ref], outs: list[Aval], **_: Any) -> Ref:
    return t.elementwise(lambda a: choice(a[0], a[1:]), ins, outs[0])


def clamp(t: Lowering, ins: list[Ref], outs: list[Aval], **_: Any) -> Ref:
    return t.elementwise(lambda a: clamped(a[0], a[1], a[2]), ins, outs[0])


def integer_pow(t: Lowering, ins: list[Ref], outs: list[Aval], y: int, **_: Any) -> Ref:
    def expr(a: list[str]) -> str:
        if y == 0:
            return "1"
        product = "*".join([f"({a[0]})"] * abs(y))
        return product if y > 0 else f"1.0/({product})"

    return t.elementwise(expr, ins, outs[0])


HANDLERS: dict[str, Handler] = {"convert_element_type": convert_element_type, "select_n": select_n, "clamp": clamp,
                                "integer_pow": integer_pow}
