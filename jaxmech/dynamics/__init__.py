"""Bodies and loads; inverse dynamics by virtual power, joint reactions, statics and
forward dynamics.  One module per concept:

- ``model``: the spec (``Body``, the loads, ``Model`` and its parameters);
- ``virtual_power``: generalized forces and multipliers, mass matrix, energies at one state;
- ``joints``: joints between bodies (revolute, prismatic, slot, actuator) and the layout of
  the per-body Newton-Euler system; ``reactions``: every joint's reaction from it;
- ``inverse``: inverse dynamics over batches of states or along a drive, and statics at
  given poses;
- ``closure``: closing the loop at a new input by a fixed number of Newton steps;
- ``static_equilibrium``: equilibrium of a force-driven model (``equilibrium``);
- ``forward``: forward dynamics by an implicit Runge-Kutta method;
- ``status``: the result codes of statics and forward dynamics.

**Statics** solves ``tau(u) = tau_applied`` (quasi-static: no inertia) for the free input
``u`` with a safeguarded Newton method and attaches the root to ``p`` by an implicit-
function custom JVP.  **Forward dynamics** integrates
``M(u) u_ddot + h(u, u_dot, t) = tau`` (``h = (1/2) M' u_dot^2 - Q`` for one input: the
inverse-dynamics torque at zero acceleration) with an implicit Runge-Kutta method (Radau
IIA by default, L-stable for the stiff motor inductance), the loop solve inside every stage.
"""

from .closure import close_loop as close_loop
from .forward import METHODS as METHODS
from .forward import Integrator as Integrator
from .forward import Trajectory as Trajectory
from .forward import forward_dynamics as forward_dynamics
from .forward import integrate as integrate
from .forward import rhs as rhs
from .inverse import InverseDynamics as InverseDynamics
from .inverse import inverse_dynamics as inverse_dynamics
from .inverse import inverse_dynamics_at as inverse_dynamics_at
from .inverse import inverse_dynamics_batch as inverse_dynamics_batch
from .inverse import statics as statics
from .joints import Actuator as Actuator
from .joints import Prismatic as Prismatic
from .joints import Revolute as Revolute
from .joints import Slot as Slot
from .reactions import joint_reactions as joint_reactions
from .model import Axial as Axial
from .model import Body as Body
from .model import Gravity as Gravity
from .model import Model as Model
from .model import Moment as Moment
from .model import PointForce as PointForce
from .model import Potential as Potential
from .static_equilibrium import Equilibrium as Equilibrium
from .static_equilibrium import equilibrium as equilibrium
from .virtual_power import generalized_forces as generalized_forces
from .virtual_power import kinetic_energy as kinetic_energy
from .virtual_power import mass_matrix as mass_matrix
from .virtual_power import potential_energy as potential_energy

__all__ = [
    "Body",
    "PointForce",
    "Moment",
    "Gravity",
    "Axial",
    "Potential",
    "Model",
    "generalized_forces",
    "mass_matrix",
    "kinetic_energy",
    "potential_energy",
    "InverseDynamics",
    "inverse_dynamics",
    "inverse_dynamics_at",
    "inverse_dynamics_batch",
    "statics",
    "Revolute",
    "Prismatic",
    "Slot",
    "Actuator",
    "joint_reactions",
    "Equilibrium",
    "equilibrium",
    "close_loop",
    "Trajectory",
    "forward_dynamics",
    "Integrator",
    "integrate",
    "rhs",
    "METHODS",
]


def __getattr__(name):
    """The result codes' retired names (deprecated: ``jaxmech.Status``, ``status.RETIRED``)."""
    from ..solver.status import retired

    return retired(__name__, name)
