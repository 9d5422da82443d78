"""Controllers: `tau, dx = ctrl(t, x, q, dq, ref)`, pure, batch-capable, gains validated at construction; every law
derives from :class:`Law` (its optional parts are hooks with defaults)."""

from .base import Law
from .baseline import PD, ComputedTorque, PDGravity
from .composite import Composite
from .computed_torque import AdaptiveComputedTorque
from .dcal import DCAL
from .inertia_related import InertiaRelated
from .passivity import PassivityBased, ServoFilter, pd_servo, pid_servo, state_space_servo
from .repetitive import Repetitive
from .robust import SignRobust

__all__ = [
    "DCAL",
    "PD",
    "AdaptiveComputedTorque",
    "Composite",
    "ComputedTorque",
    "InertiaRelated",
    "Law",
    "PDGravity",
    "PassivityBased",
    "Repetitive",
    "SignRobust",
    "pd_servo",
    "pid_servo",
    "state_space_servo",
    "ServoFilter",
]
