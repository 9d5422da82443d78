"""Array helpers shared by models and controllers, written against the array API (numpy today, JAX later).

No function here assigns into an array; each takes the namespace `xp` of its inputs.
"""

from __future__ import annotations

from typing import Any

import array_api_compat
import numpy as np

__all__ = ["array_namespace", "matrix", "matvec", "quad", "vector"]


def array_namespace(*arrays: Any) -> Any:
    """The array-API namespace of the inputs: numpy itself for numpy arrays and Python numbers (numpy 2 implements the
    standard; this skips array-api-compat's per-call dispatch in hot loops), else `array_api_compat.array_namespace`."""
    if all(isinstance(a, np.ndarray | float | int | np.generic) for a in arrays):
        return np
    return array_api_compat.array_namespace(*arrays)


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
    """`A @ x` over leading batch axes: `(..., n, m) × (..., m) → (..., n)`."""
    return (A @ x[..., None])[..., 0]


def quad(x: Any, A: Any) -> Any:
    """xᵀ A x over leading batch axes: `(..., n), (n, n) → (...)`."""
    return ((x @ A.T) * x).sum(axis=-1)
