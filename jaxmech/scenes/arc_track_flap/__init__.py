"""Circular-arc-track flap driven by a screw jack (seed 003: Arslan, MSc thesis, IZTECH 2022).

**Model.**  An inverted slider-crank whose crank is the flap itself.  The flap (link 2)
carries two pins, F on a slot of radius ``b1`` and G on a slot of radius ``c1``; both
slots are circular arcs centred at ``A0``, so the flap turns about the remote centre
``A0`` (origin; x towards the nose, y up, angles CCW).  The screw (link 3) is pivoted at
``B0 = a1 e^{i alpha0}``; the nut (link 4) slides on it and is pinned to the flap at A.
The input is the nut travel ``s34 = |B0 A|`` (m); deploying the flap is CCW (``theta12``
grows with ``s34``).  The coordinates are the thesis's angles ``theta12``, ``theta13``
and the flap's translation ``(x2, y2)``, which the two slots hold at zero::

    x2 + i y2 + a2 e^{i(alpha0+theta12)} = a1 e^{i alpha0} + s34 e^{i(alpha0+theta13)}
    |G| - c1 = 0,   G = x2 + i y2 + c1 e^{i(beta1+beta2+theta12-theta12_i)}
    |F| - b1 = 0,   F = x2 + i y2 + b1 e^{i(beta1+theta12-theta12_i)}

Each slot equation has a unit gradient, so with the engine's convention
``I - Q + Phi_x^T lambda = tau e_u`` (constraint force on the bodies ``-Phi_x^T lambda``)
the slot reactions in newtons are ``G12G = -lambda_G``, ``G12F = -lambda_F`` (outward
radial positive), the loop multiplier is ``-F42`` and ``tau = F_input`` (N, nut push
along ``+s34``).  Statics is quasi-static (inertia neglected, as in the thesis; the
accelerations of A and D stay below 0.1 % of g).

**Loads and the reading that reproduces Table 3.**  Per mechanism (screw jack, two per
flap): the air moment ``M12 / n_jacks`` (a couple that closes the flap), linear in
``s34`` from ``M12_i`` (flap closed) to ``M12_f`` (deployed), and the weight
``weight_share * m_flap * g`` at D with ``weight_share = 1``: each jack carries *half
the air moment but the whole 12 kg weight*.  Cruise: ``M12_i = M12_f = 750`` N m, the
column is the closed flap.  Landing: ``M12_i = 220``, ``M12_f = 650`` N m, the column is
closed (min) / deployed (max), except G12G, which is printed in algebraic min/max order
(deployed first).  Screw torques use the load ``L = F_input``.

**Document corrections** (details and evidence in ``docs/seeds/arc_track_flap.md``):
eq. (3.3.2) is ``omega13 = s34_dot / (s34 tan psi)``; eq. (3.3.3)'s second term is ``+``
(so Fig. 46's alpha12 and acceleration components have the wrong sign); the lead angle
is ``tan lambda = l / (2 pi r)``; Table 3's landing G12G is deployed-first; the weight is
counted once per jack (twice per flap) while the moment is halved; "weight below 8 % of
F_input" holds only with the sheet's metric (8.64 % against eq. 3.5.1's numerator);
eqs. (3.4.11) and (3.4.15) have scalar sign slips; Table 2 shades alpha2 as an input;
typos (``sin a0``, ``x_A`` for ``x_A_dot``, Excel's ``ATAN2(x; y)``); landing moments
are interpolated in ``s34``.

**Parameters** (SI, the thesis's names): ``a1`` |A0 B0|, ``a2`` |A0 A|, ``a3`` screw
length, ``alpha0`` angle x-A0-B0, ``b1 > c1`` slot radii (pins F, G), ``beta1`` angle of
F's slot start, ``beta2`` angle F-A0-G, ``beta3`` arc angle = flap rotation, ``x_D``,
``y_D`` centre of mass (flap closed), ``m_flap``, ``g``, screw ``r`` (mean radius), ``l``
(lead), ``f`` (friction); ``n_jacks`` (2), ``weight_share`` (1: the thesis's reading),
``M12_i``, ``M12_f`` whole-flap air moment at the closed / deployed flap.  Default drive:
nut at 35 mm/s from ``s34_i`` to ``s34_f = s34_i + 2 a2 sin(beta3/2)``.

**API.**  ``SCENE`` (cruise), ``LANDING_SCENE`` / ``scene_for(scenario)``, ``params(scenario,
**overrides)``; from the command line ``jaxmech run arc_track_flap`` (cruise) and
``jaxmech run arc_track_flap_landing`` (landing, its own title and files).  ``design(**inputs)`` (Chapter 4: inputs -> parameters),
``geometry(p)``, ``validate(p, s34=None)`` (Section 5.3's red cells), ``forces(p, s34)``,
``quasi_static(q, u, p)``, ``screw_torques(L, p)``, ``air_moment(s34, p)``,
``accelerations(p)``, ``fairing_depth(p)``, ``table2(p)``, ``table3(p)``; ``MECHANISM``,
``MODEL`` (``jaxmech.dynamics``), ``SCREW`` (``jaxmech.actuators.ScrewJack``).

Units: SI throughout (m, rad, N, N m, kg, s).
"""

from .model import MM as MM
from .model import DEG as DEG
from .model import SCENARIOS as SCENARIOS
from .model import THESIS_INPUTS as THESIS_INPUTS
from .model import PARAM_NAMES as PARAM_NAMES
from .model import PARAMETERS as PARAMETERS
from .model import stroke_ends as stroke_ends
from .model import geometry as geometry
from .model import design as design
from .model import validate as validate
from .model import MECHANISM as MECHANISM
from .model import initial_pose as initial_pose
from .model import air_moment as air_moment
from .model import SCREW as SCREW
from .model import MODEL as MODEL
from .model import screw_torques as screw_torques
from .model import quasi_static_one as quasi_static_one
from .model import quasi_static as quasi_static
from .model import scene_for as scene_for
from .model import SCENE as SCENE
from .model import LANDING_SCENE as LANDING_SCENE
from .tables import params as params
from .tables import forces as forces
from .tables import accelerations as accelerations
from .tables import fairing_depth as fairing_depth
from .tables import table2 as table2
from .tables import table3 as table3

__all__ = ["SCENE", "LANDING_SCENE", "SCENARIOS", "PARAMETERS", "THESIS_INPUTS", "MECHANISM", "scene_for", "params", "design", "geometry", "validate", "air_moment", "screw_torques", "SCREW", "MODEL", "quasi_static", "forces", "accelerations", "fairing_depth", "table2", "table3"]
