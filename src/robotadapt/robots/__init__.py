"""Robot models: dynamics linear in the parameters, batch-capable, parameters passed in (docs/laws.md#model).

The n-DOF models (`robotadapt.robots.symbolic` from DH tables with sympy, `robotadapt.robots.pinocchio` from URDF) import
their optional dependency on first use, so they are importable here without it.
"""

from .base import RobotModel
from .hand import Hand, KinematicBasis, TaskKinematics, orientation_error
from .identifiability import BaseParameterModel, BaseParameters, base_parameters
from .one_link import OneLinkArm
from .pinocchio import PinocchioArm
from .polar import PolarArm
from .symbolic import SymbolicArm
from .two_link import TwoLinkArm

__all__ = [
    "BaseParameterModel", "BaseParameters", "Hand", "KinematicBasis", "OneLinkArm", "PinocchioArm", "PolarArm",
    "RobotModel", "SymbolicArm", "TaskKinematics", "TwoLinkArm", "base_parameters", "orientation_error",
]
