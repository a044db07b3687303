"""Inverse dynamics: the driving forces, the constraint reactions and (for a model with
joints) every joint's reaction, at a batch of independent states (``inverse_dynamics_at``,
``statics``) or along a drive (``inverse_dynamics``), by virtual power
(``virtual_power.balance``) and the per-body Newton-Euler equations
(``reactions.joint_reactions``) at positions solved by the engine."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..continuation.solve import stroke
from ..solver.implicit import input_derivatives
from ..solver.inputs import as_coords, as_inputs, batch_shape
from ..kinematics import chain_rule, drive_rates, drive_samples, join_drive, point_kinematics, split_drive
from ..solver.options import SolverOptions
from ..solver.positions import solve_one
from ..solver.status import Status
from ..solver.xla import jit
from .friction import (JointFriction, friction_parameters, friction_reactions, friction_signs, friction_speeds, friction_status,
                       joint_speeds, stroke_signs)
from .joints import Prismatic, Slot, joint_name
from .model import Model, mechanism_params, prepare_params
from .reactions import joint_axes, joint_reactions
from .virtual_power import balance, loaded_state

__all__ = ["InverseDynamics", "Holding", "holding", "inverse_dynamics", "inverse_dynamics_at",
           "inverse_dynamics_batch", "statics"]


class JointBodies(NamedTuple):
    """A joint of a result (``InverseDynamics.joint_bodies``): its name, its first and
    second bodies (its reaction is the first's force on the second), and the index of the
    input it drives where it is a driven slider (-1 otherwise: a driven pin's effort is a
    torque, an actuator's push is its reaction already)."""

    joint: str
    first: str
    second: str
    drive: int


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class InverseDynamics:
    """Inverse-dynamics result (a pytree; leading axes = samples).

    - `t` (s), `u`, `u_dot`, `u_ddot` ``(..., dof)``; `q`, `q_dot`, `q_ddot` ``(..., m)``.
    - `tau`: driving force/torque on each input ``(..., dof)`` (N or N m), positive in the
      input's positive sense.
    - `reactions`: the loop equations' multipliers ``(..., m)`` (N for loops in metres; see
      ``virtual_power``): ``reaction("loop 2")`` pairs a loop's two rows as ``Fx + i Fy``.
    - `points`: ``{name: (position, velocity, acceleration)}`` of every named point of the
      mechanism (complex ``x + i y``: m, m/s, m/s^2).
    - `joints`: for a model with joints, ``{joint: F}``: the force (N, complex, global) that
      the joint's first body exerts on its second (``dynamics.joints``), from the per-body
      Newton-Euler equations; `joint_moments`: ``{joint: M}`` (N m) of prismatic joints.
      Per link: ``force_on(link, joint)``; a slider's or slot's ``normal_force(joint)``.
    - `joint_normals`: ``{joint: n}`` the unit normal (complex, global) of every slider's
      guide and every slot at each sample, along which its normal force acts.
    - `joint_bodies`: a ``JointBodies`` (joint, first and second body, the driven slider's
      input index) per joint, in the order of ``Model.joints`` (static).
    - `status`: position-solve ``Status`` per sample (NaN results where not CONVERGED;
      with joint friction, ``MAX_STEPS`` where the friction's Newton did not converge: a
      linkage jammed by friction, which no effort drives that way).
    - `joint_friction`: with joint friction (``friction=``), ``{joint: f}`` each joint's
      friction load on its second body: a pin's moment (N m, CCW), a guide's or slot's
      force along its direction (N) (``dynamics.friction``); `tau` and `joints` include
      it.  The loop multipliers `reactions` do not.
    """

    t: jax.Array
    u: jax.Array
    u_dot: jax.Array
    u_ddot: jax.Array
    q: jax.Array
    tau: jax.Array
    reactions: jax.Array
    status: jax.Array
    q_dot: jax.Array | None = None
    q_ddot: jax.Array | None = None
    points: dict = dataclasses.field(default_factory=dict)
    joints: dict = dataclasses.field(default_factory=dict)
    joint_moments: dict = dataclasses.field(default_factory=dict)
    joint_normals: dict = dataclasses.field(default_factory=dict)
    loops: tuple = dataclasses.field(metadata=dict(static=True), default=())
    joint_bodies: tuple = dataclasses.field(metadata=dict(static=True), default=())
    joint_friction: dict = dataclasses.field(default_factory=dict)

    def reaction(self, name):
        """The reaction named `name` (N, complex ``Fx + i Fy``, one per sample):

        - a joint's name (models with joints): the force its first body exerts on its second;
        - a loop's name (``Mechanism.equations``: ``"loop 1"``, or the constraints' mapping
          keys): the multipliers of that loop's two rows as ``Fx + i Fy`` (a real equation's
          one multiplier as a real number); an ``int`` k is the k-th loop (from 0).

        **Raises** ``ValueError`` for a name or index that is neither.
        """
        if isinstance(name, str) and name in self.joints:
            return self.joints[name]
        if isinstance(name, (int, np.integer)) and not isinstance(name, bool):
            if not 0 <= name < len(self.loops):
                raise ValueError(f"reaction({name}): there are {len(self.loops)} loops (0 to {len(self.loops) - 1}): "
                                 f"{[n for n, _ in self.loops]}")
            name = self.loops[name][0]
        for loop, rows in self.loops:
            if loop == name:
                if len(rows) == 2:
                    return jax.lax.complex(self.reactions[..., rows[0]], self.reactions[..., rows[1]])
                return self.reactions[..., rows[0]]
        known = list(self.joints) + [n for n, _ in self.loops]
        raise ValueError(f"no joint or loop named {name!r}; known: {known}")

    def _joint(self, joint: str, what: str) -> JointBodies:
        for entry in self.joint_bodies:
            if entry.joint == joint:
                return entry
        if not self.joint_bodies:
            raise ValueError(f"{what}: this result has no joint reactions (a Model without joints=; a Linkage has them)")
        raise ValueError(f"{what}: no joint named {joint!r}; joints are {[j.joint for j in self.joint_bodies]}")

    def force_on(self, link: str, joint: str):
        """The force (N, complex ``Fx + i Fy``, global frame, one per sample) that the rest of
        the mechanism exerts on `link` through `joint`: on a pin's link, the pin's force on
        it; on a slider's block, the guide's normal force plus, where the slider is driven,
        the drive's force along the guide (``tau``); on the guide, the opposite; on an
        actuator's link, the actuator's push or pull.  `link` is one of the joint's two
        bodies (``"ground"`` gives the force on the frame).

        Newton's third law holds by construction, ``force_on(a, J) == -force_on(b, J)``, and
        per link ``sum_J force_on(link, J) + gravity + loads = m a_G``.  Couples are not
        forces: a driven pin's torque is in ``tau``, a slider's guide moment in
        ``joint_moments``.  ``joints[J]`` is ``force_on(second body, J)`` less a driven
        slider's drive force.

        **Raises** ``ValueError`` for an unknown joint, or a link the joint does not join.
        """
        j = self._joint(joint, f"force_on({link!r}, {joint!r})")
        if link not in (j.first, j.second):
            raise ValueError(f"force_on({link!r}, {joint!r}): joint {joint!r} joins {j.first!r} and {j.second!r}; "
                             "ask for the force on one of them")
        force = self.joints[joint]
        if j.drive >= 0:  # a driven slider: the drive pushes the block along the guide, e = -i n
            force = force - 1j * self.joint_normals[joint] * self.tau[..., j.drive]
        return force if link == j.second else -force

    def normal_force(self, joint: str):
        """A slider's or a slot's normal force (N, real, one per sample): the force of the
        joint's first body (the guide, the slotted body) on its second (the block, the pin's
        link) along the joint's normal ``joint_normals[joint]``: the guide's left normal
        (``i e``, ``e`` the guide's direction), or a circular slot's radius from its centre
        to the pin.  Positive pushes the block to the guide's left (out of a circular slot's
        centre).  A driven slider's drive force along the guide is not in it (``tau``).

        **Raises** ``ValueError`` for a joint that is not a slider or a slot."""
        self._joint(joint, f"normal_force({joint!r})")
        if joint not in self.joint_normals:
            raise ValueError(f"normal_force({joint!r}): {joint!r} is not a slider or a slot; "
                             f"they are {list(self.joint_normals)} (a pin's force is force_on(link, joint))")
        return jnp.real(self.joints[joint] * jnp.conj(self.joint_normals[joint]))


def _sample(model: Model, quasi_static: bool, names, p, t, u, ud, udd, q, d1, d2, signs=None, speeds=None, friction=None):
    """Everything at one sample from its position and per-unit-input derivatives: the rates,
    the points' kinematics, the drive efforts, multipliers and joint reactions; with
    `friction`, the reactions and efforts with joint friction (`signs` and `speeds` of the
    joints' relative motion, ``dynamics.friction``)."""
    mech = model.mechanism
    ok = jnp.all(jnp.isfinite(q))
    qs = jnp.where(ok, q, 0.0)
    qd, qdd = chain_rule(jnp.where(ok, d1, 0.0), jnp.where(ok, d2, 0.0), ud, udd)
    st = loaded_state(model, q, u, ud, udd, p, t, inertia=not quasi_static, q_dot=qd, q_ddot=qdd)
    tau, lam = balance(model, st)
    nan = lambda x: jnp.where(ok, x, jnp.nan)  # noqa: E731
    # the bodies' centres of mass, which the balance has differentiated twice already
    known = {}
    if st.accels is not None:
        known = {b.position: (st.poses[0][k], st.rates[0][k], st.accels[0][k])
                 for k, b in enumerate(model.bodies) if isinstance(b.position, str) and b.position in names}
    pts = point_kinematics(mech, tuple(n for n in names if n not in known), p, qs, qd, qdd, u, ud, udd)
    pts = {n: known[n] if n in known else pts[n] for n in names}
    out = dict(tau=tau, reactions=lam, q_dot=nan(qd), q_ddot=nan(qdd), points=jax.tree_util.tree_map(nan, pts), joints={},
               joint_moments={}, joint_normals={})
    if model.joints and friction is not None:
        fres = friction_reactions(model, friction, st, signs, speeds)
        out.update(tau=tau + fres.efforts, joints=fres.forces, joint_moments=fres.moments, friction_ok=fres.converged,
                   joint_friction={fj.joint: fres.friction[k] for k, fj in enumerate(friction.joints)})
    elif model.joints:
        _, out["joints"], out["joint_moments"] = joint_reactions(model, st)
    if model.joints:
        out["joint_normals"] = {joint_name(j): nan(joint_axes(model, j, st.q, st.u, st.p)[1])
                                for j in model.joints if isinstance(j, (Prismatic, Slot))}
    return out


def _at_one(model, quasi_static, names, options, u, ud, udd, p, t, guess, friction=None, scale=None):
    mech = model.mechanism
    sol = solve_one(mech, u, mechanism_params(model, p), guess, options)
    ok = sol.status == Status.CONVERGED
    d1, d2 = input_derivatives(mech, jnp.where(ok, sol.q, 0.0), u, mechanism_params(model, p), ok)
    if friction is None:
        return dict(_sample(model, quasi_static, names, p, t, u, ud, udd, sol.q, d1, d2), q=sol.q, status=sol.status)
    w = _speeds(model, friction, p, u, ud, udd, sol.q, d1, d2)
    out = _sample(model, quasi_static, names, p, t, u, ud, udd, sol.q, d1, d2, friction_signs(friction, w, scale), w,
                  friction=friction)
    return _with_friction_status(out, sol.q, sol.status)


@functools.partial(jit, static_argnums=(0, 1, 2), static_argnames=("friction",))
def inverse_dynamics_batch(model, quasi_static, options, u, ud, udd, p, t, guess, *, friction=None, scale=None):
    """The compiled kernel of ``inverse_dynamics_at`` on a flat batch (jit; `model`,
    `quasi_static`, `options` and `friction` static): `u`, `ud`, `udd` ``(n, dof)``, `p`
    leaves ``(n,)``, `t` ``(n,)``, `guess` ``(n, m)``, `scale` ``(k,)`` the friction joints'
    speed scales (with `friction`), no checks.  Returns a dict of the ``InverseDynamics``
    fields (``q``, ``tau``, ``reactions``, ``status``, ``points``, ``joints``...)."""
    names = tuple(model.mechanism.points)
    one = lambda *a: _at_one(model, quasi_static, names, options, *a, friction=friction, scale=scale)  # noqa: E731
    return jax.vmap(one)(u, ud, udd, p, t, guess)


def _joint_bodies(model: Model) -> tuple[JointBodies, ...]:
    inputs = model.mechanism.inputs
    return tuple(JointBodies(joint_name(j), *j.bodies, inputs.index(j.input) if isinstance(j, Prismatic) and j.input else -1)
                 for j in model.joints)


def _result(model: Model, t, u, ud, udd, fields) -> InverseDynamics:
    return InverseDynamics(t=t, u=u, u_dot=ud, u_ddot=udd, loops=model.mechanism.equations, joint_bodies=_joint_bodies(model), **fields)


def inverse_dynamics_at(model: Model, u, u_dot, u_ddot, p: Mapping, guess, *, t=0.0, quasi_static: bool = False,
                        options: SolverOptions = SolverOptions(), friction: JointFriction | None = None,
                        friction_speed=None) -> InverseDynamics:
    """Driving forces and reactions at a batch of independent states (jit, vmapped).

    **Arguments**: `u`, `u_dot`, `u_ddot`: ``(..., dof)`` (or the bare batch for one input);
    `p`: parameters (arrays broadcast against the batch); `guess`: ``(..., m)`` coordinates
    near each solution (it picks the branch); `t`: time(s) for time-dependent loads;
    `quasi_static`: leave inertia out (``statics`` is this at rest).  `friction`: joint
    friction (a ``JointFriction``, its parameters in `p`) with `friction_speed` its sign's
    speed scale ``W`` (a number, or one per friction joint: independent states have no
    stroke to take it from, as forward dynamics has none); None: none.

    **Returns** an ``InverseDynamics`` with the broadcast batch shape in front (with
    friction, its ``joint_friction`` and ``MAX_STEPS`` where friction jams the state).
    """
    mech = model.mechanism
    scale = friction_speeds(friction, friction_speed)
    extra = friction_parameters(model, friction)
    u = as_inputs(mech, u)
    ud = as_inputs(mech, u_dot, "u_dot")
    udd = as_inputs(mech, u_ddot, "u_ddot")
    guess = as_coords(mech, guess)
    dtype = jnp.result_type(u, ud, udd, guess, float)
    p = prepare_params(model, p, dtype, extra)
    t = jnp.asarray(t, dtype)
    shape = batch_shape(mech, {"u": u.shape[:-1], "u_dot": ud.shape[:-1], "u_ddot": udd.shape[:-1], "guess": guess.shape[:-1],
                               "t": t.shape, **{f"p[{k!r}]": v.shape for k, v in p.items()}})
    n = int(np.prod(shape, dtype=np.int64))
    flat = lambda x, k: jnp.broadcast_to(x, shape + x.shape[x.ndim - k:]).reshape((n,) + x.shape[x.ndim - k:])  # noqa: E731
    args = [flat(x.astype(dtype), 1) for x in (u, ud, udd)]
    pf = {k: flat(v, 0) for k, v in p.items()}
    fr = {} if friction is None else dict(friction=friction, scale=jnp.asarray(scale, dtype))
    out = inverse_dynamics_batch(model, bool(quasi_static), options, *args, pf, flat(t, 0), flat(guess.astype(dtype), 1), **fr)
    out = jax.tree_util.tree_map(lambda x: x.reshape(shape + x.shape[1:]), out)
    r = lambda x: x.reshape(shape + x.shape[1:])  # noqa: E731
    return _result(model, jnp.broadcast_to(t, shape), r(args[0]), r(args[1]), r(args[2]), out)


def statics(model: Model, u, p: Mapping, guess, *, t=0.0, options: SolverOptions = SolverOptions()) -> InverseDynamics:
    """Statics at given poses: the holding torque (or force) on each input and every
    reaction, at rest under gravity and the loads (no inertia, zero rates), for a batch of
    inputs ``u (..., dof)``.  What a peer tool calls a static force analysis; for the input
    at which the loads balance with no drive, see ``equilibrium``.

    **Returns** an ``InverseDynamics`` (``tau``: the effort the drive must hold, N m or N;
    ``joints``: every joint's reaction for a model with joints)."""
    zero = jnp.zeros_like(as_inputs(model.mechanism, u))
    return inverse_dynamics_at(model, u, zero, zero, p, guess, t=t, quasi_static=True, options=options)


class AlongDrive(NamedTuple):
    """``_along``'s result: the drive's inputs `u` and their rates ``(N, dof)``, and every
    sample's dynamics `samples` (``_sample``'s mapping, leading axis N)."""

    u: jax.Array
    u_dot: jax.Array
    u_ddot: jax.Array
    samples: dict


@functools.partial(jit, static_argnums=(0, 1, 2, 3))
def _along(model, quasi_static, names, drive_static, drive_leaves, p, t, q, d1, d2):
    drive = join_drive(drive_static, drive_leaves)
    u, ud, udd = drive_rates(drive, t, model.mechanism.dof)
    out = jax.vmap(lambda *a: _sample(model, quasi_static, names, p, *a))(t, u, ud, udd, q, d1, d2)
    return AlongDrive(u, ud, udd, out)


def inverse_dynamics(model: Model, drive, t=None, p: Mapping | None = None, guess=None, *, quasi_static: bool = False,
                     options: SolverOptions = SolverOptions(), friction: JointFriction | None = None) -> InverseDynamics:
    """Driving force/torque and reactions along a drive (one design).

    **Arguments**

    - `drive`: ``u(t)``, a pytree drive law (``ConstantSpeed``, ``SmoothStart``...) or any
      differentiable function, scalar for one input or ``(dof,)``; or ``Samples(u, u_dot,
      u_ddot)`` (no `t`): the inputs and their rates, in the order the stroke passes them.
    - `t`: ``(N,)`` times (s) in order; positions are solved by continuation along them.
    - `p`: parameters; `guess`: coordinates at the first sample (picks the branch).
    - `quasi_static`: leave inertia out.
    - `friction`: joint friction (``dynamics.friction.JointFriction``; its parameters in
      `p`), its sign regularised over this stroke's joint speeds; None: none (the
      frictionless program, unchanged).

    **Returns** an ``InverseDynamics`` with leading axis ``N``; NaN where the position
    status is not ``CONVERGED``.

    Power balance (a check the tests make): ``tau . u_dot = dT/dt - Pi_loads``.
    """
    mech = model.mechanism
    if p is None or guess is None:
        raise ValueError(f"{mech.name}: inverse_dynamics needs the parameters p= and a guess= at the first sample")
    drive, us, t = drive_samples(mech, drive, t)
    extra = friction_parameters(model, friction)
    model.check_params(p, extra)
    # positions, dq/du and d2q/du2 in one compiled pass; the drive's rates give the rest
    sol, d1, d2 = stroke(mech, us, mechanism_params(model, p), guess, options, derivs=True)
    dtype = sol.q.dtype
    pj = prepare_params(model, p, dtype, extra)
    static, leaves = split_drive(drive)
    if leaves is not None:
        leaves = [jnp.asarray(x, dtype) for x in leaves]
    if friction is None:
        u, ud, udd, out = _along(model, bool(quasi_static), tuple(mech.points), static, leaves, pj, t.astype(dtype), sol.q, d1, d2)
        return _result(model, t, u, ud, udd, dict(out, q=sol.q, status=sol.status))
    u, ud, udd, out = _along_friction(model, friction, bool(quasi_static), tuple(mech.points), static, leaves, pj, t.astype(dtype),
                                      sol.q, d1, d2)
    return _result(model, t, u, ud, udd, _with_friction_status(out, sol.q, sol.status))


def _speeds(model, friction, p, u, ud, udd, q, d1, d2):
    """The joints' relative speeds at one sample of a stroke (zero where it failed)."""
    ok = jnp.all(jnp.isfinite(q))
    qd, _ = chain_rule(jnp.where(ok, d1, 0.0), jnp.where(ok, d2, 0.0), ud, udd)
    return joint_speeds(model, friction, jnp.where(ok, q, 0.0), u, p, qd, ud)


def _with_friction_status(out: dict, q, status) -> dict:
    """The samples' fields with ``MAX_STEPS`` where the position converged but friction did not."""
    return dict(out, q=q, status=friction_status(status, out.pop("friction_ok")))


@functools.partial(jit, static_argnums=(0, 1, 2, 3, 4))
def _along_friction(model, friction, quasi_static, names, drive_static, drive_leaves, p, t, q, d1, d2):
    drive = join_drive(drive_static, drive_leaves)
    u, ud, udd = drive_rates(drive, t, model.mechanism.dof)
    w = jax.vmap(lambda *a: _speeds(model, friction, p, *a))(u, ud, udd, q, d1, d2)
    signs = stroke_signs(friction, w, jnp.all(jnp.isfinite(q), axis=-1))
    out = jax.vmap(lambda *a: _sample(model, quasi_static, names, p, *a, friction=friction))(t, u, ud, udd, q, d1, d2, signs, w)
    return AlongDrive(u, ud, udd, out)


class Holding(NamedTuple):
    """Statics with joint friction (``holding``): what holds the linkage at each pose.

    - `up`: an ``InverseDynamics`` at rest whose `tau` is the effort that drives the
      linkage on, in the input's positive sense (along ``direction``), friction opposing
      that motion (the effort to raise a load);
    - `back`: the same holding it back: the effort at which it starts to move the other
      way, friction helping the drive (the effort to lower a load, negative where it
      must be pulled down); ``back.tau <= up.tau`` with the frictionless effort between;
    - `self_locking` ``(...)``: True where zero lies between them for every input: with
      the drive released the linkage stays put (friction alone holds the loads).  A sense
      that friction jams (no effort moves it that way: its ``status`` is ``MAX_STEPS``,
      its efforts NaN) holds whatever the effort; a pose that does not assemble is not
      self-locking.
    """

    up: InverseDynamics
    back: InverseDynamics
    self_locking: jax.Array


@functools.partial(jit, static_argnums=(0, 1, 2))
def _holding_batch(model, friction, options, u, direction, p, t, guess):
    mech, names = model.mechanism, tuple(model.mechanism.points)

    def position(u_, p_, g_):
        sol = solve_one(mech, u_, mechanism_params(model, p_), g_, options)
        ok = sol.status == Status.CONVERGED
        d1, d2 = input_derivatives(mech, jnp.where(ok, sol.q, 0.0), u_, mechanism_params(model, p_), ok)
        return sol.q, sol.status, d1, d2

    q, status, d1, d2 = jax.vmap(position)(u, p, guess)
    zero = jnp.zeros_like(u)
    w = jax.vmap(lambda *a: _speeds(model, friction, *a))(p, u, direction, zero, q, d1, d2)
    signs = stroke_signs(friction, w, jnp.all(jnp.isfinite(q), axis=-1))  # the sense each joint moves in, per unit input rate

    def at_rest(sg):  # the loads at rest (no rate), friction along the sense `sg`, no viscous term
        one = lambda *a: _sample(model, True, names, *a, friction=friction)  # noqa: E731
        out = jax.vmap(one)(p, t, u, zero, zero, q, d1, d2, sg, jnp.zeros_like(w))
        moves = out["friction_ok"]  # False: friction jams this sense (no effort moves it)
        return _with_friction_status(out, q, status), moves

    return at_rest(signs), at_rest(-signs)


def holding(model: Model, u, p: Mapping, guess, friction: JointFriction, *, direction=None, t=0.0,
            options: SolverOptions = SolverOptions()) -> Holding:
    """Statics with joint friction at a batch of poses ``u (..., dof)``: the effort that
    drives the linkage on and the one that holds it back, and where it is self-locking (a
    ``Holding``).  `guess` ``(..., m)`` picks each pose's branch; `direction` ``(dof,)``
    the sense "on" means (default +1 on every input); friction's sign is regularised over
    the batch's joint speeds per unit input rate (``dynamics.friction``), so a joint that
    barely turns at a pose (a toggle) carries less of its friction there."""
    mech = model.mechanism
    extra = friction_parameters(model, friction)
    if friction is None:
        raise ValueError("holding: give friction= (a JointFriction); without friction the holding effort is statics()'s")
    u, guess = as_inputs(mech, u), as_coords(mech, guess)
    direction = jnp.ones((mech.dof,)) if direction is None else as_inputs(mech, direction, "direction")
    dtype = jnp.result_type(u, guess, float)
    p = prepare_params(model, p, dtype, extra)
    shape = batch_shape(mech, {"u": u.shape[:-1], "guess": guess.shape[:-1], **{f"p[{k!r}]": v.shape for k, v in p.items()}})
    n = int(np.prod(shape, dtype=np.int64))
    flat = lambda x, k: jnp.broadcast_to(x, shape + x.shape[x.ndim - k:]).reshape((n,) + x.shape[x.ndim - k:])  # noqa: E731
    uf = flat(u.astype(dtype), 1)
    args = (uf, flat(jnp.asarray(direction, dtype), 1), {k: flat(v, 0) for k, v in p.items()},
            flat(jnp.asarray(t, dtype), 0), flat(guess.astype(dtype), 1))
    (up, up_moves), (back, back_moves) = _holding_batch(model, friction, options, *args)
    r = lambda x: x.reshape(shape + x.shape[1:])  # noqa: E731
    zero = r(jnp.zeros_like(uf))
    res = [_result(model, r(args[3]), r(uf), zero, zero, jax.tree_util.tree_map(r, out)) for out in (up, back)]
    # zero between the two efforts; a sense that friction jams holds whatever the effort
    up_holds = ~r(up_moves)[..., None] | (res[0].tau >= 0.0)
    back_holds = ~r(back_moves)[..., None] | (res[1].tau <= 0.0)
    assembled = jnp.all(jnp.isfinite(res[0].q), axis=-1)
    return Holding(*res, assembled & jnp.all(up_holds & back_holds, axis=-1))
