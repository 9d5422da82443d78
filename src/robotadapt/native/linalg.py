"""Small dense linear algebra in C, per leading batch index: Cholesky factors, triangular solves and LU with partial
pivoting (LAPACK's getrf), each a loop nest written out."""

from __future__ import annotations

from typing import Any

import numpy as np

from .lowering import Handler, Lowering
from .values import Aval, Ref, Unsupported


def cholesky(t: Lowering, ins: list[Ref], outs: list[Aval], **_: Any) -> Ref:
    """L with A = L Lᵀ (lower; zeros above the diagonal), per leading batch index; NaN where A is not positive
    definite (as XLA)."""
    a, (shape, dtype) = ins[0], outs[0]
    n = shape[-1]
    ref = t.em.buffer(shape, dtype)
    batch = int(np.prod(shape[:-2], dtype=np.int64))
    b, i, j, k, s = (t.em.fresh(p) for p in "bijks")
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
        t.em.emit(line)
    return ref


def triangular_solve(t: Lowering, ins: list[Ref], outs: list[Aval], left_side: bool, lower: bool, transpose_a: bool,
                     unit_diagonal: bool, conjugate_a: bool = False, **_: Any) -> Ref:
    """X with op(A) X = B (left_side) or X op(A) = B, op(A) = A or Aᵀ, A triangular; per leading batch index."""
    a, b, shape = ins[0], ins[1], outs[0][0]
    n = a.shape[-1]
    ref = t.copy(b)
    m, r = shape[-2], shape[-1]
    batch = int(np.prod(shape[:-2], dtype=np.int64))
    # the system is solved column by column of X (left) or row by row (right: X op(A) = B ⇔ op(A)ᵀ Xᵀ = Bᵀ)
    effective_lower = lower != transpose_a  # op(A) lower triangular?
    transposed = transpose_a
    if not left_side:
        effective_lower, transposed = not effective_lower, not transpose_a
    count, stride_e, stride_c = (r, r, 1) if left_side else (m, 1, r)  # elements of one system: stride_e apart
    bi, c, i, k, s = (t.em.fresh(p) for p in "bciks")

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
        t.em.emit(line)
    return ref


def lu(t: Lowering, ins: list[Ref], outs: list[Aval], **_: Any) -> list[Ref]:
    """P A = L U with partial pivoting (LAPACK getrf: the largest |a| first): the packed LU, the pivots (row
    swapped with at each step) and the permutation."""
    a = ins[0]
    (shape, dtype), (pshape, pdtype), (qshape, qdtype) = outs
    n = shape[-1]
    if shape[-2] != n:
        raise Unsupported("LU of a non-square matrix")
    batch = int(np.prod(shape[:-2], dtype=np.int64))
    packed, piv, perm = t.copy(a), t.em.buffer(pshape, pdtype), t.em.buffer(qshape, qdtype)
    b, i, j, k, p = (t.em.fresh(x) for x in "bijkp")
    A = lambda r, c: f"{packed.name}[{b}*{n * n} + ({r})*{n} + ({c})]"  # noqa: E731
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
        t.em.emit(line)
    return [packed, piv, perm]


HANDLERS: dict[str, Handler] = {"cholesky": cholesky, "triangular_solve": triangular_solve, "lu": lu}
