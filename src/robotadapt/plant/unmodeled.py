"""Dynamics the controller's model leaves out: a payload (attached at t = 0 or at a step time) and elastic joints.

Both are parts of a :class:`~robotadapt.plant.Plant`; friction or geometry the model lacks is a different plant model
(`Plant(model=...)` against the controller's own).

Payload: a point mass m_p at a point p of the last link's frame changes that link's parameters linearly,

    Δm = m_p,   Δ(m c) = m_p p,   ΔI_o = m_p (|p|² E − p pᵀ)   (inertia about the frame origin, the order of φ)

for models with the standard parameters per link ("m{n}", "mx{n}", …, "Izz{n}": symbolic DH arms, whose standard-DH
frame sits at the distal end of the link, and URDF arms, whose frame is the joint's). Models whose last link is a point
mass ("m2" of the two-link arm at the end of link 2, "m" of the polar arm) take Δm = m_p with p = 0; for the one-link
arm, whose "m" is the inertia about its axis, Δm = m_p is a point mass at unit radius.

Elastic joint (a two-mass model per joint, Spong 1987): the motor side θ with inertia J drives the link side q through
a spring K and a damper D,

    M(q) q̈ + V_m q̇ + G + F = K (θ − q) + D (θ̇ − q̇),     J θ̈ + K (θ − q) + D (θ̇ − q̇) = τ.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..pytree import Module
from ..robots.base import RobotModel
from ..validation import ConfigError, as_scalar, as_vector

Array = Any
_INERTIA = ("Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")


@dataclass(frozen=True, eq=False)
class Payload(Module):
    """A point mass `mass` (kg) at `offset` (m, 3 numbers in the last link's frame), attached at `time` (s)."""

    mass: float
    offset: Any = (0.0, 0.0, 0.0)
    time: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "mass", as_scalar(self.mass, "plant.payload", positive=True))
        object.__setattr__(self, "offset", as_vector(self.offset, 3, "plant.payload_offset", broadcast=False))
        object.__setattr__(self, "time", as_scalar(self.time, "plant.payload_time", nonnegative=True))

    def change(self, model: RobotModel) -> Array:
        """Δφ in `model`'s parameterization (module docstring); a ConfigError when the model has no place for it."""
        names, n = model.param_names, model.n
        delta = np.zeros(model.p)
        last = f"m{n}" if f"m{n}" in names else "m" if "m" in names else None
        if last is None:
            raise ConfigError("plant.payload", f"the model has no mass parameter of its last link (parameters "
                              f"{', '.join(names[:6])}{', …' if len(names) > 6 else ''}); give the true plant.phi")
        delta[names.index(last)] = self.mass
        p = self.offset
        if f"mx{n}" in names:
            for axis, value in zip("xyz", self.mass * p, strict=True):
                delta[names.index(f"m{axis}{n}")] = value
            inertia = self.mass * (p @ p * np.eye(3) - np.outer(p, p))
            for name, (i, j) in zip(_INERTIA, [(0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2)], strict=True):
                delta[names.index(f"{name}{n}")] = inertia[i, j]
        elif np.any(p != 0):
            raise ConfigError("plant.payload_offset", f"this model's last link is a point mass ({last}); a payload "
                              "sits at it, offset 0")
        return delta


@dataclass(frozen=True, eq=False)
class ElasticJoint(Module):
    """Per joint: motor-side inertia `J` (kg m², reflected to the link side), stiffness `K` (N m/rad), damping `D`
    (N m s/rad). The plant's state gains θ and θ̇ (n each)."""

    n: int
    J: Any
    K: Any
    D: Any = 0.0

    def __post_init__(self) -> None:
        f = "plant.elastic_joint"
        object.__setattr__(self, "J", as_vector(self.J, self.n, f"{f}.J", positive=True))
        object.__setattr__(self, "K", as_vector(self.K, self.n, f"{f}.K", positive=True))
        D = as_vector(self.D, self.n, f"{f}.D")
        if np.any(D < 0):
            raise ConfigError(f"{f}.D", f"must be zero or positive, got {D}")
        object.__setattr__(self, "D", D)

    def torque(self, q: Array, dq: Array, theta: Array, dtheta: Array) -> Array:
        """The spring and damper torque K (θ − q) + D (θ̇ − q̇) on the link, shape `(..., n)`."""
        return self.K * (theta - q) + self.D * (dtheta - dq)

    def rate(self, extra_inertia: Array) -> float:
        """The fastest motor-side rate √(K/J) + D/J (1/s), J including `extra_inertia` (a rotor)."""
        J = self.J + extra_inertia
        return float(np.max(np.sqrt(self.K / J) + self.D / J))
