"""Control flow in C: while (and fori) as `for (;;)` with a break, scan as a counted loop over its slices, cond and
switch as an if/else chain; each body a nested program translated inside the loop or branch."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .lowering import Handler, Lowering, equations
from .values import Aval, Ref

#: a loop body of at least this many equations (nested ones included) is a C function of its own, called in the loop:
#: gcc's register allocation grows faster than linearly on one long loop body (the Panda's records, 4 700 lines: 24 s
#: inlined, 5 s as a function), the same arithmetic
BODY_FUNCTION_MIN = 1000


def assign(t: Lowering, targets: Sequence[Ref], values: Sequence[Ref]) -> None:
    """targets ← values, every value read before any target is written (a value may alias another target)."""
    staged = [t.copy(v) for v in values]
    for target, value in zip(targets, staged, strict=True):
        t.copy_into(target, value, "0", max(target.size, 1))


def block(t: Lowering, opening: str, fill: Callable[[], None]) -> None:
    """`opening` (a loop's head), the statements `fill` emits indented (held elements local to them), and "}"."""
    t.em.emit(opening)
    t.em.depth += 1
    t.em.scalars.open()
    fill()
    t.em.scalars.close()
    t.em.depth -= 1
    t.em.emit("}")


def while_(t: Lowering, ins: list[Ref], outs: list[Aval], cond_jaxpr: Any, body_jaxpr: Any, cond_nconsts: int,
           body_nconsts: int, **_: Any) -> list[Ref]:
    """`for (;;)`: the condition on the carry, break when false, the body, the carry replaced."""
    cond_consts, body_consts = ins[:cond_nconsts], ins[cond_nconsts : cond_nconsts + body_nconsts]
    carry = [t.copy(r) for r in ins[cond_nconsts + body_nconsts :]]

    def fill() -> None:
        pred = t.call(cond_jaxpr, [*cond_consts, *carry])[0]
        t.em.emit(f"if (!({pred.at('0')})) break;")
        assign(t, carry, t.call(body_jaxpr, [*body_consts, *carry]))

    block(t, "for (;;) {", fill)
    return carry


def scan(t: Lowering, ins: list[Ref], outs: list[Aval], jaxpr: Any, length: int, reverse: bool, num_consts: int,
         num_carry: int, **_: Any) -> list[Ref]:
    """A loop of `length` iterations: the body on the consts, the carry and the i-th slices of xs; the carry replaced,
    the i-th slices of ys written."""
    consts, xs = ins[:num_consts], [t.materialize(x) for x in ins[num_consts + num_carry :]]
    carry = [t.copy(r) for r in ins[num_consts : num_consts + num_carry]]
    ys = [t.em.buffer(shape, dtype) for shape, dtype in outs[num_carry:]]
    it, at = t.em.fresh("t"), t.em.fresh("j")

    apart = equations(jaxpr.jaxpr) >= BODY_FUNCTION_MIN
    slice_avals = [(shape[1:], dtype) for shape, dtype in outs[num_carry:]]

    def fill() -> None:
        t.em.emit(f"const int64_t {at} = {f'{length - 1} - {it}' if reverse else it};")
        slices = [Ref(f"({x.name} + {at}*{max(int(np.prod(x.shape[1:])), 1)})", x.shape[1:], x.dtype) for x in xs]
        body = [*consts, *carry, *slices]
        if apart:
            t.used = [True] * len(outs)  # the body's every output: the carry goes round, each y is written
            new = t.apart(jaxpr, body, [*((r.shape, r.dtype) for r in carry), *slice_avals])
        else:
            new = t.call(jaxpr, body)
        for y, value in zip(ys, new[num_carry:], strict=True):  # before the carry moves: a y may alias it
            size = max(int(np.prod(y.shape[1:])), 1)
            t.copy_into(y, value, f"{at}*{size}", size)
        assign(t, carry, new[:num_carry])

    block(t, f"for (int64_t {it} = 0; {it} < {int(length)}; {it}++) {{", fill)
    return [*carry, *ys]


def cond(t: Lowering, ins: list[Ref], outs: list[Aval], branches: Sequence[Any], **_: Any) -> list[Ref]:
    """The branch of the (clamped) index, its outputs copied into buffers declared before."""
    index, operands = ins[0].at("0"), ins[1:]
    results = [t.em.buffer(shape, dtype) for shape, dtype in outs]
    for k, branch in enumerate(branches):
        test = f"if (({index}) <= 0) {{" if k == 0 else f"}} else if (({index}) == {k}) {{" if k < len(
            branches) - 1 else "} else {"
        t.em.emit(test)
        t.em.depth += 1
        t.em.scalars.open()
        assign(t, results, t.call(branch, operands))
        t.em.scalars.close()
        t.em.depth -= 1
    t.em.emit("}")
    return results


HANDLERS: dict[str, Handler] = {"while": while_, "scan": scan, "cond": cond}
