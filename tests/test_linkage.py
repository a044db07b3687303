"""Acceptance of ``jm.Linkage``: six-bars drawn as joint coordinates, masses and gravity (a
Watt I and a Stephenson III), driven along a stroke whose input reverses, against an
independent Newton-Euler model written here in numpy.

The numpy model shares no code with jaxmech: every moving link is a rigid body with its
own maximal coordinates (centre of mass ``x_G, y_G`` and rotation ``phi`` from the drawing),
every pin is two equations ``r_P(body a) - r_P(body b) = 0``, the driver one more.  Positions
come from a Newton solve along the stroke, velocities and accelerations from linear solves
with that Jacobian (the quadratic velocity terms written by hand), the mass properties
from the drawing (a uniform bar: midpoint and ``m L^2/12``; a uniform triangle: centroid and
``m (a^2 + b^2 + c^2)/36``), and the joint forces and crank torque from the square per-body
Newton-Euler system.  jaxmech's joint reactions, crank torque, coordinates and point
kinematics are then checked against it to 1e-10 relative, and against the power balance.
"""

import jax

jax.config.update("jax_enable_x64", True)

import functools  # noqa: E402

import jax.numpy as jnp  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402

RTOL = 1e-10
N = 61  # samples of a stroke s in [0, 2 pi]: u = u_drawing + 1.2 sin(s) (reverses at s = pi/2, 3 pi/2)
AMP = 1.2

# --------------------------------------------------------------------------- the drawings
# Watt I: ternary coupler A B E and ternary rocker O4 B F (adjacent at B), binary ground, a
# dyad E-C-F between the two ternaries.  Explicit centre and inertia on the coupler.
WATT = dict(
    points={"O2": (0, 0), "A": (0.5, 0.866), "B": (3.2, 2.0), "O4": (3.6, 0), "E": (2.2, 3.2), "F": (4.5, 1.6), "C": (4.2, 3.6)},
    links={"crank": "O2 A", "coupler": "A B E", "rocker": "O4 B F", "link5": "E C", "link6": "C F"},
    ground="O2 O4", driver="crank", mass={"crank": 1.0, "coupler": 3.0, "rocker": 4.0, "link5": 1.5, "link6": 2.0},
    centre={"coupler": (2.0, 2.1)}, inertia={"coupler": 1.1}, gravity=9.81)
# Stephenson III: four-bar O2 A B O4 with a ternary coupler A B C, a dyad C-D-O6 to a third
# ground pivot (ternary ground).  Explicit centre (off the bar's line) and inertia on link5,
# an explicit centre named by a point on the rocker (with its inertia), defaults elsewhere.
STEPH = dict(
    points={"O2": (0, 0), "A": (0.4, 0.9), "B": (3.0, 1.8), "O4": (3.4, 0), "C": (1.8, 3.0), "D": (4.2, 3.9), "O6": (5.6, 1.9)},
    links={"crank": "O2 A", "coupler": "A B C", "rocker": "O4 B", "link5": "C D", "link6": "O6 D"},
    ground="O2 O4 O6", driver="crank", mass={"crank": 0.8, "coupler": 3.5, "rocker": 2.0, "link5": 1.2, "link6": 1.8},
    centre={"link5": (3.1, 3.7), "rocker": "B"}, inertia={"link5": 0.3, "rocker": 0.2}, gravity=9.81)
# A four-bar (ground pivots off the origin), explicit centre and inertia on the coupler.
FOUR = dict(
    points={"O2": (0.2, -0.1), "A": (0.55, 0.75), "B": (2.9, 1.7), "O4": (3.3, -0.2)},
    links={"crank": "O2 A", "coupler": "A B", "rocker": "O4 B"}, ground="O2 O4", driver="crank",
    mass={"crank": 0.7, "coupler": 2.5, "rocker": 1.6}, centre={"coupler": (1.8, 1.5)}, inertia={"coupler": 0.9}, gravity=9.81)
SPECS = {"watt": WATT, "stephenson": STEPH, "fourbar": FOUR}


def cross(r, f):
    """z of r x f for planar vectors as complex numbers."""
    return (np.conj(r) * f).imag


# --------------------------------------------------------------------------- numpy model
class Rigid:
    """The independent model: body k's coordinates ``X[3k:3k+3] = (x_G, y_G, phi)``; a point
    P of body k is ``G + e^{i phi} (P_drawing - G_drawing)``."""

    def __init__(self, spec):
        self.P0 = {k: complex(*v) for k, v in spec["points"].items()}
        self.links = {k: v.split() for k, v in spec["links"].items()}
        self.ground = spec["ground"].split()
        self.driver = spec["driver"]
        self.bodies = list(self.links)
        self.n = len(self.bodies)
        self.g = float(spec["gravity"])
        centre, inertia, mass = spec.get("centre", {}), spec.get("inertia", {}), spec["mass"]
        owners = {x: (["ground"] if x in self.ground else []) + [k for k in self.bodies if x in self.links[k]] for x in self.P0}
        assert all(1 <= len(o) <= 2 for o in owners.values())  # the drawings here: two bodies per pin, no tracer
        self.owner = {x: o[-1] for x, o in owners.items()}
        self.joints = [(x, *o) for x, o in owners.items() if len(o) == 2]  # (point, a, b): +F on b, -F on a
        self.m, self.G0, self.J = {}, {}, {}
        for k in self.bodies:
            js = [self.P0[x] for x in self.links[k] if len(owners[x]) == 2]
            m = self.m[k] = float(mass[k])
            if len(js) == 2:  # uniform bar
                G, J = 0.5 * (js[0] + js[1]), m * abs(js[1] - js[0]) ** 2 / 12.0
            else:  # uniform triangular plate
                assert len(js) == 3
                G, J = sum(js) / 3.0, m * sum(abs(js[i] - js[i - 1]) ** 2 for i in range(3)) / 36.0
            c = centre.get(k)
            self.G0[k] = G if c is None else (self.P0[c] if isinstance(c, str) else complex(*c))
            self.J[k] = float(inertia[k]) if k in inertia else J
        pivot, tip = self.links[self.driver]
        self.u_d = float(np.angle(self.P0[tip] - self.P0[pivot]))
        self.kd = self.bodies.index(self.driver)

    def arm(self, k, x):
        return self.P0[x] - self.G0[k]

    def pos(self, X, k, x):
        if k == "ground":
            return self.P0[x]
        i = self.bodies.index(k)
        return X[3 * i] + 1j * X[3 * i + 1] + np.exp(1j * X[3 * i + 2]) * self.arm(k, x)

    def residual(self, X, u):
        r = []
        for x, a, b in self.joints:
            d = self.pos(X, a, x) - self.pos(X, b, x)
            r += [d.real, d.imag]
        return np.array(r + [X[3 * self.kd + 2] - (u - self.u_d)])

    def jacobian(self, X):
        A = np.zeros((3 * self.n, 3 * self.n))
        for row, (x, a, b) in enumerate(self.joints):
            for k, sg in ((a, 1.0), (b, -1.0)):
                if k == "ground":
                    continue
                i = self.bodies.index(k)
                d = 1j * np.exp(1j * X[3 * i + 2]) * self.arm(k, x)
                A[2 * row, 3 * i] += sg
                A[2 * row + 1, 3 * i + 1] += sg
                A[2 * row, 3 * i + 2] += sg * d.real
                A[2 * row + 1, 3 * i + 2] += sg * d.imag
        A[-1, 3 * self.kd + 2] = 1.0
        return A

    def quadratic(self, X, W):
        """The constraints' second derivative at zero accelerations: sum of -w^2 e^{i phi} arm."""
        r = []
        for x, a, b in self.joints:
            d = 0j
            for k, sg in ((a, 1.0), (b, -1.0)):
                if k != "ground":
                    i = self.bodies.index(k)
                    d -= sg * W[3 * i + 2] ** 2 * np.exp(1j * X[3 * i + 2]) * self.arm(k, x)
            r += [d.real, d.imag]
        return np.array(r + [0.0])

    def stroke(self, u, ud, udd):
        """``(X, X_dot, X_ddot)`` ``(N, 3n)`` along the stroke, by continuation from the drawing."""
        X = np.concatenate([[self.G0[k].real, self.G0[k].imag, 0.0] for k in self.bodies])
        e = np.zeros(3 * self.n)
        e[-1] = 1.0
        xs, vs, acs = [], [], []
        for uk, udk, uddk in zip(u, ud, udd):
            for _ in range(60):
                dX = np.linalg.solve(self.jacobian(X), -self.residual(X, uk))
                X = X + dX
                if np.max(np.abs(dX)) < 1e-14:
                    break
            assert np.max(np.abs(self.residual(X, uk))) < 1e-13
            A = self.jacobian(X)
            W = np.linalg.solve(A, udk * e)
            xs.append(X.copy())
            vs.append(W)
            acs.append(np.linalg.solve(A, uddk * e - self.quadratic(X, W)))
        return np.array(xs), np.array(vs), np.array(acs)

    def point(self, X, W, Ac, x, k=None):
        """Position, velocity and acceleration of point `x` (of body `k`, default its owner)."""
        k = self.owner[x] if k is None else k
        if k == "ground":
            return self.P0[x], 0j, 0j
        i = self.bodies.index(k)
        r = np.exp(1j * X[3 * i + 2]) * self.arm(k, x)
        w, al = W[3 * i + 2], Ac[3 * i + 2]
        return (X[3 * i] + 1j * X[3 * i + 1] + r, W[3 * i] + 1j * W[3 * i + 1] + 1j * w * r,
                Ac[3 * i] + 1j * Ac[3 * i + 1] + (1j * al - w * w) * r)

    def centre(self, Z, k):
        i = self.bodies.index(k)
        return Z[3 * i] + 1j * Z[3 * i + 1]

    def newton_euler(self, X, W, Ac):
        """The square per-body system: unknowns every joint force (2 each, in ``joints``
        order) and the crank torque.  Returns ``({point: F on b from a}, tau)``."""
        size = 3 * self.n
        A, b = np.zeros((size, size)), np.zeros(size)
        for i, k in enumerate(self.bodies):
            G = self.centre(X, k)
            b[3 * i: 3 * i + 2] = self.m[k] * np.array([Ac[3 * i], Ac[3 * i + 1] + self.g])
            b[3 * i + 2] = self.J[k] * Ac[3 * i + 2]
            for j, (x, ka, kb) in enumerate(self.joints):
                for kk, sg in ((ka, -1.0), (kb, 1.0)):
                    if kk == k:
                        r = self.pos(X, k, x) - G
                        A[3 * i, 2 * j] += sg
                        A[3 * i + 1, 2 * j + 1] += sg
                        A[3 * i + 2, 2 * j] += sg * cross(r, 1.0)
                        A[3 * i + 2, 2 * j + 1] += sg * cross(r, 1j)
        A[3 * self.kd + 2, -1] = 1.0
        sol = np.linalg.solve(A, b)
        return {x: sol[2 * j] + 1j * sol[2 * j + 1] for j, (x, _, _) in enumerate(self.joints)}, sol[-1]


def stroke_samples(u_d, offset=0.0, n=N):
    s = np.linspace(0.0, 2.0 * np.pi, n)
    return u_d + offset + AMP * np.sin(s), AMP * np.cos(s), -AMP * np.sin(s)


@functools.lru_cache(maxsize=None)
def case(name):
    """``(linkage, numpy model, jaxmech result, (X, X_dot, X_ddot))`` along the stroke."""
    spec = SPECS[name]
    lk = jm.Linkage(**spec)
    rig = Rigid(spec)
    u, ud, udd = stroke_samples(rig.u_d, offset=0.3 if name == "fourbar" else 0.0)  # the four-bar starts off the drawing
    res = lk.inverse_dynamics(jm.Samples(u, ud, udd))
    return lk, rig, res, rig.stroke(u, ud, udd)


SIX = ["watt", "stephenson"]
ALL = SIX + ["fourbar"]


def _rel(err, scale):
    return float(np.max(np.abs(err)) / scale)


# --------------------------------------------------------------------------- the drawing itself
@pytest.mark.parametrize("name", ALL)
def test_topology_and_mass_properties(name):
    """The linkage's joints, coordinates and parameters against the drawing (no compile)."""
    lk, rig = jm.Linkage(**SPECS[name]), Rigid(SPECS[name])
    assert {(j.point, frozenset(j.bodies)) for j in lk.model.joints} == {(x, frozenset((a, b))) for x, a, b in rig.joints}
    assert set(lk.joints) == {x for x, _, _ in rig.joints}
    assert lk.mechanism.inputs == ("theta_crank",)
    assert set(lk.mechanism.coords) == {f"theta_{k}" for k in rig.bodies if k != "crank"}
    assert len(lk.equations()) == len(rig.joints) - len(rig.bodies)  # Euler: E - N + 1 loops (N counts ground)
    assert abs(lk.input_at_drawing[0] - rig.u_d) <= 1e-15
    p, mass = lk.params, lk.mass_properties()
    for k in rig.bodies:
        assert abs(p[f"m_{k}"] - rig.m[k]) <= 1e-15 * rig.m[k]
        assert abs(mass[k][2] - rig.J[k]) <= RTOL * rig.J[k], k
    assert p["g"] == rig.g
    # the coordinates at the drawing: the angle of each link's frame vector (entry -> direction)
    for c, g0 in zip(lk.mechanism.coords, lk.guess):
        entry, direction = lk.built.frames[c[len("theta_"):]]
        assert abs(g0 - np.angle(rig.P0[direction] - rig.P0[entry])) <= 1e-15


# --------------------------------------------------------------------------- kinematics
@pytest.mark.parametrize("name", ALL)
def test_coordinates_and_points_match_numpy_kinematics(name):
    lk, rig, res, (X, W, Ac) = case(name)
    assert np.all(np.asarray(res.status) == 0)
    q, qd, qdd = (np.asarray(a) for a in (res.q, res.q_dot, res.q_ddot))
    for c, name_ in enumerate(lk.mechanism.coords):
        i = rig.bodies.index(name_[len("theta_"):])
        turn = q[:, c] - lk.guess[c] - X[:, 3 * i + 2]  # the link's rotation from the drawing
        assert _rel(np.angle(np.exp(1j * turn)), 1.0) <= RTOL, name_
        assert _rel(qd[:, c] - W[:, 3 * i + 2], np.max(np.abs(W[:, 3 * i + 2]))) <= RTOL, name_
        assert _rel(qdd[:, c] - Ac[:, 3 * i + 2], np.max(np.abs(Ac[:, 3 * i + 2]))) <= RTOL, name_
    names = list(rig.P0) + [f"G_{k}" for k in rig.bodies]
    assert set(res.points) == set(names)
    mine = {}
    for x in names:
        kin = [_centre_kin(rig, x[2:], *s) if x.startswith("G_") else rig.point(*s, x) for s in zip(X, W, Ac)]
        mine[x] = [np.array(v) for v in zip(*kin)]
    scale = [max(np.max(np.abs(mine[x][d])) for x in names) for d in range(3)]
    for x in names:
        for d in range(3):
            err = np.asarray(res.points[x][d]) - mine[x][d]
            assert _rel(err, scale[d]) <= RTOL, (x, ("position", "velocity", "acceleration")[d])


def _centre_kin(rig, k, X, W, Ac):
    i = rig.bodies.index(k)
    return (complex(X[3 * i], X[3 * i + 1]), complex(W[3 * i], W[3 * i + 1]), complex(Ac[3 * i], Ac[3 * i + 1]))


@pytest.mark.parametrize("name", SIX)
def test_joints_coincide_with_the_drawing_at_its_input(name):
    """At s = 0, pi and 2 pi the input is the drawing's (before and after each reversal):
    every joint is where it was drawn and every centre of mass where the drawing puts it."""
    lk, rig, res, _ = case(name)
    L = max(abs(z) for z in rig.P0.values())
    for k in (0, N // 2, N - 1):
        assert abs(float(res.u[k, 0]) - rig.u_d) <= 1e-15
        for x, z in rig.P0.items():
            assert abs(complex(res.points[x][0][k]) - z) <= RTOL * L, (k, x)
        for b in rig.bodies:
            assert abs(complex(res.points[f"G_{b}"][0][k]) - rig.G0[b]) <= RTOL * L, (k, b)
        assert np.max(np.abs(np.angle(np.exp(1j * (np.asarray(res.q[k]) - lk.guess))))) <= RTOL


# --------------------------------------------------------------------------- dynamics
def _jax_forces(lk, res, k):
    """jaxmech's joint reactions at sample k: ``[(point, a, b, F)]``: +F on b, -F on a."""
    return [(j.point, j.bodies[0], j.bodies[1], complex(res.joints[n][k])) for n, j in zip(lk.joints, lk.model.joints)]


@pytest.mark.parametrize("name", ALL)
def test_every_body_balances_with_jaxmech_reactions(name):
    """Per body and per sample: sum F = m a_G and sum M_G = J alpha, with jaxmech's joint
    reactions and crank torque and the numpy model's kinematics and mass properties."""
    lk, rig, res, (X, W, Ac) = case(name)
    tau = np.asarray(res.tau[:, 0])
    assert res.tau.shape == (N, 1)
    for k in range(N):
        forces = _jax_forces(lk, res, k)
        for i, b in enumerate(rig.bodies):
            G = rig.centre(X[k], b)
            m, J = rig.m[b], rig.J[b]
            f_terms = [m * rig.g * -1j, -m * rig.centre(Ac[k], b)]
            m_terms = [-J * Ac[k, 3 * i + 2]] + ([tau[k]] if b == rig.driver else [])
            for x, a, bb, F in forces:
                for body, sg in ((a, -1.0), (bb, 1.0)):
                    if body == b:
                        f_terms.append(sg * F)
                        m_terms.append(cross(rig.pos(X[k], b, x) - G, sg * F))
            sF = max(abs(t) for t in f_terms)
            sM = max(abs(t) for t in m_terms)
            assert abs(sum(f_terms)) <= RTOL * sF, (k, b, abs(sum(f_terms)) / sF)
            assert abs(sum(m_terms)) <= RTOL * sM, (k, b, abs(sum(m_terms)) / sM)


@pytest.mark.parametrize("name", ALL)
def test_power_balance(name):
    """tau u_dot = dT/dt + dV/dt, the energies by the numpy model."""
    lk, rig, res, (X, W, Ac) = case(name)
    lhs = np.asarray(res.tau[:, 0]) * np.asarray(res.u_dot[:, 0])
    dT = np.zeros(N)
    dV = np.zeros(N)
    for i, b in enumerate(rig.bodies):
        v, a = W[:, 3 * i] + 1j * W[:, 3 * i + 1], Ac[:, 3 * i] + 1j * Ac[:, 3 * i + 1]
        dT += rig.m[b] * (np.conj(v) * a).real + rig.J[b] * W[:, 3 * i + 2] * Ac[:, 3 * i + 2]
        dV += rig.m[b] * rig.g * v.imag
    scale = max(np.max(np.abs(lhs)), np.max(np.abs(dT)), np.max(np.abs(dV)))
    assert _rel(lhs - dT - dV, scale) <= RTOL


@pytest.mark.parametrize("name", ALL)
def test_torque_and_joint_forces_equal_numpy_newton_euler(name):
    """The virtual-power torque (res.tau) and every joint force against the numpy model's
    own square Newton-Euler solve."""
    lk, rig, res, (X, W, Ac) = case(name)
    tau = np.asarray(res.tau[:, 0])
    mine = [rig.newton_euler(*s) for s in zip(X, W, Ac)]
    t_ne = np.array([t for _, t in mine])
    assert _rel(tau - t_ne, np.max(np.abs(t_ne))) <= RTOL
    for k in range(N):
        F_ne, _ = mine[k]
        scale = max(abs(F) for F in F_ne.values())
        for x, a, b, F in _jax_forces(lk, res, k):
            ours = F_ne[x] if (a, b) == next((aa, bb) for xx, aa, bb in rig.joints if xx == x) else -F_ne[x]
            assert abs(F - ours) <= RTOL * scale, (k, x, abs(F - ours) / scale)


def test_reaction_by_name():
    lk, rig, res, _ = case("watt")
    np.testing.assert_array_equal(np.asarray(res.reaction("B")), np.asarray(res.joints["B"]))
    assert res.reaction("B").shape == (N,)
    for x in lk.joints:
        np.testing.assert_array_equal(np.asarray(res.reaction(x)), np.asarray(res.joints[x]))
    with pytest.raises(ValueError):
        res.reaction("nope")


# --------------------------------------------------------------------------- hand-written models
def _watt_hand():
    """The Watt I six-bar's two complex loops written by hand (closing at B and at C), and a
    Model with its five bodies (no joints): the loops' multipliers are the reactions."""
    rig = Rigid(WATT)
    P = rig.P0
    ang = lambda d, e: float(np.angle(P[d] - P[e]))  # noqa: E731
    geo = dict(a=abs(P["A"] - P["O2"]), b=abs(P["B"] - P["A"]), e=abs(P["E"] - P["A"]), be=ang("E", "A") - ang("B", "A"),
               c=abs(P["B"] - P["O4"]), f=abs(P["F"] - P["O4"]), ga=ang("F", "O4") - ang("B", "O4"),
               l5=abs(P["C"] - P["E"]), l6=abs(P["C"] - P["F"]), x4=P["O4"].real, y4=P["O4"].imag)
    assert P["O2"] == 0

    def loops(q, u, p):
        A = p.a * jm.cis(u.t2)
        O4 = p.x4 + 1j * p.y4
        return [A + p.b * jm.cis(q.t3) - O4 - p.c * jm.cis(q.t4),
                A + p.e * jm.cis(q.t3 + p.be) + p.l5 * jm.cis(q.t5) - O4 - p.f * jm.cis(q.t4 + p.ga) - p.l6 * jm.cis(q.t6)]

    mech = jm.Mechanism(coords=("t3", "t4", "t5", "t6"), inputs=("t2",), params=tuple(geo), constraints=loops,
                        lengths=("a", "b", "e", "c", "f", "l5", "l6", "x4", "y4"), signed=("x4", "y4"), name="watt_by_hand")
    t0 = {"t2": ang("A", "O2"), "t3": ang("B", "A"), "t4": ang("B", "O4"), "t5": ang("C", "E"), "t6": ang("C", "F")}
    base = {"crank": ("O2", "t2"), "coupler": ("A", "t3"), "rocker": ("O4", "t4"), "link5": ("E", "t5"), "link6": ("F", "t6")}

    def centre(link):
        x, t = base[link]
        arm = complex(rig.G0[link] - P[x])

        def at(q, u, p):
            v = dict(t2=u.t2, t3=q.t3, t4=q.t4, t5=q.t5, t6=q.t6)
            A = p.a * jm.cis(v["t2"])
            pt = {"O2": 0.0, "A": A, "O4": p.x4 + 1j * p.y4, "E": A + p.e * jm.cis(v["t3"] + p.be),
                  "F": p.x4 + 1j * p.y4 + p.f * jm.cis(v["t4"] + p.ga)}[x]
            return pt + arm * jm.cis(v[t] - t0[t])

        return at

    bodies = [jm.Body(centre(k), f"m_{k}", angle=base[k][1], inertia=f"J_{k}", name=k) for k in rig.bodies]
    own = {**{f"m_{k}": rig.m[k] for k in rig.bodies}, **{f"J_{k}": rig.J[k] for k in rig.bodies}, "g": rig.g}
    model = jm.Model(mech, bodies=bodies, loads=[jm.Gravity()], params=tuple(own))
    return rig, model, {**geo, **own}, t0


@functools.lru_cache(maxsize=None)
def watt_hand_result():
    rig, model, p, t0 = _watt_hand()
    _, _, _, (X, W, Ac) = case("watt")
    u, ud, udd = stroke_samples(rig.u_d)
    idx = np.arange(0, N, 6)
    # the guess: the numpy model's own angles (each frame vector's rotation from the drawing)
    guess = np.stack([t0[t] + X[idx, 3 * rig.bodies.index(k) + 2] for t, k in
                      (("t3", "coupler"), ("t4", "rocker"), ("t5", "link5"), ("t6", "link6"))], axis=1)
    res = jm.inverse_dynamics_at(model, u[idx], ud[idx], udd[idx], p, guess)
    return rig, res, idx, (X, W, Ac)


def test_hand_two_loop_mechanism_reactions_by_loop():
    rig, res, idx, (X, W, Ac) = watt_hand_result()
    assert np.all(np.asarray(res.status) == 0)
    assert [n for n, _ in res.loops] == ["loop 1", "loop 2"]
    r2 = np.asarray(res.reaction("loop 2"))
    np.testing.assert_array_equal(r2, np.asarray(jax.lax.complex(res.reactions[..., 2], res.reactions[..., 3])))
    np.testing.assert_array_equal(np.asarray(res.reaction(1)), r2)
    np.testing.assert_array_equal(np.asarray(res.reaction(0)), np.asarray(res.reaction("loop 1")))
    for bad in (2, -1, "loop 3"):
        with pytest.raises(ValueError):
            res.reaction(bad)
    # the multipliers are the cut joints' forces: loop 1 (closing at B) the coupler's force on
    # the rocker, loop 2 (closing at C) link5's on link6; the torque is the crank torque
    r1 = np.asarray(res.reaction("loop 1"))
    for n, k in enumerate(idx):
        F, tau = rig.newton_euler(X[k], W[k], Ac[k])
        scale = max(abs(v) for v in F.values())
        assert abs(r1[n] - F["B"]) <= RTOL * scale  # joint B: (coupler, rocker)
        assert abs(r2[n] - F["C"]) <= RTOL * scale  # joint C: (link5, link6)
        assert abs(float(res.tau[n, 0]) - tau) <= RTOL * abs(tau)


def test_hand_two_loop_mechanism_matches_linkage():
    """The hand-written loops and the Linkage's agree on the torque and on the forces at B and C."""
    rig, res, idx, _ = watt_hand_result()
    lk, _, lres, _ = case("watt")
    tl = np.asarray(lres.tau[idx, 0])
    assert _rel(np.asarray(res.tau[:, 0]) - tl, np.max(np.abs(tl))) <= RTOL
    scale = np.max([np.abs(np.asarray(v)[idx]) for v in lres.joints.values()], axis=0)
    assert np.max(np.abs(np.asarray(res.reaction("loop 1")) - np.asarray(lres.joints["B"])[idx]) / scale) <= RTOL
    assert np.max(np.abs(np.asarray(res.reaction("loop 2")) - np.asarray(lres.joints["C"])[idx]) / scale) <= RTOL


def _fourbar_hand():
    """The four-bar written by hand: Mechanism, Model with a Body per link and every joint."""
    rig = Rigid(FOUR)
    P = rig.P0
    t3_0 = float(np.angle(P["B"] - P["A"]))
    arm3 = rig.G0["coupler"] - P["A"]
    geo = dict(a=abs(P["A"] - P["O2"]), b=abs(P["B"] - P["A"]), c=abs(P["B"] - P["O4"]), x2=P["O2"].real, y2=P["O2"].imag,
               x4=P["O4"].real, y4=P["O4"].imag, r3=abs(arm3), d3=float(np.angle(arm3)) - t3_0)
    O2 = lambda q, u, p: p.x2 + 1j * p.y2  # noqa: E731
    O4 = lambda q, u, p: p.x4 + 1j * p.y4  # noqa: E731
    A = lambda q, u, p: O2(q, u, p) + p.a * jm.cis(u.theta2)  # noqa: E731
    points = {"O2": O2, "A": A, "B": lambda q, u, p: O4(q, u, p) + p.c * jm.cis(q.theta4), "O4": O4,
              "G2": lambda q, u, p: O2(q, u, p) + 0.5 * p.a * jm.cis(u.theta2),
              "G3": lambda q, u, p: A(q, u, p) + p.r3 * jm.cis(q.theta3 + p.d3),
              "G4": lambda q, u, p: O4(q, u, p) + 0.5 * p.c * jm.cis(q.theta4)}
    mech = jm.Mechanism(coords=("theta3", "theta4"), inputs=("theta2",), params=tuple(geo), points=points,
                        constraints=lambda q, u, p: [A(q, u, p) + p.b * jm.cis(q.theta3) - O4(q, u, p) - p.c * jm.cis(q.theta4)],
                        lengths=("a", "b", "c", "x2", "y2", "x4", "y4", "r3"), signed=("x2", "y2", "x4", "y4"), name="fourbar_by_hand")
    model = jm.Model(mech, bodies=[jm.Body("G2", "m2", angle="theta2", inertia="J2", name="crank"),
                                   jm.Body("G3", "m3", angle="theta3", inertia="J3", name="coupler"),
                                   jm.Body("G4", "m4", angle="theta4", inertia="J4", name="rocker")],
                     loads=[jm.Gravity()], params=("m2", "J2", "m3", "J3", "m4", "J4", "g"),
                     joints=[jm.Revolute("O2", ("ground", "crank"), input="theta2"), jm.Revolute("A", ("crank", "coupler")),
                             jm.Revolute("B", ("coupler", "rocker")), jm.Revolute("O4", ("ground", "rocker"))])
    own = {f"{c}{i}": getattr(rig, c)[k] for i, k in ((2, "crank"), (3, "coupler"), (4, "rocker")) for c in ("m", "J")}
    return rig, model, {**geo, **own, "g": rig.g}


def test_hand_written_fourbar_model_matches_linkage():
    lk, rig, lres, (X, W, Ac) = case("fourbar")
    _, model, p = _fourbar_hand()
    u, ud, udd = (np.asarray(a[:, 0]) for a in (lres.u, lres.u_dot, lres.u_ddot))
    np.testing.assert_array_equal(u, stroke_samples(rig.u_d, 0.3)[0])  # the approach from the drawing is not in the result
    P = rig.P0
    t0 = {k: float(np.angle(P[d] - P[e])) for k, (e, d) in (("coupler", ("A", "B")), ("rocker", ("O4", "B")))}
    guess = np.stack([t0[k] + X[:, 3 * rig.bodies.index(k) + 2] for k in ("coupler", "rocker")], axis=1)
    res = jm.inverse_dynamics_at(model, u, ud, udd, p, guess)
    assert np.all(np.asarray(res.status) == 0)
    assert _rel(np.asarray(res.tau[:, 0]) - np.asarray(lres.tau[:, 0]), np.max(np.abs(np.asarray(lres.tau[:, 0])))) <= RTOL
    hand = {j.point: j.bodies for j in model.joints}
    assert set(res.joints) == set(lres.joints) == set(hand)
    scale = np.max([np.abs(np.asarray(v)) for v in lres.joints.values()], axis=0)
    for j in lk.model.joints:
        sign = 1.0 if tuple(j.bodies) == hand[j.point] else -1.0
        err = np.asarray(res.joints[j.point]) - sign * np.asarray(lres.joints[j.point])
        assert np.max(np.abs(err) / scale) <= RTOL, j.point
    # and both against the numpy model
    for k in range(N):
        F_ne, _ = rig.newton_euler(X[k], W[k], Ac[k])
        for x, a, b in rig.joints:
            ours = F_ne[x] if (a, b) == hand[x] else -F_ne[x]
            assert abs(complex(res.joints[x][k]) - ours) <= RTOL * scale[k], (k, x)


def test_link_angles_are_measured_as_drawn_whatever_the_tree():
    """``theta_<link>`` runs from the link's first listed point to its second at every sample,
    also where the equations reach the link through its second point (``"link6": "F O6"``,
    ``"coupler": "B A"``): checked against the solved points themselves."""
    pts = {"O2": (0, 0), "A": (0.5, 0.866), "B": (3.15, 2.0), "O4": (3.5, 0), "E": (4.6, 1.6), "F": (6.2, 3.2), "O6": (7.0, 1.0)}
    links = {"crank": "O2 A", "coupler": "B A", "rocker": "O4 B E", "link5": "E F", "link6": "F O6"}
    lk = jm.Linkage(points=pts, links=links, ground="O2 O4 O6", driver="crank")
    s = jnp.linspace(0.0, 2 * jnp.pi, 25)
    res = lk.inverse_dynamics(jm.Samples(1.05 + 0.8 * jnp.sin(s), 0.8 * jnp.cos(s), -0.8 * jnp.sin(s)))
    assert np.all(np.asarray(res.status) == jm.Status.CONVERGED)
    for link, names in links.items():
        if link == "crank":
            continue
        a, b = names.split()[:2]
        at = lambda x: np.asarray(res.points[x][0]) if x in res.points else complex(*pts[x])  # noqa: E731
        want = np.angle(at(b) - at(a))
        got = np.asarray(res.q[:, lk.mechanism.coords.index(f"theta_{link}")])
        np.testing.assert_allclose(np.angle(np.exp(1j * (got - want))), 0.0, atol=1e-12, err_msg=link)
