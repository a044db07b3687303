"""Bodies and loads; inverse dynamics by virtual power, joint reactions, statics and
forward dynamics.

**Model.**  A ``Model`` adds to a ``Mechanism`` its rigid ``Body``s (pose functions and
mass properties; massless links are not bodies) and its loads (``PointForce``, ``Moment``,
``Gravity``, ``Axial`` two-point elements such as springs and SMA wires, ``Potential``).
Everything in a model is static structure (names, functions, parameter specs); every
number comes from the parameters ``p``, so one compiled function serves every design.

**Virtual power.**  With ``x = (q, u)`` treated as independent and the loop closure
``Phi(q, u, p) = 0`` enforced by multipliers ``lambda``:

    applied    Q = sum F . dr_P/dx + M dphi/dx - dV/dx - T dL/dx
    inertia    I = sum m a_G . dr_G/dx + J alpha dphi/dx
    balance    I - Q + Phi_x^T lambda = tau e_u .

We never form a Jacobian of the poses: ``I - Q`` is the gradient (one reverse pass) of the
scalar virtual-work function ``W(x) = sum m a_G . r_G(x) + J alpha phi(x) - F . r_P(x) -
M phi(x) + V(x) + T L(x)`` with the accelerations and loads frozen at the actual state.
The ``q`` rows give ``lambda = -Phi_q^{-T} (I - Q)_q``, the ``u`` rows
``tau = (I - Q)_u + Phi_u^T lambda``.  Accelerations come from the implicit kinematics
(nested ``jax.jvp`` through ``solve.implicit_root``), never from Newton iterates.

**Reactions.**  ``-Phi_x^T lambda`` is the generalized constraint force.  For a complex loop
written ``path_1 - path_2 = 0`` (the two ways to reach the closing joint), the pair
``(lambda_re, lambda_im)`` is the force (N, ``x + i y``) that the last body of path 1
applies to the last body of path 2 at the closing joint.  A real equation whose gradient
in the point's position has unit length (a pin on a slot ``|P - C| - R = 0``) gives its
normal force in newtons the same way.

**Statics** solves ``tau(u) = tau_applied`` (quasi-static: no inertia) for the free input
``u`` with a safeguarded Newton method and attaches the root to ``p`` by an implicit-
function custom JVP.  **Forward dynamics** integrates
``M(u) u_ddot + h(u, u_dot, t) = tau`` (``h = (1/2) M' u_dot^2 - Q`` for one input: the
inverse-dynamics torque at zero acceleration) with an implicit Runge-Kutta method (Radau
IIA by default, L-stable for the stiff motor inductance), the loop solve inside every stage.
"""

from __future__ import annotations

import dataclasses
import enum
import functools
from collections.abc import Callable, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .actuators import DCMotor, Spec, parameter_names, resolve, spec_names
from .kinematics import chain_rule, time_derivatives
from .mechanism import Mechanism, Vars, check_parameters
from ._linalg import cond1, solve_small
from .continuation import stroke
from .solve import SolverOptions, as_coords, as_inputs, implicit_root, solve, solve_one, tolerances
from .status import Status

__all__ = [
    "Body",
    "PointForce",
    "Moment",
    "Gravity",
    "Axial",
    "Potential",
    "Model",
    "DynStatus",
    "dyn_status_message",
    "generalized_forces",
    "mass_matrix",
    "kinetic_energy",
    "potential_energy",
    "InverseDynamics",
    "inverse_dynamics",
    "inverse_dynamics_at",
    "Equilibrium",
    "equilibrium",
    "Trajectory",
    "forward_dynamics",
    "METHODS",
]


# --------------------------------------------------------------------------- status
class DynStatus(enum.IntEnum):
    """Result code of a statics solve or a forward-dynamics run.

    - ``OK``: converged (statics) / integrated to the end (dynamics).
    - ``POSITION``: the loop could not be closed at some state: a singular (toggle, dead
      centre) or unassemblable position was reached.
    - ``STROKE_END``: the input left the given stroke range; the run stopped there.
    - ``NOT_CONVERGED``: a Newton iteration (statics, or an implicit step) did not converge.
    - ``NONFINITE``: a non-finite value appeared (mass matrix singular, NaN load...).
    - ``NO_EQUILIBRIUM``: statics: the generalized force does not change sign over the given
      range (no equilibrium in it, or an even number of them).
    """

    OK = 0
    POSITION = 1
    STROKE_END = 2
    NOT_CONVERGED = 3
    NONFINITE = 4
    NO_EQUILIBRIUM = 5


_DYN_MESSAGES = {
    DynStatus.OK: "ok",
    DynStatus.POSITION: "the loop could not be closed: a singular (toggle) or unassemblable position was reached",
    DynStatus.STROKE_END: "the input reached the end of the stroke range; integration stopped",
    DynStatus.NOT_CONVERGED: "Newton did not converge (statics) or an implicit step failed (reduce the step)",
    DynStatus.NONFINITE: "a non-finite value appeared (singular mass matrix, NaN load or parameter)",
    DynStatus.NO_EQUILIBRIUM: "no equilibrium in the given range: the generalized force keeps one sign there",
}


def dyn_status_message(code) -> str:
    """Readable message for a ``DynStatus`` code."""
    return _DYN_MESSAGES[DynStatus(int(code))]


# --------------------------------------------------------------------------- bodies and loads
PointSpec = str | Callable  # name of a mechanism point, or fn(q, u, p) -> complex
AngleSpec = str | Callable  # name of a coordinate or input, or fn(q, u, p) -> real


@dataclasses.dataclass(frozen=True, eq=False)
class Body:
    """A rigid body: centre of mass, orientation and mass properties.

    **Arguments**

    - `position`: centre of mass ``r_G`` (m, complex ``x + i y``): a mechanism point name or
      ``fn(q, u, p) -> complex``.
    - `mass`: ``m`` (kg), a spec (parameter name, number or ``fn(p)``).
    - `angle`: body angle ``phi`` (rad, CCW): a coordinate/input name or ``fn(q, u, p)``;
      ``None`` for a point mass.
    - `inertia`: ``J`` about the centre of mass (kg m^2), a spec; needs an `angle`.
    - `name`: for messages.
    """

    position: PointSpec
    mass: Spec
    angle: AngleSpec | None = None
    inertia: Spec = 0.0
    name: str = "body"


@dataclasses.dataclass(frozen=True, eq=False)
class PointForce:
    """A force ``F`` (N, complex ``Fx + i Fy``) applied at a point.

    - `point`: mechanism point name or ``fn(q, u, p) -> complex`` (m).
    - `force`: ``fn(q, u, p, v, t) -> complex``; ``v`` holds the velocities of every
      coordinate and input by name (``v.theta2`` in rad/s), ``t`` the time (s).
      Example, lift normal to a chord at angle ``-delta``:
      ``lambda q, u, p, v, t: p.qS_Cl * q.delta * 1j * cis(-q.delta)``.
    """

    point: PointSpec
    force: Callable
    name: str = "force"


@dataclasses.dataclass(frozen=True, eq=False)
class Moment:
    """A pure moment ``M`` (N m, positive in the sense of increasing `angle`).

    - `angle`: the angle it works on: a body angle ``fn(q, u, p)``, or the name of a
      coordinate or input, which makes ``M`` a generalized force on that coordinate (the
      power term ``M * coord_dot``, e.g. an aerodynamic hinge moment ``M_AC * delta_dot``).
    - `moment`: ``fn(q, u, p, v, t) -> real``.
    """

    angle: AngleSpec
    moment: Callable
    name: str = "moment"


@dataclasses.dataclass(frozen=True, eq=False)
class Gravity:
    """Uniform gravity on every body: force ``m g direction`` at its centre of mass.

    - `g`: spec (m/s^2), default the parameter ``"g"``.
    - `direction`: unit complex direction, default ``-1j`` (down).
    """

    g: Spec = "g"
    direction: complex = -1j
    name: str = "gravity"


@dataclasses.dataclass(frozen=True, eq=False)
class Axial:
    """A two-point element (spring, SMA wire, cylinder, damper) between points `a` and `b`.

    - `a`, `b`: point names or ``fn(q, u, p)``.
    - `law`: ``law(length, rate, p, t) -> tension`` (N, positive pulls the ends together);
      every ``jaxmech.actuators`` axial law (``LinearSpring``, ``SMAWire``,
      ``HydraulicCylinder``) is one.  Its virtual power is ``-T dL``.
    """

    a: PointSpec
    b: PointSpec
    law: Callable
    name: str = "axial"


@dataclasses.dataclass(frozen=True, eq=False)
class Potential:
    """A potential energy ``V`` (J): ``energy(q, u, p, t) -> real``; its force is ``-dV/dx``."""

    energy: Callable
    name: str = "potential"


_LOADS = (PointForce, Moment, Gravity, Axial, Potential)


@dataclasses.dataclass(frozen=True, eq=False)
class Model:
    """A mechanism with bodies and loads (static; hashable by identity for jit).

    **Arguments**

    - `mechanism`: the ``Mechanism``.
    - `bodies`: sequence of ``Body``.
    - `loads`: sequence of ``PointForce``, ``Moment``, ``Gravity``, ``Axial``, ``Potential``.
    - `params`: the model's own parameters: masses, inertias, load coefficients, anything
      no constraint uses.  They are not the mechanism's: the mechanism declares only what
      its constraints and points need.  Bodies and loads may use the mechanism's
      parameters too (a chord length), by name.
    - `actuators`: actuators the model is driven or loaded with (a ``DCMotor``); each
      declares the parameters its specs name (``actuators.parameter_names``), as does
      every actuator used as an ``Axial`` law.

    A model's parameters (``parameters``) are the mechanism's, then its own, then its
    actuators', merged by name: one ``p`` mapping carries them all, and each function
    takes from it what it uses.

    **Raises** ``ValueError`` for an unknown point, coordinate or parameter name, a body
    with inertia but no angle, or a clash: a parameter declared both by the mechanism and
    in `params`, or a parameter named like a coordinate or input.
    """

    mechanism: Mechanism
    bodies: Sequence[Body] = ()
    loads: Sequence = ()
    params: Sequence[str] = ()
    actuators: Sequence = ()

    def __post_init__(self):
        object.__setattr__(self, "bodies", tuple(self.bodies))
        object.__setattr__(self, "loads", tuple(self.loads))
        object.__setattr__(self, "params", (self.params,) if isinstance(self.params, str) else tuple(self.params))
        object.__setattr__(self, "actuators", tuple(self.actuators))
        mech = self.mechanism
        names = mech.coords + mech.inputs
        for n in self.params:
            if not isinstance(n, str) or not n.isidentifier():
                raise ValueError(f"params: {n!r} is not a valid name (use Python identifiers)")
            if n in mech.params:
                raise ValueError(f"params: {n!r} is declared by both the mechanism {mech.name!r} and the model; "
                                 f"declare it once (the model uses the mechanism's parameters by name)")
        if len(set(self.params)) != len(self.params):
            raise ValueError(f"params: duplicate names in {self.params}")
        for n in self.parameters:
            if n in names:
                raise ValueError(f"parameter {n!r} has the name of a coordinate or input of {mech.name!r}; rename it")
        known = self.parameters

        def check_point(spec, what):
            if isinstance(spec, str) and spec not in mech.points:
                raise ValueError(f"{what}: unknown point {spec!r}; {mech.name} defines points {list(mech.points)}")
            if not isinstance(spec, str) and not callable(spec):
                raise ValueError(f"{what}: a point is a point name or fn(q, u, p) -> complex")

        def check_angle(spec, what):
            if isinstance(spec, str) and spec not in names:
                raise ValueError(f"{what}: unknown coordinate or input {spec!r}; known: {list(names)}")

        def check_spec(spec, what):
            if isinstance(spec, str) and spec not in known:
                raise ValueError(f"{what}: unknown parameter {spec!r}; the model's parameters are {list(known)} "
                                 f"(declare a model parameter in Model(params=...))")

        for b in self.bodies:
            if not isinstance(b, Body):
                raise ValueError(f"bodies: expected Body, got {type(b).__name__}")
            check_point(b.position, f"body {b.name!r}")
            check_spec(b.mass, f"body {b.name!r} mass")
            check_spec(b.inertia, f"body {b.name!r} inertia")
            if b.angle is None and not (isinstance(b.inertia, (int, float)) and b.inertia == 0):
                raise ValueError(f"body {b.name!r}: an inertia needs an angle (give angle=...)")
            if b.angle is not None:
                check_angle(b.angle, f"body {b.name!r}")
        for ld in self.loads:
            if not isinstance(ld, _LOADS):
                raise ValueError(f"loads: expected one of {[c.__name__ for c in _LOADS]}, got {type(ld).__name__}")
            if isinstance(ld, PointForce):
                check_point(ld.point, f"load {ld.name!r}")
            elif isinstance(ld, Moment):
                check_angle(ld.angle, f"load {ld.name!r}")
            elif isinstance(ld, Axial):
                check_point(ld.a, f"load {ld.name!r}")
                check_point(ld.b, f"load {ld.name!r}")
            elif isinstance(ld, Gravity):
                check_spec(ld.g, f"load {ld.name!r}")

    @property
    def parameters(self) -> tuple[str, ...]:
        """Every parameter name of the model: the mechanism's, its own (`params`), then those
        its actuators and actuator laws declare, once each."""
        laws = [ld.law for ld in self.loads if isinstance(ld, Axial)]
        acts = [n for a in (*self.actuators, *laws) for n in parameter_names(a)]
        return tuple(dict.fromkeys(self.mechanism.params + self.params + tuple(acts)))

    def check_params(self, p: Mapping, extra: Sequence[str] = ()) -> None:
        """Eager checks of a parameter mapping against ``parameters`` (and the `extra` names
        a call adds: a motor's, a voltage's); raises ``ValueError`` naming the parameter.

        Names: none missing, none unknown.  Values where concrete: finite, and the
        mechanism's own checks (positive lengths) on its parameters.
        """
        mech = self.mechanism
        names = tuple(dict.fromkeys(self.parameters + tuple(extra)))
        check_parameters(mech.name, p, names, mech.lengths, mech.signed, whose="this model's")


# --------------------------------------------------------------------------- evaluation helpers
def _point(mech: Mechanism, spec, q, u, p):
    if isinstance(spec, str):
        return mech.point(spec, q, u, p)
    return jnp.asarray(spec(mech.vars_q(q), mech.vars_u(u), mech.vars_p(p)))


def _angle(mech: Mechanism, spec, q, u, p):
    if isinstance(spec, str):
        if spec in mech.coords:
            return q[mech.coords.index(spec)]
        return u[mech.inputs.index(spec)]
    return jnp.asarray(spec(mech.vars_q(q), mech.vars_u(u), mech.vars_p(p)))


def _dot(a, b):
    """Real dot product of two planar vectors given as complex numbers."""
    return jnp.real(jnp.conj(a) * b)


def _geometry(model: Model, q, u, p):
    """Every pose the loads and inertia need, as a flat tuple of arrays (for nested jvp)."""
    mech = model.mechanism
    rg = [_point(mech, b.position, q, u, p) for b in model.bodies]
    ph = [_angle(mech, b.angle, q, u, p) if b.angle is not None else jnp.zeros((), q.dtype) for b in model.bodies]
    lp, la, ll = [], [], []
    for ld in model.loads:
        if isinstance(ld, PointForce):
            lp.append(_point(mech, ld.point, q, u, p))
        elif isinstance(ld, Moment):
            la.append(_angle(mech, ld.angle, q, u, p))
        elif isinstance(ld, Axial):
            ll.append(jnp.abs(_point(mech, ld.a, q, u, p) - _point(mech, ld.b, q, u, p)))
    return rg, ph, lp, la, ll


def _masses(model: Model, p):
    return [resolve(b.mass, p) for b in model.bodies], [resolve(b.inertia, p) for b in model.bodies]


def _safe(model: Model, q, u, p):
    """Inputs made harmless where the position is not finite (results are masked later)."""
    ok = jnp.all(jnp.isfinite(q))
    return ok, jnp.where(ok, q, jnp.zeros_like(q))


def _path(model: Model, q, ok, u, ud, udd, p, qd=None, qdd=None):
    """``s -> (q(s), u(s))`` along ``u(s) = u + ud s + udd s^2/2``, differentiable via the
    implicit function theorem: its first and second ``s``-derivatives at 0 are the actual
    velocities and accelerations.  With the coordinates' own ``qd`` and ``qdd`` known (a
    stroke's chain rule gives them) the path is ``q + qd s + qdd s^2/2``: the same first
    and second derivatives, without differentiating the implicit root twice again."""
    mech = model.mechanism

    if qd is not None:
        qd = jnp.where(ok, qd, 0.0)
        qdd = jnp.where(ok, qdd, 0.0)

        def path(s):
            return q + qd * s + 0.5 * qdd * s * s, u + ud * s + 0.5 * udd * s * s

        return path

    def path(s):
        us = u + ud * s + 0.5 * udd * s * s
        return implicit_root(mech, q, ok, us, p), us

    return path


def generalized_forces(model: Model, q, u, u_dot, u_ddot, p, t=0.0, *, inertia: bool = True, q_dot=None, q_ddot=None):
    """Driving generalized forces and constraint multipliers at one solved state.

    **Arguments**

    - `q`: solved coordinates ``(m,)`` (NaN gives NaN results); `u`, `u_dot`, `u_ddot`:
      input position, velocity, acceleration ``(dof,)``; `p`: parameter mapping; `t`: s.
    - `inertia`: False for the quasi-static balance (inertia left out; velocity-dependent
      loads still see `u_dot`).
    - `q_dot`, `q_ddot`: the coordinates' velocities and accelerations ``(m,)`` when known
      (``motion`` and ``stroke_kinematics`` give them); otherwise they are taken from ``q``
      by the implicit function theorem.  Either way the results are differentiable in
      every parameter.

    **Returns** ``(tau (dof,), lam (m,))``: `tau` the force/torque (N or N m) that the
    drive must apply *on* each input (positive in the input's positive sense) to produce
    the motion; `lam` the multipliers (N for complex loops in metres; see the module
    docstring for the sign).
    """
    mech = model.mechanism
    p = dict(p)
    ok, q = _safe(model, q, u, p)
    dtype = q.dtype
    path = _path(model, q, ok, u, u_dot, u_ddot, p, q_dot, q_ddot)
    pv = Vars(p)
    geo = lambda s: _geometry(model, *path(s), p)  # noqa: E731
    if inertia:
        g0, gd, gdd = time_derivatives(geo, jnp.zeros((), dtype))
    else:  # quasi-static: no accelerations, so no second derivatives to trace
        g0, gd = jax.jvp(geo, (jnp.zeros((), dtype),), (jnp.ones((), dtype),))
        gdd = (None, None)
    _, (qd_, ud_) = jax.jvp(path, (jnp.zeros((), dtype),), (jnp.ones((), dtype),))
    vel = Vars({**{n: qd_[i] for i, n in enumerate(mech.coords)}, **{n: ud_[i] for i, n in enumerate(mech.inputs)}})
    qv, uv = mech.vars_q(q), mech.vars_u(u)
    m_, J_ = _masses(model, p)
    a_g, alpha = gdd[0], gdd[1]

    # Loads frozen at the actual state (constants of the virtual-work function).
    forces, moments, tensions, grav = [], [], [], []
    lengths, rates = g0[4], gd[4]
    k_ax = 0
    for ld in model.loads:
        if isinstance(ld, PointForce):
            forces.append(jnp.asarray(ld.force(qv, uv, pv, vel, t)))
        elif isinstance(ld, Moment):
            moments.append(jnp.asarray(ld.moment(qv, uv, pv, vel, t)))
        elif isinstance(ld, Axial):
            tensions.append(jnp.asarray(ld.law(lengths[k_ax], rates[k_ax], pv, t)))
            k_ax += 1
        elif isinstance(ld, Gravity):
            grav.append(resolve(ld.g, p) * ld.direction)
    potentials = [ld for ld in model.loads if isinstance(ld, Potential)]

    def work(x):
        # W(x): grad W = I - Q at the frozen accelerations and loads (virtual power).
        qx, ux = x[: mech.m], x[mech.m :]
        rg, ph, lp, la, ll = _geometry(model, qx, ux, p)
        w = jnp.zeros((), dtype)
        for k in range(len(model.bodies)):
            if inertia:
                w = w + m_[k] * _dot(a_g[k], rg[k]) + J_[k] * alpha[k] * ph[k]
            for gv in grav:
                w = w - m_[k] * _dot(gv, rg[k])
        for F, r in zip(forces, lp):
            w = w - _dot(F, r)
        for M, a in zip(moments, la):
            w = w - M * a
        for T, L in zip(tensions, ll):
            w = w + T * L
        for ld in potentials:
            w = w + ld.energy(mech.vars_q(qx), mech.vars_u(ux), pv, t)
        return w

    g = jax.grad(work)(jnp.concatenate([q, u]))
    jq, ju = jax.jacfwd(mech.residual, (0, 1))(q, u, p)
    jq = jnp.where(ok, jq, jnp.eye(mech.m, dtype=dtype))
    lam = -solve_small(jq.T, g[: mech.m])
    tau = g[mech.m :] + ju.T @ lam
    nan = lambda x: jnp.where(ok, x, jnp.nan)  # noqa: E731
    return nan(tau), nan(lam)


def mass_matrix(model: Model, q, u, p):
    """Generalized mass matrix in the inputs, ``(dof, dof)`` (kg, kg m, kg m^2):
    ``M = sum m (dr_G/du)^T (dr_G/du) + J (dphi/du)^T (dphi/du)``, with ``dq/du`` implicit."""
    mech = model.mechanism
    p = dict(p)
    ok, q = _safe(model, q, u, p)

    def poses(u_):
        qs = implicit_root(mech, q, ok, u_, p)
        rg, ph, *_ = _geometry(model, qs, u_, p)
        return jnp.stack(rg) if rg else jnp.zeros((0,), complex), jnp.stack(ph) if ph else jnp.zeros((0,))

    jr, jp = jax.jacfwd(poses)(u)  # (nb, dof) complex, (nb, dof)
    m_, J_ = _masses(model, p)
    M = jnp.zeros((mech.dof, mech.dof), q.dtype)
    for k in range(len(model.bodies)):
        M = M + m_[k] * jnp.real(jnp.conj(jr[k])[:, None] * jr[k][None, :]) + J_[k] * jnp.outer(jp[k], jp[k])
    return jnp.where(ok, M, jnp.nan)


def kinetic_energy(model: Model, q, u, u_dot, p):
    """``T = sum m |v_G|^2 / 2 + J omega^2 / 2`` (J) at one solved state."""
    mech = model.mechanism
    p = dict(p)
    ok, q = _safe(model, q, u, p)
    z = jnp.zeros_like(u_dot)
    path = _path(model, q, ok, u, u_dot, z, p)
    _, (vg, om, *_) = jax.jvp(lambda s: _geometry(model, *path(s), p), (jnp.zeros((), q.dtype),), (jnp.ones((), q.dtype),))
    m_, J_ = _masses(model, p)
    T = sum(0.5 * m_[k] * jnp.abs(vg[k]) ** 2 + 0.5 * J_[k] * om[k] ** 2 for k in range(len(model.bodies)))
    return jnp.where(ok, jnp.asarray(T, q.dtype), jnp.nan)


def potential_energy(model: Model, q, u, p, t=0.0):
    """Gravity and ``Potential`` loads' energy (J) at one state (``Axial`` laws excluded:
    a general law has no energy; use ``Potential`` for a spring you want counted)."""
    mech = model.mechanism
    rg, *_ = _geometry(model, q, u, p)
    m_, _ = _masses(model, p)
    V = jnp.zeros((), q.dtype)
    for ld in model.loads:
        if isinstance(ld, Gravity):
            gv = resolve(ld.g, p) * ld.direction
            V = V - sum(m_[k] * _dot(gv, rg[k]) for k in range(len(model.bodies)))
        elif isinstance(ld, Potential):
            V = V + ld.energy(mech.vars_q(q), mech.vars_u(u), Vars(dict(p)), t)
    return V


# --------------------------------------------------------------------------- inverse dynamics
@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class InverseDynamics:
    """Inverse-dynamics result (a pytree; leading axes = samples).

    - `t` (s), `u`, `u_dot`, `u_ddot` ``(..., dof)``, `q` ``(..., m)``.
    - `tau`: driving force/torque on each input ``(..., dof)`` (N or N m).
    - `reactions`: constraint multipliers ``(..., m)`` (N for loops in metres; sign in the
      module docstring); `reaction(i)` pairs loop ``i``'s two rows as ``x + i y``.
    - `status`: position-solve ``Status`` per sample (NaN results where not CONVERGED).
    """

    t: jax.Array
    u: jax.Array
    u_dot: jax.Array
    u_ddot: jax.Array
    q: jax.Array
    tau: jax.Array
    reactions: jax.Array
    status: jax.Array

    def reaction(self, row: int):
        """Multipliers of rows ``row`` and ``row + 1`` (a complex loop) as ``Fx + i Fy`` (N)."""
        return jax.lax.complex(self.reactions[..., row], self.reactions[..., row + 1])


def _id_one(model, quasi_static, u, ud, udd, p, t, guess, options):
    sol = solve_one(model.mechanism, u, p, guess, options)
    tau, lam = generalized_forces(model, sol.q, u, ud, udd, p, t, inertia=not quasi_static)
    return sol.q, tau, lam, sol.status


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def _id_batch(model, quasi_static, options, u, ud, udd, p, t, guess):
    return jax.vmap(lambda *a: _id_one(model, quasi_static, *a, options))(u, ud, udd, p, t, guess)


def _prep_p(model: Model, p, dtype, extra: Sequence[str] = ()):
    """Checked parameters as arrays of ``dtype``: the model's and the call's `extra` names."""
    model.check_params(p, extra)
    return {k: jnp.asarray(p[k], dtype) for k in dict.fromkeys(model.parameters + tuple(extra))}


def _mechanism_params(model: Model, p):
    """The mechanism's share of a checked model parameter mapping (for its position solves)."""
    return {k: p[k] for k in model.mechanism.params}


def inverse_dynamics_at(model: Model, u, u_dot, u_ddot, p: Mapping, guess, *, t=0.0, quasi_static: bool = False,
                        options: SolverOptions = SolverOptions()) -> InverseDynamics:
    """Driving forces and reactions at a batch of independent states (jit, vmapped).

    **Arguments**: `u`, `u_dot`, `u_ddot`: ``(..., dof)`` (or the bare batch for one input);
    `p`: parameters (arrays broadcast against the batch); `guess`: ``(..., m)`` coordinates
    near each solution (it picks the branch); `t`: time(s) for time-dependent loads;
    `quasi_static`: leave inertia out.

    **Returns** an ``InverseDynamics`` with the broadcast batch shape in front.
    """
    mech = model.mechanism
    u = as_inputs(mech, u)
    ud = as_inputs(mech, u_dot, "u_dot")
    udd = as_inputs(mech, u_ddot, "u_ddot")
    guess = as_coords(mech, guess)
    dtype = jnp.result_type(u, ud, udd, guess, float)
    p = _prep_p(model, p, dtype)
    t = jnp.asarray(t, dtype)
    shape = np.broadcast_shapes(u.shape[:-1], ud.shape[:-1], udd.shape[:-1], guess.shape[:-1], t.shape,
                                *[v.shape for v in p.values()])
    n = int(np.prod(shape, dtype=np.int64))
    flat = lambda x, k: jnp.broadcast_to(x, shape + x.shape[x.ndim - k:]).reshape((n,) + x.shape[x.ndim - k:])  # noqa: E731
    args = [flat(x.astype(dtype), 1) for x in (u, ud, udd)]
    pf = {k: flat(v, 0) for k, v in p.items()}
    q, tau, lam, status = _id_batch(model, bool(quasi_static), options, *args, pf, flat(t, 0), flat(guess.astype(dtype), 1))
    r = lambda x: x.reshape(shape + x.shape[1:])  # noqa: E731
    return InverseDynamics(t=jnp.broadcast_to(t, shape), u=r(args[0]), u_dot=r(args[1]), u_ddot=r(args[2]), q=r(q),
                           tau=r(tau), reactions=r(lam), status=r(status))


def _id_drive_one(model, quasi_static, drive, p, t_, q_, d1, d2):
    u, ud, udd = time_derivatives(lambda s: jnp.reshape(drive(s), (model.mechanism.dof,)), t_)
    qd, qdd = chain_rule(d1, d2, ud, udd)
    tau, lam = generalized_forces(model, q_, u, ud, udd, p, t_, inertia=not quasi_static, q_dot=qd, q_ddot=qdd)
    return u, ud, udd, tau, lam


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def _id_drive_leaves(model, quasi_static, drive_def, drive_leaves, p, t, q, d1, d2):
    drive = jax.tree_util.tree_unflatten(drive_def, drive_leaves)
    return jax.vmap(lambda *a: _id_drive_one(model, quasi_static, drive, p, *a))(t, q, d1, d2)


@functools.partial(jax.jit, static_argnums=(0, 1, 2))
def _id_drive_static(model, quasi_static, drive, p, t, q, d1, d2):
    return jax.vmap(lambda *a: _id_drive_one(model, quasi_static, drive, p, *a))(t, q, d1, d2)


def inverse_dynamics(model: Model, drive, t, p: Mapping, guess, *, quasi_static: bool = False,
                     options: SolverOptions = SolverOptions(), anchors: int | None = None) -> InverseDynamics:
    """Driving force/torque and reactions along a drive law ``u(t)`` (one design).

    **Arguments**

    - `drive`: ``u(t)``, a pytree drive law (``ConstantSpeed``, ``SmoothStart``...) or any
      differentiable function, scalar for one input or ``(dof,)``.
    - `t`: ``(N,)`` times (s) in order; positions are solved by continuation along them.
    - `p`: parameters; `guess`: coordinates at ``t[0]`` (picks the branch).
    - `quasi_static`: leave inertia out.

    **Returns** an ``InverseDynamics`` with leading axis ``N``; NaN where the position
    status is not ``CONVERGED``.

    Power balance (a check the tests make): ``tau . u_dot = dT/dt - Pi_loads``.
    """
    t = jnp.asarray(t)
    if t.ndim != 1:
        raise ValueError(f"t must be a 1-D array of times, got shape {t.shape}")
    us = jax.vmap(drive)(t)
    model.check_params(p)
    # positions, dq/du and d2q/du2 in one compiled pass; the drive's chain rule gives the rates
    sol, d1, d2 = stroke(model.mechanism, us, _mechanism_params(model, p), guess, options, derivs=True, anchors=anchors)
    dtype = sol.q.dtype
    pj = _prep_p(model, p, dtype)
    tt = t.astype(dtype)
    leaves, treedef = jax.tree_util.tree_flatten(drive)
    # A pytree drive is traced (one compile for every speed); a plain function is static.
    if leaves and all(hasattr(x, "dtype") or isinstance(x, (int, float)) for x in leaves):
        res = _id_drive_leaves(model, bool(quasi_static), treedef, [jnp.asarray(x, dtype) for x in leaves], pj, tt, sol.q, d1, d2)
    else:
        res = _id_drive_static(model, bool(quasi_static), drive, pj, tt, sol.q, d1, d2)
    u, ud, udd, tau, lam = res
    return InverseDynamics(t=t, u=u, u_dot=ud, u_ddot=udd, q=sol.q, tau=tau, reactions=lam, status=sol.status)


# --------------------------------------------------------------------------- statics
@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Equilibrium:
    """Static equilibrium (a pytree; leading axes = designs).

    - `u`: equilibrium inputs ``(..., dof)``, differentiable in every parameter (implicit
      function theorem); NaN where the status is not ``OK``.
    - `q`: coordinates there ``(..., m)``.
    - `stiffness`: ``d(tau - tau_applied)/du`` at the equilibrium ``(..., dof, dof)``
      (N m/rad or N/m); positive (definite) means stable.
    - `status`: ``DynStatus`` per design; `steps`: Newton iterations.
    """

    u: jax.Array
    q: jax.Array
    stiffness: jax.Array
    status: jax.Array
    steps: jax.Array

    @property
    def stable(self):
        """True where the stiffness is positive definite."""
        if self.stiffness.shape[-1] == 1:
            return self.stiffness[..., 0, 0] > 0
        return jnp.all(jnp.linalg.eigvalsh(0.5 * (self.stiffness + jnp.swapaxes(self.stiffness, -1, -2))) > 0, axis=-1)


def _static_residual(model: Model, applied, q_star, ok, u, p, t):
    """``R(u, p) = tau_quasi_static(u, p) - tau_applied(p)`` with ``q = q*(u, p)`` implicit."""
    q = implicit_root(model.mechanism, q_star, ok, u, p)
    tau, _ = generalized_forces(model, q, u, jnp.zeros_like(u), jnp.zeros_like(u), p, t, inertia=False)
    return tau - jnp.broadcast_to(jnp.asarray(resolve(applied, p), tau.dtype), tau.shape)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1))
def _attach_equilibrium(model, applied, u_star, q_star, ok, p, t):
    """Identity on ``u*``; tangent ``du = -R_u^{-1} (R_p dp + R_t dt)`` (implicit function
    theorem on ``R(u*(p), p) = 0``), zero where the solve failed."""
    return u_star


@_attach_equilibrium.defjvp
def _attach_equilibrium_jvp(model, applied, primals, tangents):
    u_star, q_star, ok, p, t = primals
    _, _, _, dp, dt = tangents
    u = _attach_equilibrium(model, applied, u_star, q_star, ok, p, t)
    # Evaluate the rule at a harmless point where the solve failed (0 * NaN leaks in reverse mode).
    u_s = jnp.where(ok, u, jnp.zeros_like(u))
    q_s = jnp.where(ok, q_star, jnp.zeros_like(q_star))
    p_s = jax.tree_util.tree_map(lambda x: jnp.where(ok, x, jnp.ones_like(x)), p)
    dp = jax.tree_util.tree_map(lambda x: jnp.where(ok, x, jnp.zeros_like(x)), dp)
    dt = jnp.where(ok, dt, jnp.zeros_like(dt))
    res = lambda u_, p_, t_: _static_residual(model, applied, q_s, ok, u_, p_, t_)  # noqa: E731
    _, rhs = jax.jvp(lambda p_, t_: res(u_s, p_, t_), (p_s, t), (dp, dt))
    ju = jax.jacfwd(res)(u_s, p_s, t)
    ju = jnp.where(ok, ju, jnp.eye(u.shape[0], dtype=ju.dtype))
    du = -solve_small(ju, rhs)
    return u, jnp.where(ok, du, jnp.zeros_like(du))


def _equilibrium_one(model: Model, applied, options: SolverOptions, max_steps: int, lo, hi, u0, guess, p, t):
    mech = model.mechanism
    stop = jax.lax.stop_gradient
    ps, ts = jax.tree_util.tree_map(stop, p), stop(t)
    dtype = guess.dtype
    eps = float(jnp.finfo(dtype).eps)
    xtol = eps ** 0.75  # Newton is quadratic: one more step after this leaves ~eps

    def evaluate(u, qg):
        sol = solve_one(mech, u, ps, qg, options)
        ok = sol.status == Status.CONVERGED
        f = lambda u_: _static_residual(model, applied, sol.q, ok, u_, ps, ts)  # noqa: E731
        r, j = jax.jvp(f, (u,), (jnp.ones_like(u),)) if mech.dof == 1 else (f(u), None)
        j = j[:, None] if mech.dof == 1 else jax.jacfwd(f)(u)
        return sol.q, r, j, ok

    bracket = mech.dof == 1
    batch_eval = jax.vmap(evaluate, in_axes=(0, None))

    # One copy of the (costly to compile) residual: iteration 0 evaluates the start and both
    # ends of the range as a batch of three; later iterations evaluate their one new point.
    # state: k, u, q, r, j, a, b, step, ok, done, r_lo, has_root
    def cond_fn(st):
        k, *_, done, _r_lo, _has = st
        return (~done) & (k < max_steps + 1)

    def body(st):
        k, u, q, r, j, a, b, step, ok, done, r_lo, has_root = st
        first = k == 0
        newton = u - solve_small(j, r)
        if bracket:
            # Safeguarded Newton (rtsafe): keep a sign-change bracket, bisect when Newton leaves it.
            inside = jnp.all(jnp.isfinite(newton)) & (newton[0] > a[0]) & (newton[0] < b[0])
            cand = jnp.where(inside, newton, 0.5 * (a + b))
        else:
            cand = jnp.clip(jnp.where(jnp.all(jnp.isfinite(newton)), newton, u), lo, hi)
        un = jnp.where(first, u0, cand)
        pts = jnp.where(first, jnp.stack([u0, lo, hi]), jnp.stack([un, un, un]))
        qs, rs, js, oks = batch_eval(pts, q)
        qn, rn, jn, okn = qs[0], rs[0], js[0], oks[0]
        if bracket:
            change = jnp.sign(rs[1, 0]) != jnp.sign(rs[2, 0])
            root0 = (oks[1] & oks[2] & change) | (rs[1, 0] == 0) | (rs[2, 0] == 0)
            has_root = jnp.where(first, root0, has_root)
            r_lo = jnp.where(first, rs[1], r_lo)
            same = jnp.sign(rn[0]) == jnp.sign(r_lo[0])
            a = jnp.where(first, lo, jnp.where(same, un, a))
            b = jnp.where(first, hi, jnp.where(same, b, un))
        step = jnp.where(first, jnp.inf, jnp.max(jnp.abs(un - u)))
        scale = 1.0 + jnp.max(jnp.abs(un))
        done = (step <= xtol * scale) | jnp.all(rn == 0) | ~okn | ~jnp.all(jnp.isfinite(rn)) | ~has_root
        if bracket:
            done = done | (b[0] - a[0] <= eps * scale)
        return k + 1, un, qn, rn, jn, a, b, step, okn, done, r_lo, has_root

    zero_r = jnp.zeros((mech.dof,), dtype)
    init = (0, u0, guess, zero_r, jnp.eye(mech.dof, dtype=dtype), lo, hi, jnp.asarray(jnp.inf, dtype),
            jnp.asarray(False), jnp.asarray(False), zero_r, jnp.asarray(True))
    k, u, q, r, j, a, b, step, ok, done, r_lo, has_root = jax.lax.while_loop(cond_fn, body, init)
    k = k - 1  # iteration 0 only evaluated the start and the ends
    # The last Newton step is cheap and takes the error from ~step^2 to round-off.
    last = u - solve_small(j, r)
    scale = 1.0 + jnp.max(jnp.abs(u))
    conv = ok & jnp.all(jnp.isfinite(r)) & ((step <= xtol * scale) | jnp.all(r == 0))
    if bracket:
        conv = conv | (ok & (b[0] - a[0] <= eps * scale))
        last = jnp.where((last[0] >= a[0]) & (last[0] <= b[0]), last, u)
    else:
        in_box = jnp.all((u > lo) & (u < hi))
    u = jnp.where(conv & jnp.all(jnp.isfinite(last)), last, u)
    status = jnp.where(
        ~has_root, DynStatus.NO_EQUILIBRIUM,
        jnp.where(~ok, DynStatus.POSITION, jnp.where(conv, DynStatus.OK, DynStatus.NOT_CONVERGED)))
    if not bracket:
        status = jnp.where((status == DynStatus.NOT_CONVERGED) & ~in_box, DynStatus.NO_EQUILIBRIUM, status)
    good = status == DynStatus.OK
    u_star = jnp.where(good, stop(u), jnp.nan)
    u_eq = _attach_equilibrium(model, applied, u_star, jnp.where(good, q, jnp.nan), good, p, t)
    # Close the loop at the final input (a few Newton steps from the last iterate's q, which is
    # within one quadratically small step) and attach it to (u_eq, p).
    q_eq, q_ok = _close(mech, u_eq, p, jnp.where(good, q, guess), 3)
    good = good & q_ok
    status = jnp.where((status == DynStatus.OK) & ~q_ok, DynStatus.POSITION, status)
    # The stiffness is the last iterate's Jacobian (one Newton step away: a diagnostic).
    return u_eq, q_eq, jnp.where(good, j, jnp.nan), status.astype(jnp.int32), k


@functools.partial(jax.jit, static_argnums=(0, 1, 2, 3))
def _equilibrium_batch(model, applied, options, max_steps, lo, hi, u0, guess, p, t):
    return jax.vmap(lambda *a: _equilibrium_one(model, applied, options, max_steps, *a))(lo, hi, u0, guess, p, t)


def equilibrium(model: Model, p: Mapping, bounds, guess, *, u0=None, applied: Spec = 0.0, t=0.0,
                options: SolverOptions = SolverOptions(), max_steps: int = 60) -> Equilibrium:
    """Static equilibrium of a force-driven scene: ``tau(u) = tau_applied`` for the inputs.

    ``tau(u)`` is the quasi-static generalized force the loads and gravity need at the input
    (``generalized_forces(..., inertia=False)``); a free hinge has ``tau_applied = 0``.  One
    input: safeguarded Newton inside the sign-change bracket ``bounds`` (always converges when
    the range holds a sign change).  Several inputs: Newton clipped to the box ``bounds``.

    **Arguments**

    - `p`: parameters (arrays broadcast: a batch of designs).
    - `bounds`: ``(lo, hi)`` input range, each ``(dof,)`` or scalar for one input.
    - `guess`: coordinates ``(m,)`` near the solution (picks the branch over the range).
    - `u0`: starting input (default the middle of the range).
    - `applied`: spec of the generalized force an actuator applies at the input (N m or N).
    - `t`: time for time-dependent loads (s).

    **Returns** an ``Equilibrium``; ``status`` ``NO_EQUILIBRIUM`` when the residual keeps one
    sign over the range (one input) or Newton leaves the box (several).  ``u`` and ``q`` are
    differentiable in ``p`` (implicit function theorem, forward and reverse mode).
    """
    mech = model.mechanism
    lo, hi = (as_inputs(mech, jnp.asarray(b), "bounds") for b in bounds)
    guess = as_coords(mech, guess)
    dtype = jnp.result_type(lo, hi, guess, float)
    pj = _prep_p(model, p, dtype, spec_names(applied))
    u0 = 0.5 * (lo + hi) if u0 is None else as_inputs(mech, jnp.asarray(u0), "u0")
    t = jnp.asarray(t, dtype)
    shape = np.broadcast_shapes(lo.shape[:-1], hi.shape[:-1], u0.shape[:-1], guess.shape[:-1], t.shape,
                                *[v.shape for v in pj.values()])
    n = int(np.prod(shape, dtype=np.int64))
    flat = lambda x, k: jnp.broadcast_to(x, shape + x.shape[x.ndim - k:]).reshape((n,) + x.shape[x.ndim - k:])  # noqa: E731
    out = _equilibrium_batch(model, applied, options, int(max_steps), flat(lo.astype(dtype), 1), flat(hi.astype(dtype), 1),
                             flat(u0.astype(dtype), 1), flat(guess.astype(dtype), 1), {k: flat(v, 0) for k, v in pj.items()},
                             flat(t, 0))
    u, q, stiff, status, steps = (x.reshape(shape + x.shape[1:]) for x in out)
    return Equilibrium(u=u, q=q, stiffness=stiff, status=status, steps=steps)


# --------------------------------------------------------------------------- forward dynamics
def _tableau(name):
    r6, r3 = np.sqrt(6.0), np.sqrt(3.0)
    if name == "radau5":  # Radau IIA, 3 stages, order 5, L-stable, stiffly accurate
        A = [[(88 - 7 * r6) / 360, (296 - 169 * r6) / 1800, (-2 + 3 * r6) / 225],
             [(296 + 169 * r6) / 1800, (88 + 7 * r6) / 360, (-2 - 3 * r6) / 225],
             [(16 - r6) / 36, (16 + r6) / 36, 1 / 9]]
        c = [(4 - r6) / 10, (4 + r6) / 10, 1.0]
    elif name == "gauss4":  # Gauss-Legendre, 2 stages, order 4, A-stable, symplectic
        A = [[0.25, 0.25 - r3 / 6], [0.25 + r3 / 6, 0.25]]
        c = [0.5 - r3 / 6, 0.5 + r3 / 6]
    elif name == "midpoint":  # implicit midpoint, order 2, A-stable, symplectic
        A, c = [[0.5]], [0.5]
    else:
        raise ValueError(f"unknown method {name!r}; choose one of {METHODS}")
    A = np.array(A)
    b = A[-1] if name == "radau5" else (np.array([0.5, 0.5]) if name == "gauss4" else np.array([1.0]))
    # y_{n+1} = y_n + h b^T F = y_n + b^T A^{-1} Z with Z_i = Y_i - y_n: no extra f evaluations.
    d = np.linalg.solve(A.T, b)
    return A, np.array(c), d


#: Implicit Runge-Kutta methods of ``forward_dynamics``: ``"radau5"`` (L-stable: use it with
#: a motor inductance), ``"gauss4"`` and ``"midpoint"`` (A-stable, symplectic: best energy
#: behaviour for unloaded mechanisms, but they do not damp a stiff electrical mode).
METHODS = ("radau5", "gauss4", "midpoint")


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Trajectory:
    """Forward-dynamics result (a pytree; leading axis = the ``steps + 1`` time points).

    - `t` (s), `u` ``(N+1, dof)``, `u_dot`, `q` ``(N+1, m)``.
    - `current`: motor current ``(N+1, 1)`` (A) with an inductive motor, else ``(N+1, 0)``.
    - `status`: ``DynStatus`` of the run (scalar); `t_stop`: time of the last valid state.
      Rows after a stop are NaN; with ``STROKE_END`` the first state past the end is kept.
    - `newton`: simplified-Newton iterations of each step ``(N,)``.
    """

    t: jax.Array
    u: jax.Array
    u_dot: jax.Array
    current: jax.Array
    q: jax.Array
    status: jax.Array
    t_stop: jax.Array
    newton: jax.Array


def _voltage(spec, t, p):
    if isinstance(spec, str):
        return p[spec]
    if callable(spec):
        return spec(t, Vars(p))
    return spec


def _close(mech: Mechanism, u, p, qg, iters: int):
    """Close the loop near ``qg`` by ``iters`` plain Newton steps (a step's guess is within
    a step of the root; a fixed count keeps every batch member in step), then
    attach the root to ``(u, p)`` (implicit derivatives).  ``ok`` is False for a residual
    above tolerance, a singular Jacobian (toggle) or a change of assembly branch."""
    stop = jax.lax.stop_gradient
    us, ps = stop(u), jax.tree_util.tree_map(stop, p)
    _, ftol, cond_max = tolerances(SolverOptions(), qg.dtype)
    def newton_step(_, q):
        return q - solve_small(jax.jacfwd(mech.residual)(q, us, ps), mech.residual(q, us, ps))

    q = jax.lax.fori_loop(0, iters, newton_step, stop(qg))
    r = mech.residual(q, us, ps)
    scale = mech.length_scale(ps)
    ok = jnp.all(jnp.isfinite(q)) & (jnp.linalg.norm(r) <= ftol * scale)
    s_ = jnp.where(jnp.asarray(mech.coord_is_length()), scale, 1.0)
    ok = ok & (cond1(jax.jacfwd(mech.residual)(q, us, ps) * s_[None, :] / scale) <= cond_max)
    if mech.branch is not None:
        ok = ok & (jnp.sign(mech.branch_value(q, us, ps)) == jnp.sign(mech.branch_value(stop(qg), us, ps)))
    q_star = jnp.where(ok, q, jnp.nan)
    return implicit_root(mech, q_star, ok, u, p), ok


def _rhs(model: Model, load, motor, voltage, k_in, iters, p, t, y, qg):
    """``y' = f(t, y)`` with ``y = (u, u_dot, [i])``: ``M u_ddot = tau - h(u, u_dot, t)``.
    NaN where the loop cannot be closed."""
    mech = model.mechanism
    dof = mech.dof
    u, ud = y[:dof], y[dof : 2 * dof]
    q, ok = _close(mech, u, p, qg, iters)
    M = mass_matrix(model, q, u, p)
    # h(u, u_dot, t): the inverse-dynamics force at zero input acceleration
    # (for one input: (1/2) M'(u) u_dot^2 - Q(u, u_dot, t)).
    hvec, _ = generalized_forces(model, q, u, ud, jnp.zeros_like(ud), p, t)
    tau = jnp.zeros_like(u)
    if load is not None:
        tau = tau + jnp.reshape(load(t, q, u, ud, p), (dof,))
    di = []
    if motor is not None:
        v = _voltage(voltage, t, p)
        if motor.inductance is None:
            tau = tau.at[k_in].add(motor.steady_torque(v, ud[k_in], p))
        else:
            i = y[2 * dof]
            tau = tau.at[k_in].add(motor.torque(i, p))
            di = [motor.current_rate(i, v, ud[k_in], p)]
    udd = solve_small(M, tau - hvec)
    f = jnp.concatenate([ud, udd, jnp.reshape(jnp.asarray(di, y.dtype), (-1,))])
    return jnp.where(ok, f, jnp.nan)


def _stage_residual(model, load, motor, voltage, k_in, iters, A, c, Z, args):
    """Stage equations ``G(Z) = Z - h A F(y + Z)`` (``Z_i = Y_i - y_n``)."""
    y, qg, p, t, h = args
    F = jax.vmap(lambda ci, zi: _rhs(model, load, motor, voltage, k_in, iters, p, t + ci * h, y + zi, qg))(c, Z)
    return Z - h * (jnp.asarray(A, Z.dtype) @ F)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _attach_stages(G, Z_star, args):
    """Identity on the converged stages ``Z*``; tangent ``dZ = -G_Z^{-1} G_args dargs``
    (implicit function theorem on ``G(Z*, args) = 0``).  Written as a custom JVP rather than
    ``jax.lax.custom_root``, which traces the linearization of ``G`` (third derivatives of
    the positions) on every call, differentiated or not."""
    return Z_star


@_attach_stages.defjvp
def _attach_stages_jvp(G, primals, tangents):
    Z_star, args = primals
    _, dargs = tangents
    Z = _attach_stages(G, Z_star, args)
    ok = jnp.all(jnp.isfinite(Z))
    Zs = jnp.where(ok, Z, jnp.zeros_like(Z))
    k = Z.size
    jz = jax.jacfwd(lambda z: G(z, args))(Zs).reshape(k, k)
    jz = jnp.where(ok & jnp.all(jnp.isfinite(jz)), jz, jnp.eye(k, dtype=jz.dtype))
    _, rhs = jax.jvp(lambda a: G(Zs, a), (args,), (dargs,))
    dZ = -jnp.linalg.solve(jz, rhs.reshape(-1)).reshape(Z.shape)
    return Z, jnp.where(ok, dZ, jnp.zeros_like(dZ))


def _forward(model, method, steps, load, motor, voltage, k_in, iters, newton_tol, newton_max, p, t0, h, y0, q0, lo, hi):
    mech = model.mechanism
    dof = mech.dof
    A_np, c_np, d_np = _tableau(method)
    A, c, d = (jnp.asarray(x, y0.dtype) for x in (A_np, c_np, d_np))
    s, n = A.shape[0], y0.shape[0]
    stop = jax.lax.stop_gradient
    ps = jax.tree_util.tree_map(stop, p)
    f = lambda t, y, qg, p_: _rhs(model, load, motor, voltage, k_in, iters, p_, t, y, qg)  # noqa: E731
    fd_step = float(jnp.finfo(y0.dtype).eps) ** 0.5

    def step(carry, k):
        y, q, status, t_stop = carry
        t = t0 + k * h
        qg = stop(q)
        ys = stop(y)
        scale = 1.0 + jnp.abs(ys)
        # Simplified Newton with one iteration matrix I - h A (x) J(y_n) per step.  J only
        # steers the iteration (the converged stages do not depend on it), so a forward
        # difference is enough, and it avoids third derivatives of the implicit positions.
        # The difference points ride in the same batched right-hand-side call as the
        # stages: one copy of the right-hand side in the compiled step (compile time is
        # dominated by it), at the price of n + 1 extra evaluations per iteration.
        dy = fd_step * scale
        ts = jnp.concatenate([t + c * h, jnp.full((n + 1,), t)])
        y_fd = jnp.concatenate([ys[None], ys + jnp.diag(dy)])
        eye = jnp.eye(s * n, dtype=y.dtype)

        def newton(Z0):
            def cond_fn(st):
                it, _, _, err = st
                return (it < newton_max) & (err > newton_tol)

            def body(st):
                it, Z, Minv, _ = st
                fb = jax.vmap(lambda ti, yi: f(ti, yi, qg, ps))(ts, jnp.concatenate([ys + Z, y_fd]))
                J0 = jnp.where(it == 0, ((fb[s + 1 :] - fb[s]) / dy[:, None]).T, 0.0)
                J0 = jnp.where(jnp.isfinite(J0), J0, 0.0)
                Minv = jnp.where(it == 0, jnp.linalg.inv(eye - h * jnp.kron(A, J0)), Minv)
                dZ = -(Minv @ (Z - h * (A @ fb[:s])).reshape(-1)).reshape(Z.shape)
                err = jnp.max(jnp.abs(dZ) / scale)
                finite = jnp.isfinite(err)
                # err = -1 marks a non-finite stage (the loop could not be closed): stop.
                return it + 1, jnp.where(finite, Z + dZ, Z), Minv, jnp.where(finite, err, -1.0)

            it, Z, _, err = jax.lax.while_loop(cond_fn, body, (0, Z0, eye, jnp.asarray(jnp.inf, Z0.dtype)))
            return Z, it, err

        Z_star, it, err = newton(jnp.zeros((s, n), y.dtype))
        G = functools.partial(_stage_residual, model, load, motor, voltage, k_in, iters, A_np, c_np)
        Z = _attach_stages(G, stop(Z_star), (y, qg, p, t, h))
        y_new = y + d @ Z
        q_new, pos_ok = _close(mech, y_new[:dof], p, qg, iters)
        conv = (err >= 0) & (err <= 1e3 * newton_tol)
        finite = jnp.all(jnp.isfinite(y_new))
        out_of_stroke = jnp.any(y_new[:dof] < lo) | jnp.any(y_new[:dof] > hi)
        new_status = jnp.where(
            (err < 0) | ~pos_ok, DynStatus.POSITION,
            jnp.where(~conv, DynStatus.NOT_CONVERGED,
                      jnp.where(~finite, DynStatus.NONFINITE,
                                jnp.where(out_of_stroke, DynStatus.STROKE_END, DynStatus.OK))))
        running = status == DynStatus.OK
        accept = running & ((new_status == DynStatus.OK) | (new_status == DynStatus.STROKE_END))
        y_next = jnp.where(accept, y_new, y)
        q_next = jnp.where(accept, q_new, q)
        status_next = jnp.where(running, new_status, status).astype(jnp.int32)
        t_stop = jnp.where(accept, t + h, t_stop)
        return (y_next, q_next, status_next, t_stop), (jnp.where(accept, y_new, jnp.nan), jnp.where(accept, q_new, jnp.nan), it)

    init = (y0, q0, jnp.asarray(DynStatus.OK, jnp.int32), t0)
    (_, _, status, t_stop), (ys, qs, its) = jax.lax.scan(step, init, jnp.arange(steps, dtype=y0.dtype))
    return jnp.concatenate([y0[None], ys]), jnp.concatenate([q0[None], qs]), status, t_stop, its


@functools.partial(jax.jit, static_argnums=tuple(range(10)))
def _forward_jit(*args):
    return _forward(*args)


def forward_dynamics(model: Model, p: Mapping, u0, u_dot0, guess, *, h, steps: int, t0=0.0, method: str = "radau5",
                     motor: DCMotor | None = None, voltage=None, current0=0.0, motor_input: str | None = None,
                     load: Callable | None = None, stroke=None, options: SolverOptions = SolverOptions(),
                     newton_tol: float = 1e-12, newton_max: int = 12, close_iters: int = 5) -> Trajectory:
    """Integrate the equations of motion in the inputs, with fixed steps (one design).

    ``M(u) u_ddot + h(u, u_dot, t) = tau_load + tau_motor`` where ``M`` is ``mass_matrix``
    and ``h`` the inverse-dynamics force at zero input acceleration (for one input
    ``h = (1/2) M'(u) u_dot^2 - Q``); with an inductive motor the state also holds the
    current, ``L di/dt = v - R i - n K w``.  Every stage closes the loop (a fixed number of
    Newton steps from the step's start, attached to ``(u, p)`` by ``solve.implicit_root``),
    and the stage equations ``Z = h A F(y + Z)`` are solved by simplified Newton (one
    iteration matrix per step, from a finite-difference Jacobian) and attached to their
    arguments by a custom JVP (the implicit function theorem on the stage equations:
    ``dZ = -G_Z^{-1} G_args dargs``).  No derivative goes through an iteration, and the
    whole run is differentiable, forward and reverse mode, in ``p``, ``u0``, ``u_dot0``
    and ``h``: see ``docs/forward_dynamics_gradients.md`` and the notebook
    ``notebooks/forward_dynamics_gradients.ipynb`` (a final angle's gradient in a mass,
    a length and the motor voltage, checked against finite differences).

    **Arguments**

    - `p`: parameters; `u0`, `u_dot0`: initial inputs and rates ``(dof,)``; `guess`:
      coordinates near the initial position (picks the branch).
    - `h`: step (s); `steps`: number of steps (static); `t0`: start time (s).
    - `method`: one of ``METHODS``.
    - `motor`: a ``DCMotor`` on input `motor_input` (default the first); `voltage`: spec of
      its voltage, a parameter name, a number, or ``fn(t, p) -> V``; `current0` (A).  The
      parameters the motor's specs name, and a voltage's name, belong in `p` alongside the
      model's (``Model.parameters``) without being declared anywhere else.
    - `load`: extra generalized force at the inputs, ``fn(t, q, u, u_dot, p) -> (dof,)``
      (arrays; ``p`` a dict), e.g. a controller or a prescribed torque.
    - `stroke`: ``(lo, hi)``: the run stops with ``STROKE_END`` when an input leaves it.
    - `newton_tol`: stage-Newton tolerance on the scaled increment; `newton_max`: its budget.
    - `close_iters`: Newton steps that close the loop at each stage from the step's start
      (the step must be small enough for them to converge; a failure is reported).
    - `options`: settings of the initial position solve.

    **Returns** a ``Trajectory``.  A run that reaches a singular or unassemblable position,
    a failed step or the stroke end stops there with its ``DynStatus``; later rows are NaN.
    """
    mech = model.mechanism
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {METHODS}")
    if motor is not None and voltage is None:
        raise ValueError("a motor needs a voltage: a parameter name, a number or fn(t, p) -> V")
    if int(steps) < 1:
        raise ValueError(f"steps must be at least 1, got {steps}")
    k_in = 0
    if motor_input is not None:
        if motor_input not in mech.inputs:
            raise ValueError(f"motor_input {motor_input!r} is not an input; inputs are {list(mech.inputs)}")
        k_in = mech.inputs.index(motor_input)
    u0 = as_inputs(mech, jnp.asarray(u0), "u0")
    ud0 = as_inputs(mech, jnp.asarray(u_dot0), "u_dot0")
    guess = as_coords(mech, guess)
    dtype = jnp.result_type(u0, ud0, guess, float)
    pj = _prep_p(model, p, dtype, parameter_names(motor) + spec_names(voltage))
    parts = [u0.astype(dtype), ud0.astype(dtype)]
    if motor is not None and motor.inductance is not None:
        parts.append(jnp.reshape(jnp.asarray(current0, dtype), (1,)))
    y0 = jnp.concatenate(parts)
    # The jitted batch solve (compiled once per mechanism and options); a dict of scalars
    # is a batch of shape ().
    sol = solve(mech, {k: u0.astype(dtype)[i] for i, k in enumerate(mech.inputs)}, _mechanism_params(model, pj),
                guess.astype(dtype), options=options)
    if stroke is None:
        lo = jnp.full((mech.dof,), -jnp.inf, dtype)
        hi = jnp.full((mech.dof,), jnp.inf, dtype)
    else:
        lo, hi = (jnp.broadcast_to(jnp.asarray(b, dtype), (mech.dof,)) for b in stroke)
    ys, qs, status, t_stop, its = _forward_jit(model, method, int(steps), load, motor, voltage, k_in, int(close_iters),
                                               float(newton_tol), int(newton_max), pj, jnp.asarray(t0, dtype),
                                               jnp.asarray(h, dtype), y0, sol.q, lo, hi)
    status = jnp.where(sol.status == Status.CONVERGED, status, DynStatus.POSITION).astype(jnp.int32)
    dof = mech.dof
    t = jnp.asarray(t0, dtype) + jnp.asarray(h, dtype) * jnp.arange(int(steps) + 1, dtype=dtype)
    return Trajectory(t=t, u=ys[:, :dof], u_dot=ys[:, dof:2 * dof], current=ys[:, 2 * dof:], q=qs, status=status,
                      t_stop=t_stop, newton=its)
