"""jaxmech: planar mechanisms in JAX, differentiable end to end.

Positions by a batched Newton solve of the loop-closure equations; every derivative
(velocities, accelerations, torques, sensitivities) by the implicit function theorem.
"""

from importlib.metadata import PackageNotFoundError, version as _version

from .kinematics import ConstantSpeed as ConstantSpeed
from .kinematics import Motion as Motion
from .kinematics import Ramp as Ramp
from .kinematics import SmoothStart as SmoothStart
from .kinematics import input_derivatives as input_derivatives
from .kinematics import motion as motion
from .kinematics import stroke_kinematics as stroke_kinematics
from .kinematics import time_derivatives as time_derivatives
from .mechanism import Mechanism as Mechanism
from .mechanism import Vars as Vars
from .mechanism import cis as cis
from .solve import Solution as Solution
from .solve import SolverOptions as SolverOptions
from .solve import implicit_root as implicit_root
from .solve import solve as solve
from .solve import solve_one as solve_one
from .solve import solve_stroke as solve_stroke
from .status import Status as Status
from .status import status_counts as status_counts
from .status import status_message as status_message

try:
    __version__ = _version("jaxmech")
except PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0"
