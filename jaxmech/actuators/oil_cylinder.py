"""A hydraulic cylinder whose oil chamber is compressible: its pressure is a state.

The cylinder drives an input of a model that is its piston position ``x`` (m).  Its one
chamber holds oil of bulk modulus ``beta`` in the volume ``V(x) = V0 + A (x - x0)`` and
is fed a flow ``Q(t)`` (m^3/s, positive in).  Mass conservation with ``dp = beta dV/V``:

    dP/dt = beta / V(x) * (Q(t) - A x_dot),        force on the input  F = P A  (N),

positive extending (gauge pressure, no rod-side chamber, no friction).  With the chamber
closed (``Q = 0``) this integrates to ``P = P0 - beta ln(V(x) / V(x0))``, a stiff nonlinear
spring of stiffness ``beta A^2 / V`` (``tests/test_actuators.py`` holds a run to it).

A ``StatefulActuator`` (``jaxmech.actuators``): ``forward_dynamics(..., actuators={"x":
OilCylinder(...)})``; registered as ``"oil_cylinder"``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import jax.numpy as jnp

from . import Spec, command, resolve

__all__ = ["OilCylinder"]


@dataclasses.dataclass(frozen=True)
class OilCylinder:
    """Single-acting cylinder with a compressible-oil chamber (state: pressure, Pa).

    **Arguments** (specs, SI): `bore` ``D`` (m; area ``A = pi D^2 / 4``); `volume0` ``V0``
    (m^3), the chamber volume at piston position `position0` ``x0`` (m); `bulk_modulus`
    ``beta`` (Pa); `pressure0` (Pa), the pressure at the start of a run; `flow` ``Q`` into
    the chamber, a parameter name, a number or ``fn(t, p)`` (m^3/s).
    """

    bore: Spec = "bore"
    volume0: Spec = "V0"
    position0: Spec = "x0"
    bulk_modulus: Spec = "beta"
    pressure0: Spec = "P0"
    flow: Spec | Callable = 0.0

    n_states = 1  # the chamber pressure

    def area(self, p):
        """Piston area ``A`` (m^2)."""
        return jnp.pi * resolve(self.bore, p) ** 2 / 4

    def volume(self, position, p):
        """Chamber volume ``V0 + A (x - x0)`` (m^3)."""
        return resolve(self.volume0, p) + self.area(p) * (position - resolve(self.position0, p))

    def initial_state(self, p):
        return jnp.reshape(jnp.asarray(resolve(self.pressure0, p), float), (1,))

    def force(self, state, position, speed, t, p):
        """``P A`` (N, extending)."""
        return state[0] * self.area(p)

    def rate(self, state, position, speed, t, p):
        """``(dP/dt,) = (beta (Q - A x_dot) / V,)`` (Pa/s)."""
        q_in = command(self.flow, t, p)
        return jnp.stack([resolve(self.bulk_modulus, p) * (q_in - self.area(p) * speed) / self.volume(position, p)])
