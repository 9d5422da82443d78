"""Array helpers for models and controllers that run on numpy and compile with JAX alike (the array API).

A law written with these and the namespace `xp = array_namespace(q, dq, x)` of its inputs is *traceable*: JAX can
compile its loop (docs/tutorial.md#traceable). No function here assigns into an array.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import array_api_compat
import numpy as np

__all__ = ["array_namespace", "expm", "matrix", "matvec", "quad", "repeat", "rk4", "solve", "vector"]


def array_namespace(*arrays: Any) -> Any:
    """The array-API namespace of the inputs: numpy itself for numpy arrays and Python numbers (numpy 2 implements the
    standard; this skips array-api-compat's per-call dispatch in hot loops), else `array_api_compat.array_namespace` of
    the non-numpy inputs (numpy constants such as gains are accepted by jax.numpy)."""
    numpy_like = [isinstance(a, np.ndarray | float | int | np.generic) for a in arrays]
    if all(numpy_like):
        return np
    # numpy constants (gains, the plant's φ) mixed with e.g. jax arrays: the other library's namespace, which takes them
    return array_api_compat.array_namespace(*[a for a, is_np in zip(arrays, numpy_like, strict=True) if not is_np])


def matrix(xp: Any, rows: list[list[Any]]) -> Any:
    """Stack scalar fields `rows[i][j]` (broadcastable arrays or numbers) into shape `(..., len(rows), len(rows[0]))`."""
    if xp is np:  # fast path: fill a fresh array (numpy only; other namespaces stack without writes)
        shape = np.broadcast_shapes(*[np.shape(e) for row in rows for e in row])
        out = np.empty(shape + (len(rows), len(rows[0])))
        for i, row in enumerate(rows):
            for j, e in enumerate(row):
                out[..., i, j] = e
        return out
    flat = xp.broadcast_arrays(*[xp.asarray(e, dtype=xp.float64) for row in rows for e in row])
    m = len(rows[0])
    return xp.stack([xp.stack(flat[i * m : (i + 1) * m], axis=-1) for i in range(len(rows))], axis=-2)


def vector(xp: Any, entries: list[Any]) -> Any:
    """Stack scalar fields into shape `(..., len(entries))`."""
    if xp is np:
        return matrix(np, [entries])[..., 0, :]
    return xp.stack(xp.broadcast_arrays(*[xp.asarray(e, dtype=xp.float64) for e in entries]), axis=-1)


def matvec(A: Any, x: Any) -> Any:
    """`A @ x` over leading batch axes: `(..., n, m) × (..., m) → (..., n)`; a shared `(n, m)` matrix is one product."""
    if A.ndim == 2:
        return x @ A.T
    return (A @ x[..., None])[..., 0]


def quad(x: Any, A: Any) -> Any:
    """xᵀ A x over leading batch axes: `(..., n), (..., n, n) → (...)`."""
    return (matvec(A, x) * x).sum(axis=-1)


def solve(xp: Any, A: Any, b: Any) -> Any:
    """x with A x = b over leading axes, `(..., n, n), (..., n) → (..., n)`; closed forms for n ≤ 2 (the book's arms),
    which beat a library call per step in numpy and under `jax.jit` alike."""
    n = A.shape[-1]
    if n == 1:
        return b / A[..., 0]
    if n == 2:
        a11, a12, a21, a22 = A[..., 0, 0], A[..., 0, 1], A[..., 1, 0], A[..., 1, 1]
        det = a11 * a22 - a12 * a21
        b1, b2 = b[..., 0], b[..., 1]
        return xp.stack([(a22 * b1 - a12 * b2) / det, (a11 * b2 - a21 * b1) / det], axis=-1)
    return xp.linalg.solve(A, b[..., None])[..., 0]


def expm(xp: Any, A: Any) -> Any:
    """The matrix exponential over leading axes, `(..., n, n)`: scipy's for numpy, JAX's (differentiable) else."""
    if xp is np:
        import scipy.linalg

        return scipy.linalg.expm(A)
    import jax.scipy.linalg

    return jax.scipy.linalg.expm(A)


UNROLL = 4  # repeat: loops of at most this many bodies are written out in a traced program; longer: a fori_loop


def repeat(xp: Any, count: int, body: Callable[[Any, Any], Any], init: Any) -> Any:
    """body(count − 1, … body(1, body(0, init))): a Python loop for numpy and short loops, `lax.fori_loop` for longer
    ones on JAX arrays (the same arithmetic, a smaller program)."""
    if xp is np or count <= UNROLL:
        for i in range(count):
            init = body(i, init)
        return init
    import jax  # only reached with JAX arrays

    return jax.lax.fori_loop(0, count, body, init)


def rk4(f: Callable[[Any, Any], Any], t: Any, y: Any, h: float) -> Any:
    """One classic RK4 step of dy/dt = f(t, y)."""
    k1 = f(t, y)
    k2 = f(t + 0.5 * h, y + 0.5 * h * k1)
    k3 = f(t + 0.5 * h, y + 0.5 * h * k2)
    k4 = f(t + h, y + h * k3)
    return y + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4)
