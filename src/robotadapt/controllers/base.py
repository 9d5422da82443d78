"""The controller contract and the error signals every law shares (spec §0.2, §3.2).

A controller holds only constants (model, gains, initial estimate). Its time-varying state `x` (φ̂, filter states,
integrals) comes in and its derivative goes out::

    tau, dx = ctrl(t, x, q, dq, ref)

with `q, dq` of shape `(..., n)`, `x` of shape `(..., s)`, `ref` a :class:`~robotadapt.trajectories.Reference`.
Controllers never see the true φ; only the optional monitors (`lyapunov`) take it, to evaluate the theory's V(t).
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from ..robots.base import RobotModel
from ..trajectories import Reference
from ..validation import as_gain, as_vector

Array = Any


@runtime_checkable
class Controller(Protocol):
    model: RobotModel

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the entries of the state vector x."""

    def initial_state(self) -> Array: ...

    def phi_hat(self, x: Array) -> Array:
        """The parameter estimate held in (or fixed by) the controller, shape `x.shape[:-1] + (p,)`."""

    def __call__(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]: ...


@runtime_checkable
class HasLyapunov(Protocol):
    def lyapunov(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference, phi: Array) -> Array:
        """The Lyapunov function of the controller's stability proof, evaluated with the true φ."""


@runtime_checkable
class HasFilteredError(Protocol):
    def filtered_error(self, t: Array, x: Array, q: Array, dq: Array, ref: Reference) -> Array:
        """The filtered tracking error r the controller drives to zero."""


def errors(q: Array, dq: Array, ref: Reference) -> tuple[Array, Array]:
    """e = q_des − q, ė = q̇_des − q̇ (the book's sign)."""
    return ref.q_des - q, ref.dq_des - dq


def quad(x: Array, A: Array) -> Array:
    """xᵀ A x over leading axes."""
    return ((x @ A.T) * x).sum(axis=-1)


def freeze(obj: Any, **values: Any) -> None:
    """Set validated fields on a frozen dataclass from its `__post_init__`."""
    for name, value in values.items():
        object.__setattr__(obj, name, value)


def gains(obj: Any, names: tuple[str, ...], dim: int) -> None:
    """Validate the named `dim`×`dim` gain fields of `obj` (scalar → k·I, list → diag, matrix) as symmetric PD."""
    freeze(obj, **{name: as_gain(getattr(obj, name), dim, f"controller.{name}") for name in names})


def estimate(obj: Any, name: str = "phi_hat0") -> None:
    """Validate a parameter-estimate field against the model's parameter count."""
    freeze(obj, **{name: as_vector(getattr(obj, name), obj.model.p, f"controller.{name}", broadcast=False)})


def inverse(A: Array) -> Array:
    return np.linalg.inv(A)
