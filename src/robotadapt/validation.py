"""Argument checking done once, at construction, with errors that name the field and the fix.

Every error the library raises on bad input is a :class:`ConfigError`; the CLI prints its message on one line and exits 2.
"""

from __future__ import annotations

import importlib.util
from collections.abc import Sequence
from typing import Any

import numpy as np

Array = np.ndarray


class ConfigError(ValueError):
    """Bad input: the message names the field and says what is expected."""

    def __init__(self, field: str, message: str) -> None:
        self.field = field
        self.reason = message
        super().__init__(f"{field}: {message}" if field else message)

    def __reduce__(self) -> tuple[Any, tuple[Any, ...]]:
        """Pickled (from a worker process) as its class, message and attributes, restored without calling `__init__`:
        a subclass's constructor takes other arguments (:class:`~robotadapt.native.patience.Building`'s path)."""
        return _restored, (type(self), self.args, self.__dict__)


def _restored(kind: type[ConfigError], args: tuple[Any, ...], state: dict[str, Any]) -> ConfigError:
    """A pickled ConfigError (of any subclass) as it was: message, field, reason and the subclass's own attributes."""
    error = kind.__new__(kind, *args)
    error.args = args
    error.__dict__.update(state)
    return error


def _show(value: Any) -> str:
    text = np.array2string(np.asarray(value), threshold=8) if isinstance(value, np.ndarray) else repr(value)
    text = " ".join(text.split())  # one line, whatever the shape
    return text if len(text) < 80 else text[:77] + "..."


def as_array(value: Any, field: str) -> Array:
    """A finite float64 array, or a ConfigError naming `field`."""
    if isinstance(value, bool | np.bool_ | str | bytes) or value is None:
        raise ConfigError(field, f"expected a number or a list of numbers, got {_show(value)}")
    if isinstance(value, np.ndarray) and value.dtype == float:  # already numbers (a gain set by code): no conversion
        arr = value
    else:
        try:
            arr = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise ConfigError(field, f"expected a number or a list of numbers, got {_show(value)}") from None
        if np.asarray(value).dtype == bool:
            raise ConfigError(field, f"expected numbers, got true/false values: {_show(value)}")
    if not np.isfinite(arr).all():
        raise ConfigError(field, f"every entry must be a finite number, got {_show(value)}")
    return arr


def scalar_gain(value: Any, field: str, *, positive: bool = True, nonnegative: bool = False) -> np.ndarray:
    """:func:`as_scalar` held as a 0-d float array: a leaf of the law's tree, so a compiled program takes it as an
    argument and a new value does not recompile (robotadapt.pytree)."""
    return np.asarray(as_scalar(value, field, positive=positive and not nonnegative, nonnegative=nonnegative))


def as_scalar(value: Any, field: str, *, positive: bool = False, nonnegative: bool = False,
              maximum: float | None = None) -> float:
    """A finite float (optionally > 0 or ≥ 0, and at most `maximum`)."""
    arr = as_array(value, field)
    if arr.ndim != 0:
        raise ConfigError(field, f"expected a single number, got {_show(value)}")
    x = float(arr)
    if positive and not x > 0:
        raise ConfigError(field, f"must be positive, got {x:g}")
    if nonnegative and not x >= 0:
        raise ConfigError(field, f"must be zero or positive, got {x:g}")
    if maximum is not None and x > maximum:
        raise ConfigError(field, f"must be at most {maximum:g}, got {x:g}")
    return x


def as_vector(value: Any, n: int, field: str, *, broadcast: bool = True, positive: bool = False) -> Array:
    """A length-`n` vector; a scalar is repeated when `broadcast`."""
    arr = as_array(value, field)
    if arr.ndim == 0 and broadcast:
        arr = np.full(n, float(arr))
    if arr.shape != (n,):
        what = f"a number or a list of {n} numbers" if broadcast else f"a list of {n} numbers"
        raise ConfigError(field, f"expected {what}, got shape {arr.shape}: {_show(value)}")
    if positive and not np.all(arr > 0):
        raise ConfigError(field, f"every entry must be positive, got {_show(arr)}")
    return arr


def as_gain(value: Any, n: int, field: str, *, semidefinite: bool = False) -> Array:
    """A gain matrix: a scalar k means k·I, a list means diag(list), an n×n matrix is taken as is.

    The result must be symmetric positive definite (the book's gains are diagonal PD; the proofs need symmetry), or
    positive semidefinite with `semidefinite=True`.
    """
    arr = as_array(value, field)
    if arr.ndim == 0:
        arr = float(arr) * np.eye(n)
    elif arr.ndim == 1:
        if arr.shape != (n,):
            raise ConfigError(field, f"a list gain is a diagonal and needs {n} entries, got {arr.shape[0]}")
        arr = np.diag(arr)
    elif arr.shape != (n, n):
        raise ConfigError(field, f"expected a scalar, a list of {n} numbers or a {n}x{n} matrix, got shape {arr.shape}")
    check_spd(arr, field, semidefinite)
    return arr


def check_spd(arr: Array, field: str, semidefinite: bool = False) -> None:
    """Raise unless `arr` is symmetric positive definite (or semidefinite)."""
    diagonal = np.count_nonzero(arr) == np.count_nonzero(np.diagonal(arr))  # the usual gain: symmetric, eigenvalues seen
    if not diagonal and not np.allclose(arr, arr.T, rtol=1e-10, atol=1e-12 * max(1.0, float(np.abs(arr).max()))):
        raise ConfigError(field, f"must be symmetric, got {_show(arr)}")
    eig = np.sort(np.diagonal(arr)) if diagonal else np.linalg.eigvalsh(arr)
    if semidefinite and eig.min() < -1e-12 * max(1.0, float(eig.max())):
        raise ConfigError(field, f"must be positive semidefinite (smallest eigenvalue {eig.min():.3g})")
    if not semidefinite and not eig.min() > 0:
        raise ConfigError(field, f"must be positive definite (smallest eigenvalue {eig.min():.3g}); use positive gains")


def check_names(given: Sequence[str], known: Sequence[str], section: str, required: Sequence[str] = ()) -> None:
    """Raise once, naming every name in `given` that is not in `known` and every name of `required` not given.

    One problem names its key as the field (`section.key`); several are listed together under `section`.
    """
    unknown = [name for name in given if name not in known]
    missing = [name for name in required if name not in given]
    if not unknown and not missing:
        return
    parts = []
    if unknown:
        parts.append(f"unknown key{'s' if len(unknown) > 1 else ''} {', '.join(unknown)}" if len(unknown) + len(missing) > 1
                     else "unknown key")
    if missing:
        parts.append(f"missing key{'s' if len(missing) > 1 else ''} {', '.join(missing)}" if len(unknown) + len(missing) > 1
                     else "missing")
    field = f"{section}.{(unknown or missing)[0]}" if len(unknown) + len(missing) == 1 else section
    raise ConfigError(field, f"{'; '.join(parts)}; known keys here: {', '.join(sorted(known))}")


def check_switch(value: Any, field: str) -> None:
    """Raise unless `value` is a bool (a TOML true/false)."""
    if not isinstance(value, bool | np.bool_):
        raise ConfigError(field, f"expected true or false, got {value!r}")


def require_extra(module: str, extra: str, field: str, what: str, otherwise: str = "") -> None:
    """Stop before any work when `module` (of the extra `extra`) is missing: one line naming `field`, the install and
    `otherwise`, the way around it."""
    if importlib.util.find_spec(module) is None:
        around = f", or {otherwise}" if otherwise else ""
        raise ConfigError(field, f"{what} needs {module}: pip install 'robotadapt[{extra}]' (`make demo` installs every "
                                 f"extra){around}")
