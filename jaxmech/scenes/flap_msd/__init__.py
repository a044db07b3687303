"""The MSD double-flap extraction mechanism (seed 000_0e5ea70f9886b82a).

Source: "MSD Project: flap extraction and retraction system", PoliMi, Group 6,
A.Y. 2022/23.  The analysis behind every choice below, with evidence, is in
``docs/seeds/flap_msd.md``; ``tests/seeds/reference_flap_msd.py`` is an independent
numpy/scipy implementation that the tests compare against.

**Model.**  A crank ``OA`` (angle ``alpha``, counter-clockwise, driven at O) moves the
main flap (chord ``c1``, hinged at the fixed point ``C``) through the coupler ``AG``;
``G`` is the tip of the main flap's arm ``CG`` (perpendicular to the chord).  The bar
``BD`` (fixed pivot ``B``) and the straight bar ``DGE`` (through ``G``) carry ``E``, and
the link ``EH`` turns the second flap (chord ``c2``, hinged at the main flap's trailing
edge ``F``; ``H`` is the tip of its arm ``FH``).  Gauss plane, angles counter-clockwise
from +x, SI units; the flap deflections ``delta`` and ``theta`` are *clockwise*
(chords along ``e^{-i delta}`` and ``e^{-i theta}``).  Three loop closures (report §2):

    L1 = a e^{i alpha} + b e^{i beta} - (l - i r) - i c e^{-i delta}              (§2.1)
    L2 = d e^{i phi} + p e^{i psi} - (s - i t) - i c e^{-i delta}                  (§2.2)
    L3 = (i c - c1) e^{-i delta} + g e^{i psi} + h e^{i xi} - i z e^{-i theta}      (§2.3)

**Branch.**  Of the four assemblies at ``alpha = 275 deg`` (loop 1 has only one), the
scene takes the dyad signs (+, -, +): flaps retracted at the start (delta = 0.95 deg,
theta = 0.02 deg) and the second flap turning through 60.58 deg over the stroke, the
design goal of §1.  The branch indicator has one entry per loop, ``cos(beta+delta)``,
``-sin(phi-psi)``, ``cos(theta+xi)``, all positive on it; an entry vanishes at a toggle of
its loop, and a flip is reported ``BRANCH`` naming the loop.

**Loads (§3.1).**  Masses ``M``, ``m`` at the chord midpoints ``G1``, ``G2`` with
inertias ``J_M``, ``J_m``; gravity ``G``; linearised lift ``F1 = q S1 Cl_delta delta`` at
the quarter chord ``AC1`` normal to the chord (``+i e^{-i delta}``), ``F2`` likewise with
``theta`` at ``AC2``; pure aerodynamic moments entering the power as the report's Pi
writes them, ``MAC1 delta_dot + MAC2 theta_dot`` with ``MAC = q S c Cm``.  These are the
bodies and loads of ``MODEL`` (a ``jaxmech.dynamics.Model``); the driving torque at O
follows by virtual power (``torque``), and the DC motor's steady voltage is
``v = R_a T / K_m + K_m alpha_dot`` (``MOTOR``, §3.2, inductance neglected).

**Singular positions.**  ``singular_positions()`` finds, with the engine, the toggles that
bound the branch: loop 2 (``phi - psi = -180 deg``) at 256.396 deg and 440.942 deg
(= 80.942 deg); the stroke is far from both.

**Corrections to the document** (22 in all, with evidence, in ``docs/seeds/flap_msd.md``
section (d)); those that change numbers:

- §2.1-§2.3 velocity and acceleration formulas: a wrong matrix sign, a doubled factor
  ``a``, ``sin(beta)`` for ``sin(psi)``, ``sin(phi+psi)`` for ``sin(phi-psi)``, missing
  squares, a spurious factor ``c``, a missing ``c``, missing brackets.  Not used here:
  every derivative comes from the loop closures by the implicit function theorem.
- §2.3 singularity condition: ``theta + xi != pi/2 + k pi``, not ``k pi/2``.
- §3.1 printed ``T_m``: ``F2 c1 cos(theta - delta)`` (printed ``sin``: up to 852 N m, 28 %,
  off at 305 deg) and ``m c2^2/4`` (printed ``m (c2^2/4)^2``); ``dT/dt`` has ``m c2^2/4``
  for the theta-dd coefficient (printed ``m c1^2/4``); the ``AC1`` velocity is mislabelled
  and wrong.  ``torque_document`` transcribes the printed formula for comparison.
- §4 data: ``g`` (printed ``q``) is the E-G length; ``J_M = M c1 3.5/K`` and
  ``J_m = m c2 2.5/K`` are used as printed (kg m^2), though their units are kg m; their
  effect on the torque is below 2 N m.
"""

from .model import ALPHA_START as ALPHA_START
from .model import ALPHA_END as ALPHA_END
from .model import DEG as DEG
from .model import COORDS as COORDS
from .model import DEFAULTS as DEFAULTS
from .model import PARAMETERS as PARAMETERS
from .model import BRANCH_SIGNS as BRANCH_SIGNS
from .model import mechanism as mechanism
from .model import loop_determinants as loop_determinants
from .model import closed_form_positions as closed_form_positions
from .model import MODEL as MODEL
from .model import MOTOR as MOTOR
from .model import torque as torque
from .model import voltage as voltage
from .model import torque_document as torque_document
from .model import SCENE as SCENE
from .toggles import Toggle as Toggle
from .toggles import singular_positions as singular_positions

__all__ = ["SCENE", "mechanism", "DEFAULTS", "PARAMETERS", "closed_form_positions", "MODEL", "MOTOR", "loop_determinants", "torque", "torque_document", "voltage", "Toggle", "singular_positions"]
