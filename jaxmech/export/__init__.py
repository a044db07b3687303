"""CAD export: ``pose`` (a pose of a mechanism, or its stroke, solved and drawn) and
``cad`` (the DXF and SVG sheets it is written on).

This face hands on the names of ``pose``, which was the module ``jaxmech.export``.
"""

from .pose import APPID as APPID
from .pose import Pose as Pose
from .pose import export_pose as export_pose
from .pose import export_stroke as export_stroke
from .pose import input_value as input_value
from .pose import solve_pose as solve_pose
from .pose import write_pose as write_pose

__all__ = ["Pose", "solve_pose", "export_pose", "write_pose", "export_stroke", "input_value", "APPID"]
