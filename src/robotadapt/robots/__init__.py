"""Robot models: dynamics linear in the parameters, batch-capable, parameters passed in (spec §1)."""

from .base import RobotModel
from .one_link import OneLinkArm
from .polar import PolarArm
from .two_link import TwoLinkArm

__all__ = ["OneLinkArm", "PolarArm", "RobotModel", "TwoLinkArm"]
