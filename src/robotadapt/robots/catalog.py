"""The n-DOF arms a scenario names (`[robot] kind = "urdf" | "example_robot" | "dh" | "puma560" | "planar"`), each
built as a :class:`~robotadapt.robots.kinematic_tree.KinematicTree` — traced by JAX, so the compiled engine runs it —
unless `model` asks for the reference it is checked against: ``"pinocchio"`` (Pinocchio's C++, URDF arms) or
``"sympy"`` (expressions derived by sympy, DH arms). Both give the same parameters in the same order and agree to
round-off (tests/test_kinematic_tree.py); the kinematic tree needs no sympy and compiles in seconds.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from ..validation import ConfigError
from .base import RobotModel
from .dh import SMOOTH_VELOCITY
from .kinematic_tree import KinematicTree

URDF_MODELS = ("tree", "pinocchio")
DH_MODELS = ("tree", "sympy")


def _check(model: Any, choices: tuple[str, ...]) -> str:
    if model not in choices:
        raise ConfigError("robot.model", f"expected one of {', '.join(choices)}; got {model!r}")
    return str(model)


@contextmanager
def _scenario_names() -> Iterator[None]:
    """Errors name the scenario's keys (`robot.path`, `robot.locked_joints`), as the Pinocchio model's do."""
    try:
        yield
    except ConfigError as exc:
        field = {"robot.locked": "robot.locked_joints", "robot.urdf": "robot.path"}.get(exc.field, exc.field)
        raise ConfigError(field, exc.reason.replace("(robot.locked)", "(robot.locked_joints)")) from None


def _pinocchio(model: str, rotor_inertia: bool) -> Any:
    """The PinocchioArm class when `model` asks for it (it has no rotor-inertia columns), else None."""
    if _check(model, URDF_MODELS) == "tree":
        return None
    if rotor_inertia:
        raise ConfigError("robot.rotor_inertia", "the Pinocchio model has no rotor-inertia columns: use model = 'tree'")
    from .pinocchio import PinocchioArm

    return PinocchioArm


def urdf_arm(path: str | Path, locked_joints: Any = (), viscous: bool = False, coulomb: bool = False,
             rotor_inertia: bool = False, gravity: Any = None, model: str = "tree", *, smooth_coulomb: bool = False,
             smooth_coulomb_velocity: Any = SMOOTH_VELOCITY, offset: bool = False) -> RobotModel:
    """An arm from a URDF file: joints in `locked_joints` held at zero; friction (viscous, Coulomb, smooth Coulomb
    tanh(q̇/v_s) at v_s = `smooth_coulomb_velocity`, a constant offset) and rotor-inertia columns on request."""
    reference = _pinocchio(model, rotor_inertia)
    if reference is not None:
        return reference.from_urdf(path, locked_joints, viscous, coulomb, gravity, smooth_coulomb, offset,
                                   smooth_coulomb_velocity)
    with _scenario_names():
        return KinematicTree.from_urdf(path, tuple(locked_joints), rotor_inertia, viscous, coulomb, gravity,
                                       smooth_coulomb, offset, smooth_coulomb_velocity)


def example_arm(name: str, locked_joints: Any = (), viscous: bool = False, coulomb: bool = False,
                rotor_inertia: bool = False, gravity: Any = None, model: str = "tree", *, smooth_coulomb: bool = False,
                smooth_coulomb_velocity: Any = SMOOTH_VELOCITY, offset: bool = False) -> RobotModel:
    """An arm of example-robot-data by name (`robotadapt.robots.pinocchio.EXAMPLES`; grippers locked)."""
    reference = _pinocchio(model, rotor_inertia)
    if reference is not None:
        return reference.example(name, locked_joints, viscous, coulomb, gravity, smooth_coulomb, offset,
                                 smooth_coulomb_velocity)
    with _scenario_names():
        arm = KinematicTree.example(name, tuple(locked_joints), rotor_inertia, viscous, coulomb, smooth_coulomb,
                                    offset, smooth_coulomb_velocity)
    return arm if gravity is None else replace(arm, g=np.asarray(gravity, dtype=float))


def _tree_or_sympy(make: Any, model: str) -> RobotModel:
    """The arm `make(derive)` builds: derived by sympy, or its link data on the kinematic tree (no sympy)."""
    if _check(model, DH_MODELS) == "sympy":
        return make(True)
    return KinematicTree.from_symbolic(make(False))


def dh_arm(links: Any, convention: str = "standard", g: Any = (0.0, 0.0, -9.81), model: str = "tree", *,
           smooth_coulomb_velocity: Any = SMOOTH_VELOCITY) -> RobotModel:
    """An arm from a DH table (the link tables of :func:`robotadapt.robots.symbolic.from_dh_table`; a link's
    `smooth_coulomb` or `offset` adds that friction group, v_s = `smooth_coulomb_velocity`)."""
    _check(model, DH_MODELS)
    if model == "tree":
        return KinematicTree.from_dh(links, convention, g, smooth_coulomb_velocity)
    from .symbolic import from_dh_table

    return from_dh_table(links, convention, g, smooth_coulomb_velocity)


def puma560_arm(rotor_inertia: bool = False, viscous: bool = False, coulomb: bool = False, model: str = "tree", *,
                smooth_coulomb: bool = False, smooth_coulomb_velocity: Any = SMOOTH_VELOCITY,
                offset: bool = False) -> RobotModel:
    """The PUMA 560 of :func:`robotadapt.robots.symbolic.puma560` (published parameters, joint limits)."""
    from .symbolic import puma560

    return _tree_or_sympy(lambda derive: puma560(rotor_inertia, viscous, coulomb, smooth_coulomb, offset,
                                                 smooth_coulomb_velocity, derive=derive), model)


def planar(n_links: int, lengths: Any = 1.0, masses: Any = 1.0, rods: bool = False, g: float = 9.8,
           rotor_inertia: Any = None, viscous: Any = None, coulomb: Any = None, model: str = "tree", *,
           smooth_coulomb: Any = None, smooth_coulomb_velocity: Any = SMOOTH_VELOCITY,
           offset: Any = None) -> RobotModel:
    """The n-link planar arm of :func:`robotadapt.robots.symbolic.planar_arm`."""
    from .symbolic import planar_arm

    return _tree_or_sympy(lambda derive: planar_arm(n_links, lengths, masses, rods, g, rotor_inertia, viscous, coulomb,
                                                    smooth_coulomb, offset, smooth_coulomb_velocity, derive=derive),
                          model)
