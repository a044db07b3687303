"""Every joint's reaction from the per-body Newton-Euler equations, at one solved state.

Once the motion is known (``q``, ``q_dot``, ``q_ddot``: every body's centre-of-mass
acceleration ``a_G`` and angular acceleration ``alpha``), each moving body k gives three
equations, linear in the joint forces and the drive efforts:

    sum F_joints + sum F_applied + m g = m a_G                    (x and y)
    sum (r_P - r_G) x F_joints + M_joints + sum (r_P - r_G) x F_applied + M_applied = J alpha

A joint joining bodies (a, b) enters b's equations with its force ``F`` (the force a exerts
on b) and a's with ``-F`` (``dynamics.joints`` lists the unknowns of each type).  For a
mobile linkage with as many drives as degrees of freedom the system is square (Gruebler:
``3 n = 2 j_revolute + 2 j_prismatic + j_slot + dof``), and its sparsity is known before
any number: ``structure.block_order`` orders it into small blocks (a four-bar: the dyad's 6x6,
then the crank's 3x3), solved in sequence per sample (``linalg.solve_blocks``).  Unlike the
multipliers of the loop equations, these reactions do not depend on which joints the loops
happened to cut; the drive efforts equal the virtual-power ones (a test checks it).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..solver.linalg import parts, solve_small
from ..mechanism.structure import block_order
from .joints import GROUND, Actuator, Prismatic, Revolute, Slot, joint_name
from .model import Axial, Model, Moment, PointForce, angle_of, point_of
from .virtual_power import LoadedState

__all__ = ["joint_reactions", "joint_axes", "reaction_system", "solve_reaction_system", "unpack_reactions"]


def _cross(r, f):
    """z-component of ``r x f`` for planar vectors given as complex numbers."""
    return jnp.real(r) * jnp.imag(f) - jnp.imag(r) * jnp.real(f)


class _System:
    """The entries of the Newton-Euler system being written: ``a[(row, col)]`` and ``rhs[row]``."""

    def __init__(self, model: Model, st: LoadedState):
        self.index = {b.name: k for k, b in enumerate(model.bodies)}
        self.centre = st.poses[0]
        self.a: dict = {}
        self.rhs: dict = {}

    def add(self, row, col, value):
        if isinstance(value, float) and value == 0.0:
            return
        self.a[(row, col)] = self.a.get((row, col), 0.0) + value

    def force(self, body: str, col: int, direction, at):
        """Unknown ``x[col]`` times the force ``direction`` (complex) applied to `body` at `at`.
        A constant direction (a pin's x or y) stays a Python number: the elimination pivots
        on it (``_solve``)."""
        if body == GROUND:
            return
        k = self.index[body]
        r = at - self.centre[k]
        if isinstance(direction, complex):
            fx, fy = direction.real, direction.imag
            self.add(3 * k, col, fx)
            self.add(3 * k + 1, col, fy)
            self.add(3 * k + 2, col, (jnp.real(r) * fy if fy else 0.0) - (jnp.imag(r) * fx if fx else 0.0))
            return
        self.add(3 * k, col, jnp.real(direction))
        self.add(3 * k + 1, col, jnp.imag(direction))
        self.add(3 * k + 2, col, _cross(r, direction))

    def torque(self, body: str, col: int, sign: float):
        if body != GROUND:
            self.add(3 * self.index[body] + 2, col, sign)

    def applied(self, body: str, force=0.0, at=None, moment=0.0):
        """A known load on `body`: it moves to the right-hand side."""
        if body == GROUND:
            return
        k = self.index[body]
        rows = (3 * k, 3 * k + 1, 3 * k + 2)
        mom = moment + (_cross(at - self.centre[k], force) if at is not None else 0.0)
        for r, v in zip(rows, (jnp.real(force), jnp.imag(force), mom)):
            self.rhs[r] = self.rhs.get(r, 0.0) - v


def joint_axes(model: Model, joint, q, u, p):
    """Unit vectors (complex, global) of a ``Prismatic`` or ``Slot`` joint at a pose: the
    guide's direction ``e`` (a straight guide or slot at its angle; ``None`` for a circular
    slot) and the normal ``n`` its normal force acts along (``i e``, the left normal of
    ``e``; a circular slot's radius, from its centre to the pin)."""
    mech = model.mechanism
    at = point_of(mech, joint.point, q, u, p)
    if isinstance(joint, Slot) and joint.center is not None:
        r = at - point_of(mech, joint.center, q, u, p)
        return None, r / jnp.abs(r)
    e = jnp.exp(1j * angle_of(mech, joint.angle, q, u, p))
    return e, 1j * e


def _write_joints(sys_: _System, model: Model, st: LoadedState):
    mech, q, u, p = model.mechanism, st.q, st.u, st.p
    lay = model.layout
    geometry = {}
    for j in model.joints:
        name = joint_name(j)
        cols = lay.columns[name]
        a, b = j.bodies
        drive_input = getattr(j, "input", None)
        drive = lay.efforts[mech.inputs.index(drive_input)] if drive_input is not None else None
        if isinstance(j, Actuator):
            pa, pb = (point_of(mech, x, q, u, p) for x in j.points)
            e = (pb - pa) / jnp.abs(pb - pa)
            sys_.force(b, drive, e, pb)
            sys_.force(a, drive, -e, pa)
            geometry[name] = (e, None)
            continue
        at = point_of(mech, j.point, q, u, p)
        if isinstance(j, Revolute):
            for col, d in zip(cols, (1.0 + 0j, 1j)):
                sys_.force(b, col, d, at)
                sys_.force(a, col, -d, at)
            if drive is not None:
                sys_.torque(b, drive, 1.0)
                sys_.torque(a, drive, -1.0)
            geometry[name] = (None, None)
            continue
        e, n = joint_axes(model, j, q, u, p)
        sys_.force(b, cols[0], n, at)
        sys_.force(a, cols[0], -n, at)
        if isinstance(j, Prismatic):
            sys_.torque(b, cols[1], 1.0)
            sys_.torque(a, cols[1], -1.0)
            if drive is not None:
                sys_.force(b, drive, e, at)
                sys_.force(a, drive, -e, at)
        geometry[name] = (e, n)
    return geometry


def _write_loads(sys_: _System, model: Model, st: LoadedState):
    mech, q, u, p = model.mechanism, st.q, st.u, st.p
    inertia = st.accels is not None
    for k, body in enumerate(model.bodies):
        m, J = st.masses[k], st.inertias[k]
        a_g = st.accels[0][k] if inertia else 0.0
        alpha = st.accels[1][k] if inertia else 0.0
        for r, v in zip((3 * k, 3 * k + 1, 3 * k + 2), (m * jnp.real(a_g), m * jnp.imag(a_g), J * alpha)):
            sys_.rhs[r] = sys_.rhs.get(r, 0.0) + v
        for gv in st.gravity:
            sys_.applied(body.name, force=m * gv, at=sys_.centre[k])
    forces, moments, tensions = iter(st.forces), iter(st.moments), iter(st.tensions)
    for ld, at in zip([ld for ld in model.loads if isinstance(ld, PointForce)], st.poses[2]):
        sys_.applied(ld.body, force=next(forces), at=at)
    for ld in model.loads:
        if isinstance(ld, Moment):
            M = next(moments)
            pair = (GROUND, ld.body) if isinstance(ld.body, str) else tuple(ld.body)
            sys_.applied(pair[1], moment=M)
            sys_.applied(pair[0], moment=-M)
        elif isinstance(ld, Axial):
            T = next(tensions)
            pa, pb = point_of(mech, ld.a, q, u, p), point_of(mech, ld.b, q, u, p)
            e = (pb - pa) / jnp.abs(pb - pa)  # tension pulls the ends together
            sys_.applied(ld.bodies[0], force=T * e, at=pa)
            sys_.applied(ld.bodies[1], force=-T * e, at=pb)


def _constant(v) -> bool:
    return isinstance(v, (int, float))


def _solve(sys_: _System, n: int, ok, dtype):
    """The unknowns of the Newton-Euler system, NaN where the position failed.

    Gaussian elimination with pivots chosen from the structure, not the values: every force
    row is pivoted on a constant entry (a pin's force enters its two bodies' force balances
    with coefficient +-1), and eliminated from the remaining rows with the multipliers the
    lever arms give, as a textbook eliminates pin forces by hand; the few rows left (the
    moment balances) are ordered block lower-triangular (``structure.block_order``) and
    solved block by block (``linalg.solve_small``); back substitution gives the pins.  No
    LAPACK call (a stored executable with one does not run in a new process: jaxlib 0.10)
    and no loop: a six-bar's 15 unknowns are 10 pivots and blocks of 2x2."""
    zero = jnp.zeros((), dtype)
    rows = {i: {} for i in range(n)}
    for (i, j), v in sys_.a.items():
        rows[i][j] = v
    rhs = {i: sys_.rhs.get(i, 0.0) for i in range(n)}
    left, pivots, taken = set(range(n)), [], set()
    for r in [i for i in range(n) if i % 3 != 2]:  # the force balances
        cands = sorted(c for c, v in rows[r].items() if _constant(v) and c not in taken)
        if not cands:
            continue
        c = cands[0]
        piv = rows[r][c]
        left.discard(r)
        taken.add(c)
        pivots.append((r, c))
        for i in left:
            if c not in rows[i]:
                continue
            m = rows[i].pop(c) / piv
            for j, v in rows[r].items():
                if j != c:
                    new = rows[i].get(j, 0.0) - m * v
                    if _constant(new) and new == 0.0:
                        rows[i].pop(j, None)
                    else:
                        rows[i][j] = new
            rhs[i] = rhs[i] - m * rhs[r]
    rest_rows = sorted(left)
    rest_cols = sorted(set(range(n)) - taken)
    pattern = np.array([[c in rows[i] for c in rest_cols] for i in rest_rows], bool).reshape(len(rest_rows), len(rest_cols))
    order = block_order(pattern) if pattern.size else ()
    if order is None:  # the pivots left no triangular order: one dense solve
        order = ((tuple(range(len(rest_rows))), tuple(range(len(rest_cols)))),)
    x: dict = {}
    for brows, bcols in order:
        rr, cc = [rest_rows[i] for i in brows], [rest_cols[j] for j in bcols]
        b = []
        for i in rr:
            v = jnp.asarray(rhs[i], dtype)
            for j, xj in x.items():
                if j in rows[i]:
                    v = v - rows[i][j] * xj
            b.append(v)
        sub = jnp.stack([jnp.stack([jnp.asarray(rows[i].get(j, zero), dtype) for j in cc]) for i in rr])
        sub = jnp.where(ok, sub, jnp.eye(len(rr), dtype=dtype))
        x.update(zip(cc, parts(solve_small(sub, jnp.stack(b)), 0)))
    for r, c in reversed(pivots):
        v = jnp.asarray(rhs[r], dtype)
        for j, a_rj in rows[r].items():
            if j != c:
                v = v - a_rj * x[j]
        x[c] = v / rows[r][c]
    return jnp.where(ok, jnp.stack([x[j] for j in range(n)]), jnp.nan)


def reaction_system(model: Model, st: LoadedState):
    """The per-body Newton-Euler system at one state, written but not solved: ``(system,
    geometry)``.  `system` holds the matrix entries ``system.a[(row, col)]`` and right-hand
    side ``system.rhs[row]`` (three rows per body: x, y force and moment balance); its
    ``applied(body, force=, at=, moment=)`` writes a further known load into ``rhs`` (how
    joint friction enters, ``dynamics.friction``).  `geometry` ``{joint: (e, n)}`` the
    unit vectors ``joint_reactions`` unpacks the unknowns with."""
    sys_ = _System(model, st)
    geometry = _write_joints(sys_, model, st)
    _write_loads(sys_, model, st)
    return sys_, geometry


def solve_reaction_system(model: Model, sys_, st: LoadedState):
    """The unknowns ``x (n,)`` of a ``reaction_system`` (``x (n, k)`` where every entry of
    ``sys_.rhs`` is a ``(k,)`` vector: k right-hand sides in one elimination); NaN where the
    position failed."""
    return _solve(sys_, model.layout.size, st.ok, st.q.dtype)


def unpack_reactions(model: Model, x, geometry):
    """``(efforts, forces, moments)`` of ``joint_reactions`` from the solved unknowns `x`."""
    lay = model.layout
    efforts = jnp.stack([x[c] for c in lay.efforts]) if lay.efforts else jnp.zeros((0,), x.dtype)
    forces, moments = {}, {}
    mech = model.mechanism
    for j in model.joints:
        name = joint_name(j)
        cols = lay.columns[name]
        e, nrm = geometry[name]
        if isinstance(j, Actuator):
            forces[name] = x[lay.efforts[mech.inputs.index(j.input)]] * e
        elif isinstance(j, Revolute):
            forces[name] = jnp.asarray(x[cols[0]] + 1j * x[cols[1]])
        else:
            forces[name] = x[cols[0]] * nrm
            if isinstance(j, Prismatic):
                moments[name] = x[cols[1]]
    return efforts, forces, moments


def joint_reactions(model: Model, st: LoadedState):
    """Every joint's reaction and every drive's effort at one solved state.

    **Arguments**: `model` with ``joints``; `st` the ``virtual_power.LoadedState`` of the
    sample (inertia left out where it was built quasi-static).

    **Returns** ``(efforts (dof,), forces, moments)``: `efforts` the drive torque (N m) or
    force (N) on each input, in its positive sense; `forces` ``{joint: F}`` the force (N,
    complex ``Fx + i Fy``, global) that the joint's first body exerts on its second (a
    slot's or a guide's normal force as a vector; an actuator's push on its second body);
    `moments` ``{joint: M}`` (N m, CCW on the second body) for prismatic joints.  NaN where
    the position failed.
    """
    sys_, geometry = reaction_system(model, st)
    x = solve_reaction_system(model, sys_, st)
    return unpack_reactions(model, x, geometry)
