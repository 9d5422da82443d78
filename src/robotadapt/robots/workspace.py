"""Where the hand can go: a bound on the reach of an arm (checked against a task-space path when a scenario loads), and
the joint angles that put the hand at a point (a task-space run starts on its path; docs/task-space.md)."""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from ..validation import ConfigError
from .hand import TaskKinematics

Array = Any


def reach(model: Any, tool: Array | None = None) -> tuple[np.ndarray, float, float] | None:
    """(origin, inner, outer): every point the hand reaches lies between `inner` and `outer` metres from `origin`, in
    the hand's task coordinates (`model.task_axes`). From the kinematic parameters (:meth:`TaskKinematics.kinematic_names`):
    the vectors fixed in the links, grouped by name ("joint3.x", "joint3.y" → one vector), add up to at most the sum of
    their lengths; a spatial arm's first one, fixed in the base, places the origin. The book's two-link arm (l1, l2)
    also has inner = |l1 − l2|. None where the hand's position is not all parameters (a prismatic joint's travel):
    no bound is claimed, nor for an arm whose hand has no kinematic parameters."""
    if not isinstance(model, TaskKinematics):  # a hand without kinematic parameters (PinocchioArm): no bound
        return None
    names, values = model.kinematic_names(tool), np.asarray(model.kinematic_values(tool), dtype=float)
    m = len(model.task_axes)
    q = np.zeros(cast(Any, model).n)  # a TaskKinematics is a RobotModel too
    basis = model.kinematic_basis(q, q, tool)
    if not names or np.abs(np.asarray(basis.h)[0]).max() > 1e-12:
        return None
    groups: dict[str, float] = {}
    for name, value in zip(names, values, strict=True):
        group = name.rsplit(".", 1)[0] if "." in name else name
        groups[group] = groups.get(group, 0.0) + value**2
    lengths = {g: float(np.sqrt(v)) for g, v in groups.items()}
    origin = np.zeros(m)
    first = next(iter(lengths))
    if "." in names[0] and not first.endswith(".link") and m == 3:  # the base's placement of the first joint
        origin = np.array([dict(zip(names, values, strict=True)).get(f"{first}.{a}", 0.0) for a in "xyz"])
        lengths.pop(first)
    outer = sum(lengths.values())
    inner = abs(lengths["l1"] - lengths["l2"]) if set(lengths) == {"l1", "l2"} else 0.0
    return origin, inner, outer


def inverse_kinematics(model: Any, x: Array, guess: Array, tool: Array | None = None, tol: float = 1e-12,
                       iterations: int = 500, field: str = "plant.q0") -> np.ndarray:
    """Joint angles q with the hand at `x` (its m task coordinates), by damped Gauss–Newton from `guess` (the
    nearest solution to it: an elbow up or down): q ← q + Jᵀ(JJᵀ + μ²I)⁻¹ (x − x(q)), μ shrinking with the
    residual. A ConfigError naming `field` when no angles within `tol` metres are found."""
    m = len(model.task_axes)
    q = np.array(guess, dtype=float)
    target = np.asarray(x, dtype=float)
    zero = np.zeros(len(guess))
    for _ in range(iterations):
        hand = model.hand(q, zero, tool)
        e = target - np.asarray(hand.p)[:m]
        if np.linalg.norm(e) < tol:
            return q
        J = np.asarray(hand.J)[:m]
        mu2 = min(1e-2, float(e @ e))
        q = q + J.T @ np.linalg.solve(J @ J.T + mu2 * np.eye(m), e)
    raise ConfigError(field, f"no joint angles put the hand at x_d(0) = {np.round(target, 6).tolist()} from "
                      f"{np.round(np.asarray(guess), 4).tolist()} (left {np.linalg.norm(e):.3g} m away): give "
                      f"{field} near a solution, or move the path into the arm's reach")
