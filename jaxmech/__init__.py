"""jaxmech: planar mechanisms in JAX, differentiable end to end.

Positions by a batched Newton solve of the loop-closure equations; every derivative
(velocities, accelerations, torques, sensitivities) by the implicit function theorem.
"""

from importlib import metadata as _metadata

from ._moved import MOVED as _MOVED
from ._moved import install as _install_moved

_install_moved()  # the module paths before the packages (jaxmech.positions, ...): one release more, with a warning

from .actuators import DCMotor as DCMotor
from .actuators import HydraulicCylinder as HydraulicCylinder
from .actuators import LinearSpring as LinearSpring
from .actuators import ScrewJack as ScrewJack
from .actuators import SMAWire as SMAWire
from .dynamics import Actuator as Actuator
from .dynamics import Axial as Axial
from .dynamics import Body as Body
from .dynamics import Equilibrium as Equilibrium
from .dynamics import Gravity as Gravity
from .dynamics import InverseDynamics as InverseDynamics
from .dynamics import Model as Model
from .dynamics import Moment as Moment
from .dynamics import PointForce as PointForce
from .dynamics import Prismatic as Prismatic
from .dynamics import Revolute as Revolute
from .dynamics import Slot as Slot
from .dynamics import Potential as Potential
from .dynamics import Trajectory as Trajectory
from .dynamics import equilibrium as equilibrium
from .dynamics import forward_dynamics as forward_dynamics
from .dynamics import generalized_forces as generalized_forces
from .dynamics import inverse_dynamics as inverse_dynamics
from .dynamics import inverse_dynamics_at as inverse_dynamics_at
from .dynamics import kinetic_energy as kinetic_energy
from .dynamics import mass_matrix as mass_matrix
from .dynamics import potential_energy as potential_energy
from .dynamics import statics as statics
from .continuation.solve import solve_stroke as solve_stroke
from .kinematics import ConstantSpeed as ConstantSpeed
from .kinematics import Motion as Motion
from .kinematics import Ramp as Ramp
from .kinematics import Samples as Samples
from .kinematics import SmoothStart as SmoothStart
from .kinematics import input_derivatives as input_derivatives
from .kinematics import motion as motion
from .kinematics import StrokeKinematics as StrokeKinematics
from .kinematics import stroke_kinematics as stroke_kinematics
from .kinematics import time_derivatives as time_derivatives
from .mechanism.mechanism import Mechanism as Mechanism
from .mechanism.mechanism import Vars as Vars
from .mechanism.mechanism import cis as cis
from .solver.solution import Solution as Solution
from .solver.options import SolverOptions as SolverOptions
from .solver.implicit import implicit_positions as implicit_positions
from .solver.positions import solve as solve
from .solver.status import Status as Status
from .solver.status import status_counts as status_counts
from .solver.status import status_message as status_message

from ._compile import stored as _stored  # noqa: F401 - installs the executable store at the programs' edge
from ._compile.cache import enable_compile_cache as enable_compile_cache
from .solver.xla import warn_if_wrong_jaxlib as _warn_if_wrong_jaxlib

_warn_if_wrong_jaxlib()


#: Deprecated names -> ``() -> (the new name, its value)``: they work one release more, with a warning.
_RENAMED = {
    "implicit_root": lambda: ("implicit_positions", implicit_positions),
    "solve_one": lambda: ("solve (one sample: a scalar input; it works inside jit, vmap and grad too)",
                          __import__("jaxmech.solver.positions", fromlist=["solve_one"]).solve_one),
}

#: Names whose modules load on first use (``jaxmech.linkage``: 15 ms of the import).
_LAZY = {"Linkage": "linkage", "load_linkage": "linkage", "drawing_from_lengths": "linkage"}


def __getattr__(name):
    """The documented packages and the lazily loaded names (``_LAZY``), and the deprecated ones: ``jaxmech.implicit_root``
    is ``jaxmech.implicit_positions``, and a module's old path (``jaxmech.positions``) loads it through ``_MOVED``."""
    import importlib

    if name in _PACKAGES or f"{__name__}.{name}" in _MOVED:  # a documented package, loaded on first use (jaxmech.design, ...)
        return importlib.import_module(f".{name}", __name__)
    if name in _LAZY:
        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    if name in ("DynStatus", "dyn_status_message"):  # the result codes' retired names
        from .solver.status import retired

        return retired(__name__, name)
    if name in _RENAMED:
        import warnings

        new, value = _RENAMED[name]()
        warnings.warn(f"jaxmech.{name} is deprecated: use jaxmech.{new}", DeprecationWarning, stacklevel=2)
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


try:
    __version__ = _metadata.version("jaxmech")
except _metadata.PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0"

#: The public face: one name per job, the rest in the documented packages.
__all__ = [
    # mechanisms and solving
    "Mechanism", "Vars", "cis", "SolverOptions", "Solution", "Status", "status_counts", "status_message",
    "solve", "solve_stroke", "implicit_positions",
    # motion
    "ConstantSpeed", "Ramp", "SmoothStart", "Samples", "Motion", "motion", "StrokeKinematics", "stroke_kinematics",
    "input_derivatives", "time_derivatives",
    # models and dynamics
    "Model", "Body", "Gravity", "PointForce", "Moment", "Axial", "Potential", "Revolute", "Prismatic", "Slot",
    "Actuator", "InverseDynamics", "Equilibrium", "Trajectory",
    "inverse_dynamics", "inverse_dynamics_at", "statics", "equilibrium", "forward_dynamics",
    "mass_matrix", "generalized_forces", "kinetic_energy", "potential_energy",
    # actuators
    "DCMotor", "HydraulicCylinder", "ScrewJack", "LinearSpring", "SMAWire",
    # linkages from a drawing
    "Linkage", "load_linkage", "drawing_from_lengths",
    # the compile cache (opt-in)
    "enable_compile_cache",
]

#: The documented packages, listed by ``dir(jaxmech)`` beside ``__all__`` (the library's
#: internal modules stay importable by their full names, but are not part of its face).
_PACKAGES = ("actuators", "design", "dynamics", "linkage", "scenes", "sweep")


def __dir__():
    return sorted({*__all__, *_PACKAGES, "__version__"})
