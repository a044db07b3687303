"""Joint friction: Coulomb friction and viscous damping at the joints of a ``Model``, from
the joints' own reactions.

**The laws.**  At a joint joining bodies ``(a, b)`` (``dynamics.joints``) friction acts on
``b`` (and its opposite on ``a``) against the relative motion of ``b`` with respect to ``a``:

- a ``Revolute`` pin of radius ``r``: the moment ``M_f = -mu r |F| sgn(w) - c w`` (N m, CCW
  on b), ``F`` the pin's force, ``w = omega_b - omega_a`` (rad/s) the relative rotation:
  the friction-circle relation (the force's line of action tangent to the circle of
  radius ``mu r``);
- a ``Prismatic`` slider or a ``Slot`` (straight or circular): the force ``F_f e`` at the
  joint's point with ``F_f = -mu |N| sgn(v) - c v`` (N), ``N`` the normal force, ``e`` the
  guide's (the slot's) direction and ``v`` the sliding speed of b's point over a's along
  ``e`` (m/s).  Left out: the edge forces of a long block carrying the guide's moment
  (``mu |M| / half-length`` more where the block is long), and a slot's pin turning in
  the slot (its pin friction).

``c`` is an optional viscous coefficient (N m s/rad at a pin, N s/m in a guide).

**The regularised sign.**  ``sgn(w) = tanh(w / (width * W))``: ``W`` the largest ``|w|`` of
that joint over the samples of the call (the stroke's own speed scale of the joint, so the
band is scale-aware: the same ``width`` serves a pin and a guide, a slow and a fast
stroke), ``width`` a fraction (default ``1e-3``).  Outside ``|w| > 20 width W`` the sign is
``+-1`` to round-off; a stroke reversing through ``w = 0`` shows the effort's jump
``2 mu r |F|`` within ``|w| <~ 3 width W``.  A joint that does not move in any sample has
no friction (sign 0).

**The solve.**  The reactions are linear in the loads, so with ``s`` the friction loads'
magnitudes, ``x(s) = x0 + X s`` (``x0`` the reactions without friction, ``X`` the
reactions to one unit friction load at each joint: one elimination with several
right-hand sides, ``reactions.solve_reaction_system``), and friction is the small
nonlinear system ``s = a |F(x0 + X s)| + d`` (``a = -mu r sgn``, ``d = -c w``), one
unknown per joint with friction.  It is solved per sample by Newton's method (a status per
sample: ``FrictionReactions.converged``), and ``s`` is attached to the parameters by the
implicit function theorem (``implicit.implicit_solution``): derivatives in every
parameter, no derivative through the iterations.  With every ``mu`` and ``c`` zero the
residual is zero at ``s = 0`` and no step is taken: ``x = x0 + X 0 = x0`` exactly.
Forward dynamics solves the same system with the accelerations free
(``forward_friction``: ``solve_friction_loads`` with its own ``x0`` and ``X``).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..actuators import resolve
from ..solver.implicit import implicit_solution
from ..solver.linalg import solve_small
from ..solver.status import Status
from .joints import GROUND, Prismatic, Revolute, Slot, joint_name
from .model import Model, geometry, point_of
from .reactions import joint_axes, reaction_system, solve_reaction_system, unpack_reactions
from .virtual_power import LoadedState

__all__ = ["FrictionJoint", "JointFriction", "joint_speeds", "friction_signs", "stroke_signs", "friction_speeds",
           "friction_reactions", "friction_status", "friction_parameters", "friction_joints", "friction_norms",
           "friction_terms", "unit_friction_solutions", "solve_friction_loads"]

#: Newton steps allowed per sample (a converged sample takes 2 to 5).
NEWTON_STEPS = 40
#: Convergence: every joint's residual within this many round-offs of its friction load.
TOL_EPS = 64.0


class FrictionJoint(NamedTuple):
    """One joint with friction: its name in the model (``joint_name``) and the names of its
    parameters: `mu` the friction coefficient (-), `radius` the pin's radius (m; None for a
    slider or a slot), `damping` the viscous coefficient (N m s/rad or N s/m; None: none)."""

    joint: str
    mu: str
    radius: str | None = None
    damping: str | None = None


@dataclasses.dataclass(frozen=True)
class JointFriction:
    """The joints with friction of a model (static: hashable, a compiled program's key) and
    the width of the regularised sign (a fraction of each joint's largest relative speed
    over the samples of a call; module docstring).  Values come from the parameters ``p``
    under the names each ``FrictionJoint`` gives (``parameters``)."""

    joints: tuple = ()
    width: float = 1e-3

    def __post_init__(self):
        object.__setattr__(self, "joints", tuple(FrictionJoint(*j) for j in self.joints))
        if not (isinstance(self.width, (int, float)) and 0.0 < self.width < 1.0):
            raise ValueError(f"friction width={self.width!r}: give a fraction of the joints' speed scale in (0, 1), "
                             "e.g. 1e-3")

    @property
    def parameters(self) -> tuple[str, ...]:
        """Every parameter name the friction reads, once each."""
        return tuple(dict.fromkeys(n for j in self.joints for n in (j.mu, j.radius, j.damping) if n))

    def check(self, model: Model) -> None:
        """``ValueError`` for a joint the model does not have, or a pin radius missing or
        given where there is no pin."""
        kinds = {joint_name(j): j for j in model.joints}
        for fj in self.joints:
            j = kinds.get(fj.joint)
            if not isinstance(j, (Revolute, Prismatic, Slot)):
                raise ValueError(f"friction: {fj.joint!r} is not a pin, slider or slot of the model; they are "
                                 f"{[n for n, x in kinds.items() if isinstance(x, (Revolute, Prismatic, Slot))]}")
            if isinstance(j, Revolute) != (fj.radius is not None):
                raise ValueError(f"friction at {fj.joint!r}: a pin needs its radius, a slider or slot has none "
                                 f"(got radius={fj.radius!r})")


def friction_parameters(model: Model, friction: JointFriction | None) -> tuple:
    """The parameter names joint friction adds to the model's (checked against the model)."""
    if friction is None:
        return ()
    if not isinstance(friction, JointFriction):
        raise ValueError(f"friction= takes a dynamics.friction.JointFriction (or None), got {type(friction).__name__}")
    if not model.joints:
        raise ValueError("friction= needs a model with joints= (a Linkage has them): friction acts at the joints")
    friction.check(model)
    return tuple(n for n in friction.parameters if n not in model.parameters)


def friction_joints(model: Model, fr: JointFriction):
    """The model's joint objects carrying friction, in the order of ``fr.joints``."""
    by_name = {joint_name(j): j for j in model.joints}
    return [by_name[fj.joint] for fj in fr.joints]


def friction_norms(model: Model, joints) -> tuple:
    """The columns of each joint's force in the reaction unknowns: a pin's two, a guide's one (its normal force)."""
    lay = model.layout
    return tuple(tuple(lay.columns[joint_name(j)][: 2 if isinstance(j, Revolute) else 1]) for j in joints)


def friction_terms(fr: JointFriction, p, signs, speeds, dtype):
    """``(a, d)`` of the friction loads ``s = a |F| + d`` (``a = -mu r sgn``, ``d = -c w``) at one state."""
    mu = jnp.stack([resolve(fj.mu, p) for fj in fr.joints])
    arm = jnp.stack([resolve(fj.radius, p) if fj.radius else 1.0 for fj in fr.joints])
    c = jnp.stack([resolve(fj.damping, p) if fj.damping else 0.0 for fj in fr.joints])
    return (-mu * arm * signs).astype(dtype), (-c * speeds).astype(dtype)


def _direction(model: Model, j, q, u, p):
    """The unit direction (complex) a slider's or slot's friction force acts along."""
    e, n = joint_axes(model, j, q, u, p)
    return 1j * n if e is None else e  # a circular slot: its tangent


def joint_speeds(model: Model, fr: JointFriction, q, u, p, q_dot, u_dot):
    """The relative speed ``(k,)`` of each joint with friction at one state: a pin's
    ``omega_b - omega_a`` (rad/s), a slider's or slot's sliding speed of b's point over a's
    along the friction direction (m/s)."""
    mech = model.mechanism
    (rg, ph, *_), (vg, om, *_) = jax.jvp(lambda q_, u_: geometry(model, q_, u_, p), (q, u), (q_dot, u_dot))
    index = {b.name: k for k, b in enumerate(model.bodies)}

    def point_velocity(body, at):
        if body == GROUND:
            return jnp.zeros((), at.dtype)
        k = index[body]
        return vg[k] + 1j * om[k] * (at - rg[k])

    out = []
    for j in friction_joints(model, fr):
        a, b = j.bodies
        if isinstance(j, Revolute):
            out.append((om[index[b]] if b != GROUND else 0.0) - (om[index[a]] if a != GROUND else 0.0))
            continue
        at = point_of(mech, j.point, q, u, p)
        rel = point_velocity(b, at) - point_velocity(a, at)
        out.append(jnp.real(jnp.conj(_direction(model, j, q, u, p)) * rel))
    return jnp.stack([jnp.asarray(w, q.dtype) for w in out]) if out else jnp.zeros((0,), q.dtype)


def friction_signs(fr: JointFriction, speeds, scale):
    """The regularised sign ``tanh(w / (width W))`` of each joint's relative speed `speeds`
    ``(..., k)``, ``W = scale (k,)`` the joint's speed scale (0 where it never moves)."""
    moving = scale > 0
    return jnp.where(moving, jnp.tanh(speeds / (fr.width * jnp.where(moving, scale, 1.0))), 0.0)


def speed_scale(speeds, ok=None):
    """Each joint's speed scale ``W (k,)`` over a stroke's samples: its largest finite
    ``|w|`` of `speeds` ``(N, k)``, over the samples where `ok` ``(N,)`` (all: None)."""
    keep = jnp.isfinite(speeds) if ok is None else jnp.isfinite(speeds) & ok[:, None]
    return jnp.max(jnp.where(keep, jnp.abs(speeds), 0.0), axis=0, initial=0.0)


def stroke_signs(fr: JointFriction, speeds, ok=None):
    """The regularised signs ``(N, k)`` of a stroke's joint speeds `speeds` ``(N, k)``
    (``joint_speeds`` at each sample), each joint's band set by its own speed scale over
    the stroke (``speed_scale``; `ok` ``(N,)`` the samples that count, None: all): the
    law of every stroke with friction (``inverse.inverse_dynamics``, ``holding``, a
    linkage's scene)."""
    return friction_signs(fr, speeds, speed_scale(speeds, ok))


def friction_speeds(friction, speed) -> tuple:
    """Each friction joint's speed scale ``W`` (a tuple of positive floats; ``()`` without
    friction) from `speed`: a number for every joint or one per joint of ``friction.joints``.
    ``ValueError`` for a scale missing, not positive, or given without friction."""
    if friction is None:
        if speed is not None:
            raise ValueError("friction_speed is the speed scale of joint friction's sign: give it with friction only")
        return ()
    k = len(friction.joints)
    if speed is None:
        raise ValueError("joint friction at given states (forward dynamics, inverse_dynamics_at) needs friction_speed=, "
                         "each joint's speed scale W (rad/s at a pin, m/s in a guide; e.g. the largest speed expected): "
                         "the sign tanh(w / (width W)) changes within width W of w = 0")
    w = np.broadcast_to(np.asarray(speed, float), (k,)) if np.ndim(speed) == 0 else np.asarray(speed, float)
    if w.shape != (k,) or not np.all(np.isfinite(w) & (w > 0)):
        raise ValueError(f"friction_speed must be a positive number or {k} of them (one per friction joint "
                         f"{[fj.joint for fj in friction.joints]}), got {speed!r}")
    return tuple(float(x) for x in w)


def friction_status(status, converged):
    """The samples' ``Status`` with ``MAX_STEPS`` where the position converged but the
    friction's Newton did not (`converged`: ``FrictionReactions.converged``): a linkage
    jammed by friction, which no effort drives that way."""
    stuck = (status == Status.CONVERGED) & ~converged
    return jnp.where(stuck, jnp.asarray(Status.MAX_STEPS, status.dtype), status)


def _magnitude(x, cols):
    """A pin's force magnitude ``|F|`` (its gradient 0, not NaN, where ``F = 0``) or a guide's ``|N|``."""
    if len(cols) == 1:
        return jnp.abs(x[cols[0]])
    n2 = x[cols[0]] ** 2 + x[cols[1]] ** 2
    pos = n2 > 0
    return jnp.where(pos, jnp.sqrt(jnp.where(pos, n2, 1.0)), 0.0)


def _residual(norms, s, args):
    """Friction's own equations ``s - a |F(x0 + X s)| - d`` (one per joint)."""
    a, d, x0, X = args
    x = x0 + X @ s
    return s - a * jnp.stack([_magnitude(x, cols) for cols in norms]) - d


class _NewtonCarry(NamedTuple):
    s: jax.Array
    steps: jax.Array
    done: jax.Array


def _newton(norms, args):
    """``(s, converged)``: Newton's method on ``_residual`` from ``s = 0`` (the no-friction
    reactions), each joint's residual against its own friction load's size."""
    a, d, x0, _ = args
    f = functools.partial(_residual, norms)
    eps = jnp.finfo(x0.dtype).eps

    def small(s, g):
        size = jnp.abs(s) + jnp.abs(a) * jnp.stack([_magnitude(x0, c) for c in norms]) + jnp.abs(d)
        return jnp.all(jnp.abs(g) <= TOL_EPS * eps * size)

    def step(c: _NewtonCarry) -> _NewtonCarry:
        g = f(c.s, args)
        jac = jax.jacfwd(lambda s_: f(s_, args))(c.s)
        s = c.s - solve_small(jac, g)
        return _NewtonCarry(s, c.steps + 1, small(s, f(s, args)))

    s0 = jnp.zeros_like(d)
    first = _NewtonCarry(s0, jnp.zeros((), jnp.int32), small(s0, f(s0, args)))
    last = jax.lax.while_loop(lambda c: ~c.done & (c.steps < NEWTON_STEPS), step, first)
    return last.s, last.done & jnp.all(jnp.isfinite(last.s))


def unit_friction_solutions(model: Model, sys_, st: LoadedState, joints, extra=None):
    """The reactions ``X (n, k)`` to one unit friction load at each joint (a moment of
    1 N m on a pin's second body, a force of 1 N along a guide's direction on its block,
    their opposites on the first bodies), in one elimination.  `extra` ``{row: (k,)}``:
    more right-hand side for each unit load (forward dynamics: the inertia of the
    accelerations it causes), or None."""
    mech, q, u, p = model.mechanism, st.q, st.u, st.p
    base, units = sys_.rhs, []
    for j in joints:
        sys_.rhs = {}
        a, b = j.bodies
        if isinstance(j, Revolute):
            sys_.applied(b, moment=1.0)
            sys_.applied(a, moment=-1.0)
        else:
            at, e = point_of(mech, j.point, q, u, p), _direction(model, j, q, u, p)
            sys_.applied(b, force=e, at=at)
            sys_.applied(a, force=-e, at=at)
        units.append(sys_.rhs)
    dtype = q.dtype
    sys_.rhs = {i: jnp.stack([jnp.asarray(x.get(i, 0.0), dtype) for x in units]) for i in range(model.layout.size)}
    for i, v in (extra or {}).items():
        sys_.rhs[i] = sys_.rhs[i] + v
    X = solve_reaction_system(model, sys_, st)
    sys_.rhs = base
    return X


def solve_friction_loads(norms, a, d, x0, X, ok):
    """``(s, converged, ok)``: the friction loads ``s (k,)`` solving ``s = a |F(x0 + X s)| +
    d`` (module docstring) by Newton's method from ``s = 0``, attached to ``(a, d, x0, X)``
    by the implicit function theorem (no derivative through the iterations); `norms` each
    joint's force columns in ``x`` (``friction_norms``), `ok` whether the state is valid.
    `converged`: the Newton's; `ok`: both (where False, ``s`` is 0)."""
    safe = lambda v: jnp.where(ok, v, 0.0)  # noqa: E731
    args = (a, d, safe(x0), safe(X))
    s, conv = _newton(norms, jax.lax.stop_gradient(args))
    ok = ok & conv
    s = implicit_solution(functools.partial(_residual, norms), jnp.where(ok, s, 0.0), ok, args)
    return s, conv, ok


class FrictionReactions(NamedTuple):
    """``friction_reactions``' result at one sample.

    - `efforts` ``(dof,)``: the drive efforts' change due to friction (N m or N; add it to
      the frictionless effort); `forces`, `moments`: every joint's reaction with friction
      (as ``reactions.joint_reactions``; a guide's or slot's force includes its friction
      force along it).
    - `friction` ``(k,)``: each joint's friction load on its second body: a pin's moment
      (N m, CCW), a guide's force along its direction (N).
    - `converged`: whether the friction Newton converged (False: NaN results).
    """

    efforts: jax.Array
    forces: dict
    moments: dict
    friction: jax.Array
    converged: jax.Array


def friction_reactions(model: Model, fr: JointFriction, st: LoadedState, signs, speeds) -> FrictionReactions:
    """Every joint's reaction with friction at one state (module docstring): `st` the
    sample's ``LoadedState`` (its loads; inertia where it has any), `signs` ``(k,)`` the
    regularised signs of the joints' relative motion (``friction_signs``), `speeds` ``(k,)``
    the relative speeds the viscous terms see (rad/s, m/s)."""
    joints = friction_joints(model, fr)
    sys_, geo = reaction_system(model, st)
    x0 = solve_reaction_system(model, sys_, st)  # the frictionless reactions (joint_reactions' own)
    X = unit_friction_solutions(model, sys_, st, joints)
    a, d = friction_terms(fr, st.p, signs, speeds, st.q.dtype)
    s, conv, ok = solve_friction_loads(friction_norms(model, joints), a, d, x0, X, st.ok)
    dx = X @ s
    x = jnp.where(conv, x0 + dx, jnp.nan)
    _, forces, moments = unpack_reactions(model, x, geo)
    efforts, _, _ = unpack_reactions(model, jnp.where(conv, dx, jnp.nan), geo)
    # A guide's or slot's friction is a force of its first body on its second, along it:
    # part of that joint's force (the reaction system holds it as a load), so that per body
    # the joints' forces, gravity and the loads balance m a_G.  A pin's is a moment.
    for k, j in enumerate(joints):
        if not isinstance(j, Revolute):
            name = joint_name(j)
            forces[name] = forces[name] + jnp.where(conv, s[k], jnp.nan) * _direction(model, j, st.q, st.u, st.p)
    return FrictionReactions(efforts, forces, moments, jnp.where(ok, s, jnp.nan), conv)
