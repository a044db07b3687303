"""Where the power goes: the power balance of a ``Model`` at every sample of an inverse-dynamics
result.

The drive's power goes into kinetic energy, into potential energy (gravity and the loads
that store it: springs), into the loads that dissipate it (dampers) and the joints' friction,
and into the other loads (the mechanism's work on them: its output):

    P_in = sum tau_i u_dot_i = dT/dt + dV/dt + P_dissipated + P_loads

Each term is computed on its own from the sample's motion (the bodies' velocities and
accelerations, every load's point velocity, angle rate or length rate, along the exact
second-order path of ``virtual_power.loaded_state``) and the loads' values:

- ``dT/dt = sum m v_G . a_G + J omega alpha``;
- ``dV/dt = -sum m g . v_G`` (gravity) ``- P`` of every storing load;
- ``P`` of a load: ``F . v_P`` (a ``PointForce``), ``M dangle/dt`` (a ``Moment``), ``-T
  dL/dt`` (an ``Axial``): the power it puts into the mechanism; a dissipating load's
  ``-P`` is what it dissipates, any other load's ``-P`` what the mechanism delivers to it;
- a joint's friction (``dynamics.friction``; the result's ``joint_friction``, its load ``f``
  on the joint's second body and ``-f`` on the first, at one point): ``-f w``, ``w`` the
  joint's relative speed (``friction.joint_speeds``): what it dissipates
  (``mu r |F| |w| + c w^2`` at a pin).

``tau`` comes from the balance of virtual power with the loop multipliers (or the
joints' Newton-Euler system), not from these terms, so the returned residual ``P_in - dT/dt
- dV/dt - P_dissipated - P_loads`` is a check, zero to round-off where both are right.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..solver.xla import jit
from .friction import JointFriction, joint_speeds
from .model import Axial, Model, Moment, PointForce, Potential, prepare_params
from .virtual_power import loaded_state

__all__ = ["PowerBalance", "power_balance"]


def _dot(a, b):
    """Real dot product of two planar vectors given as complex numbers."""
    return jnp.real(jnp.conj(a) * b)


def _integral(y, t):
    """The trapezoidal integral of samples `y` over times `t` (one stroke)."""
    return 0.5 * jnp.sum((y[1:] + y[:-1]) * jnp.diff(t))


class PowerBalance(NamedTuple):
    """The power balance along a stroke, every field in W per sample ``(N,)`` (`t` in s):

    - `input`: the drive's power ``sum tau u_dot`` (positive: the drive puts energy in);
    - `kinetic`: ``dT/dt``, the rate of change of kinetic energy;
    - `potential`: ``dV/dt`` of gravity and the springs (positive: energy stored);
    - `dissipated`: the power the dampers and the joints' friction take out (never negative);
    - `loads`: the power the mechanism delivers to its other loads (forces, moments, a
      user's own loads; negative where they drive it);
    - `residual`: ``input - kinetic - potential - dissipated - loads``: round-off;
    - `elements`: ``{element: W}`` each spring's ``dV/dt`` and each damper's dissipation;
    - `joints`: ``{joint: W}`` each friction joint's dissipation ``-f w`` (its friction load
      times its relative speed; positive: dissipating), counted in `dissipated`.

    NaN where the position failed.
    """

    t: jax.Array
    input: jax.Array
    kinetic: jax.Array
    potential: jax.Array
    dissipated: jax.Array
    loads: jax.Array
    residual: jax.Array
    elements: dict
    joints: dict

    def work(self) -> dict:
        """Each field's energy over the stroke (J): the trapezoidal integral of its samples
        over `t` (``"input"``, ``"kinetic"``, ... and the elements by name).  Unlike the power
        balance at each sample, these close only to the quadrature's error."""
        fields = {k: getattr(self, k) for k in ("input", "kinetic", "potential", "dissipated", "loads", "residual")}
        return {k: _integral(v, self.t) for k, v in {**fields, **self.elements}.items()}

    @property
    def efficiency(self):
        """The stroke's mechanical efficiency ``E_loads / E_in`` (-): the work delivered to the
        loads over the energy the drive put in (``work()``).  It means something where the
        drive puts energy in and the loads take it out (both positive): NaN otherwise (a
        stroke driven by its loads, or one the drive brakes).  Energy stored in springs,
        gravity and motion at the stroke's end counts as not delivered."""
        w = self.work()
        e_in, e_out = w["input"], w["loads"]
        return jnp.where((e_in > 0) & (e_out >= 0), e_out / jnp.where(e_in > 0, e_in, 1.0), jnp.nan)


def _load_powers(model: Model, st) -> list:
    """The power (W) each load of the model puts into the mechanism at a ``LoadedState``, in
    the model's load order (gravity: none here)."""
    rates = st.rates
    forces, moments, tensions = iter(zip(st.forces, rates[2])), iter(zip(st.moments, rates[3])), iter(zip(st.tensions, rates[4]))
    out = []
    for ld in model.loads:
        if isinstance(ld, PointForce):
            f, v = next(forces)
            out.append((ld.name, _dot(f, v)))
        elif isinstance(ld, Moment):
            m, w = next(moments)
            out.append((ld.name, m * w))
        elif isinstance(ld, Axial):
            tension, ldot = next(tensions)
            out.append((ld.name, -tension * ldot))
    return out


def sample_power(model: Model, stored: tuple, dissipated: tuple, friction, p, t, q, u, ud, udd, qd, qdd, tau, jf) -> dict:
    """The power balance's terms at one sample (W): a dict of ``PowerBalance``'s fields but
    `t`.  `stored`, `dissipated`: the names of the loads that store and that dissipate
    energy; `friction` the ``JointFriction`` (or None) and `jf` ``(k,)`` its joints' friction
    loads; `q`, `u` and their rates the sample's motion; `tau` the drive's effort."""
    st = loaded_state(model, q, u, ud, udd, p, t, q_dot=qd, q_ddot=qdd)
    v_g, omega = st.rates[0], st.rates[1]
    a_g, alpha = st.accels[0], st.accels[1]
    zero = jnp.zeros((), q.dtype)
    kinetic, potential = zero, zero
    for k in range(len(model.bodies)):
        kinetic = kinetic + st.masses[k] * _dot(v_g[k], a_g[k]) + st.inertias[k] * omega[k] * alpha[k]
        for g in st.gravity:
            potential = potential - st.masses[k] * _dot(g, v_g[k])
    lost, delivered, elements = zero, zero, {}
    for name, power in _load_powers(model, st):
        if name in stored:
            elements[name] = -power
            potential = potential - power
        elif name in dissipated:
            elements[name] = -power
            lost = lost - power
        else:
            delivered = delivered - power
    joints = {}
    if friction is not None:
        w = joint_speeds(model, friction, q, u, p, qd, ud)
        joints = {fj.joint: -jf[k] * w[k] for k, fj in enumerate(friction.joints)}
        lost = lost + sum(joints.values())
    inp = jnp.sum(tau * ud)
    out = dict(input=inp, kinetic=kinetic, potential=potential, dissipated=lost, loads=delivered,
               residual=inp - kinetic - potential - lost - delivered, elements=elements, joints=joints)
    return jax.tree_util.tree_map(lambda x: jnp.where(st.ok, x, jnp.nan), out)


@functools.partial(jit, static_argnums=(0, 1, 2, 3))
def _powers(model, stored, dissipated, friction, p, t, q, u, ud, udd, qd, qdd, tau, jf):
    return jax.vmap(lambda *a: sample_power(model, stored, dissipated, friction, p, *a))(t, q, u, ud, udd, qd, qdd, tau, jf)


def _friction_loads(result, friction: JointFriction | None):
    """The result's joint friction loads ``(N, k)`` in the order of `friction`'s joints;
    ``ValueError`` where the result and `friction` do not go together (a balance that
    would not close)."""
    have = dict(result.joint_friction or {})
    if friction is None:
        if have:
            raise ValueError("power_balance: the result has joint friction; give friction= (the JointFriction it was computed with)")
        return jnp.zeros((result.q.shape[0], 0), result.q.dtype)
    missing = [fj.joint for fj in friction.joints if fj.joint not in have]
    if missing:
        raise ValueError(f"power_balance: the result has no joint friction at {missing}; "
                         "give a result of inverse_dynamics(..., friction=) with the same friction")
    return jnp.stack([jnp.asarray(have[fj.joint], result.q.dtype) for fj in friction.joints], axis=-1)


def power_balance(model: Model, result, p: Mapping, *, stored=(), dissipated=(), friction: JointFriction | None = None) -> PowerBalance:
    """The power balance at every sample of an inverse-dynamics `result` (an
    ``InverseDynamics`` along a drive, with inertia) of `model` for its parameters `p`.

    - `stored`: the names of the loads that store energy (springs: their power counts in
      ``potential``); `dissipated`: those that dissipate it (dampers).  Every other load is
      an output (``loads``).  A ``Linkage`` says which of its elements are which.
    - `friction`: the ``JointFriction`` the result was computed with (its ``joint_friction``
      loads): each joint's dissipation in ``joints`` and in ``dissipated``.

    **Returns** a ``PowerBalance`` (W per sample; its ``residual`` is round-off).

    **Raises** ``ValueError`` for a model with a ``Potential`` load (its energy has no
    place of application here: give it as a load with a point or an angle), a result
    without velocities (a statics result: no power), or a result with joint friction
    without `friction` (or the other way round)."""
    for ld in model.loads:
        if isinstance(ld, Potential):
            raise ValueError(f"power_balance: load {ld.name!r} is a Potential; give it as a PointForce, Moment or Axial")
    if result.q_dot is None:
        raise ValueError("power_balance: the result has no velocities; give an inverse-dynamics result along a drive")
    known = {ld.name for ld in model.loads}
    for name in (*stored, *dissipated):
        if name not in known:
            raise ValueError(f"power_balance: no load named {name!r}; the model's loads are {sorted(known)}")
    jf = _friction_loads(result, friction)
    dtype = result.q.dtype
    if friction is not None:
        friction.check(model)
    extra = () if friction is None else tuple(n for n in friction.parameters if n not in model.parameters)
    pj = prepare_params(model, p, dtype, extra)  # (the friction's values are in the result's loads already)
    out = _powers(model, tuple(stored), tuple(dissipated), friction, pj, jnp.asarray(result.t, dtype), result.q, result.u,
                  result.u_dot, result.u_ddot, result.q_dot, result.q_ddot, result.tau, jf)
    return PowerBalance(t=jnp.asarray(result.t, dtype), **out)
