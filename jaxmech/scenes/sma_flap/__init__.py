"""SMA-actuated hinged flap: quasi-static equilibrium (seed 004_52c3b6aed7b0817f).

Source: "Dynamic modelling of sma-driven flap", P. B. Camara Leal, 2016 (a short note, with no
numbers).  The analysis behind every choice below, with evidence and the chosen parameter set,
is in ``docs/seeds/sma_flap.md``.  ``tests/seeds/reference_sma_flap.py`` is an independent
numpy/scipy implementation that the tests compare against.

**Model.**  Rigid flap segments hinged at ``J1`` (wing to segment 1) and ``J2`` (segment 1 to
segment 2); one hinge locks the two segments into one flap.  Airfoil plane: x aft, y up, SI
units, complex points.  ``theta_j`` is the rotation of body j relative to body j-1,
counter-clockwise positive (theta > 0 lifts the trailing edge).  Each hinge carries an SMA wire
and a linear bias spring.  Each joins a point ``F`` on the body ahead of the hinge to a point
``A`` on the body behind it, and its tension ``T > 0`` pulls A towards F:

- SMA wire, strain-driven (``jaxmech.actuators.SMAWire``, linear branch or a user constitutive
  ``law``): ``T = A_w E (L / (L0 (1 + eps)) - 1)``.  ``E = xi E_M + (1 - xi) E_A``,
  ``eps <= 0`` is the commanded transformation strain, and the wire is slack-clamped at 0.
- SMA wire, force-driven: ``T = F_j`` prescribed.
- Bias spring (``jaxmech.actuators.LinearSpring``): ``T = F_pre + k (L - L0)``.

**Equilibrium** (virtual work, i.e. the moment balance about each hinge of everything behind it):

    R_j(theta) = sum_act T dL/dtheta_j + sum_b m_b g dy_cg,b/dtheta_j = 0,   j = 1..n.

``flap_mechanism`` makes these ``n`` equations the constraints of a ``Mechanism``.  Its
coordinates are the hinge angles and its input is the drive (``eps``, or the wire forces).  So
``jaxmech.solve`` is Newton on the equilibrium, and every derivative of the equilibrium angles
(in the drive and in every parameter) comes from the implicit function theorem.  The stiffness
``dR/dtheta`` is positive definite at a stable equilibrium (output ``stiffness_min``).
``jaxmech run sma_flap`` sweeps eps from 0 to -4 % on one hinge (``SCENE``).  ``SCENE_CHAIN`` is
the two-hinge chain.

**Parameters** (``params(n_hinges)``, from docs/seeds/sma_flap.md): a 0.40 m chord section.
Hinges at x = 0.22 and 0.31 m.  Wires run from (0.06, 0.010) to (0.22, 0.010) m and from
(0.23, 0.008) to (0.31, 0.008) m: NiTi 0.381 mm, E_M = 28 GPa, E_A = 75 GPa.  Springs run from
(0.14, -0.010) to (0.22, -0.010) m (k = 1000 N/m, preload 5 N) and from (0.27, -0.008) to
(0.31, -0.008) m (800 N/m, 3 N).  Masses are 0.06 kg at x = 0.265 m and 0.04 kg at 0.355 m;
one hinge uses 0.10 kg at 0.301 m.

**The document's fixed point** (Algorithm 1, physics corrected) is ``fixed_point``, with its
iterate history.  Its rate about the root is ``1 - V''/(k L_s'^2)`` (``fixed_point_rate``).  It
fails for any realistic wire (rate -20 for E_M, -54 for E_A).  Newton (the engine) converges in
3-5 steps.

**Corrections to the document** (12 in all, with evidence, in ``docs/seeds/sma_flap.md``):

- Eq. 1.3: a1 for a2.  Eqs. 1.1/1.4: r = x_J + T(theta) a - f (the hinge position is missing).
- §1.2, eqs. 1.5-1.9: stretching the actuator does not scale its vector.  The only condition is
  |r(theta)| = eta |r0|, a circle intersection (``rigid_wire_angle``).  Eq. 1.8 has a sign error.
- §1.3, eqs. 1.11-1.14: a tension pulls A towards F.  The weight torque has the wrong sign.
  Moments are taken about the hinge, W is the segment's weight at its CG, and a chain's hinge 1
  carries every segment behind it.
- Eq. 1.16: F = E_M A eps, not (E_M/A) eps.  The bias spring needs a preload: F = F_pre + k (L - L0).
- The strain-driven problem is over-determined as written.  The wire is treated here as elastic
  with a prescribed transformation strain; the rigid limit is ``rigid_wire_angle``.
- Algorithm 1 diverges for realistic stiffness (see above).  Its bookkeeping is incomplete, and
  the model is quasi-static, not dynamic.
"""

from .model import G as G
from .model import EPS_RANGE as EPS_RANGE
from .model import params as params
from .model import parameters as parameters
from .model import point_z as point_z
from .model import hinge_geometry as hinge_geometry
from .model import rest_length as rest_length
from .model import wire_tensions as wire_tensions
from .model import drive_params as drive_params
from .model import residual as residual
from .model import stiffness as stiffness
from .model import flap_mechanism as flap_mechanism
from .model import equilibrium as equilibrium
from .model import tensions as tensions
from .model import wire_force_for_angle as wire_force_for_angle
from .model import circle_angle as circle_angle
from .model import rigid_wire_angle as rigid_wire_angle
from .model import SCENE as SCENE
from .model import SCENE_CHAIN as SCENE_CHAIN
from .fixed_point import FixedPoint as FixedPoint
from .fixed_point import fixed_point as fixed_point
from .fixed_point import fixed_point_rate as fixed_point_rate
from .fixed_point import newton_history as newton_history

__all__ = ["SCENE", "params", "parameters", "flap_mechanism", "residual", "drive_params", "SCENE_CHAIN", "stiffness", "equilibrium", "tensions", "rigid_wire_angle", "wire_force_for_angle", "FixedPoint", "fixed_point", "fixed_point_rate", "newton_history", "EPS_RANGE"]
