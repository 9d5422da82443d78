"""Controllers: `tau, dx = ctrl(t, x, q, dq, ref)`, pure, batch-capable, gains validated at construction."""

from .base import (
    Controller,
    HasFilteredError,
    HasLyapunov,
    HasProjection,
    HasRegressor,
    NeedsAcceleration,
    SimulationStop,
)
from .baseline import PD, ComputedTorque, PDGravity
from .composite import Composite
from .inertia_related import InertiaRelated

__all__ = [
    "PD",
    "Composite",
    "ComputedTorque",
    "Controller",
    "HasFilteredError",
    "HasLyapunov",
    "HasProjection",
    "HasRegressor",
    "InertiaRelated",
    "NeedsAcceleration",
    "PDGravity",
    "SimulationStop",
]
