"""Controllers: `tau, dx = ctrl(t, x, q, dq, ref)`, pure, batch-capable, gains validated at construction; every law
derives from :class:`Law` (its optional parts are hooks with defaults) and registers itself in its own class body
(:mod:`robotadapt.controllers.registry`). `robotadapt.controllers.InertiaRelated`, ..., every registered law and update
law by its class name, are found there on first use (:func:`registered`)."""

from __future__ import annotations

from typing import Any

from .base import Law as Law
from .passivity import ServoFilter as ServoFilter
from .passivity import pd_servo as pd_servo
from .passivity import pid_servo as pid_servo
from .passivity import state_space_servo as state_space_servo
from .registry import Contender as Contender
from .registry import OfTruth as OfTruth
from .registry import by_name
from .registry import registered as registered

_STATIC = ["Contender", "Law", "OfTruth", "ServoFilter", "pd_servo", "pid_servo", "registered", "state_space_servo"]


def __getattr__(name: str) -> Any:
    """A registered law or update law by its class name (PEP 562), e.g. `InertiaRelated`; `__all__` with them."""
    if name == "__all__":
        return [*_STATIC, *by_name()]
    if not name.startswith("_"):
        law = by_name().get(name)
        if law is not None:
            return law
        if name in globals():  # a module of the package, imported by the search
            return globals()[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(by_name()))
