"""The per-link view of joint reactions: ``InverseDynamics.force_on(link, joint)`` and a
slider's ``normal_force(joint)``, from ``Linkage.inverse_dynamics`` and ``Linkage.statics``.

The truth is an independent numpy model of an offset slider-crank on a guide inclined at
20 deg, with masses, gravity, a gas force on the piston and a moment on the rod: its
kinematics in closed form (positions by the triangle, velocities and accelerations from the
differentiated loop written by hand), its forces from the square per-body Newton-Euler
system written here, unknowns in the per-link convention (the force on each link at each
joint).  The same physical motion (the crank rocking) is driven twice: by the crank (a
torque) and by the piston (a force along the guide, which ``force_on`` includes).  Statics
of an actuator and a slot linkage are checked against each link's own balance.
"""

import jax

jax.config.update("jax_enable_x64", True)

import cmath  # noqa: E402
import math  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402

RTOL = 1e-10
R, L, OFF = 0.1, 0.35, 0.03  # m: crank, rod, the guide's offset from the crank's pivot
BETA = math.radians(20.0)  # the guide's direction
ROT = cmath.exp(1j * BETA)  # guide frame -> global
M2, M3, M4, G = 0.3, 0.8, 0.5, 9.81  # kg, m/s^2
F_GAS = complex(-1500.0, 400.0)  # N, global, on the piston
M_ROD = 3.0  # N m, CCW on the rod
TH0, AMP, W = math.radians(60.0), math.radians(50.0), 7.0  # crank (guide frame): th0 + AMP sin(W t)
T = np.linspace(0.0, 2 * np.pi / W, 41)


def cross(r, f):
    return (np.conj(r) * f).imag


def kinematics(t):
    """The crank's motion in the guide's frame (x along the guide, through (0, OFF)), and
    the rod and piston's, rotated to global: ``dict`` of complex positions and
    accelerations, the angles' rates, and the piston's travel and its rates along the guide."""
    th, thd, thdd = TH0 + AMP * np.sin(W * t), AMP * W * np.cos(W * t), -AMP * W * W * np.sin(W * t)
    phi = np.arcsin((OFF - R * np.sin(th)) / L)  # the rod's direction from A to B (local)
    phd = -R * thd * np.cos(th) / (L * np.cos(phi))
    phdd = (-R * thdd * np.cos(th) + R * thd**2 * np.sin(th) + L * phd**2 * np.sin(phi)) / (L * np.cos(phi))
    x = R * np.cos(th) + L * np.cos(phi)
    xd = -R * thd * np.sin(th) - L * phd * np.sin(phi)
    xdd = -R * thdd * np.sin(th) - R * thd**2 * np.cos(th) - L * phdd * np.sin(phi) - L * phd**2 * np.cos(phi)
    A = R * np.exp(1j * th)
    aA = (1j * thdd - thd**2) * A
    rod = L * np.exp(1j * phi)
    k = dict(A=A, B=x + 1j * OFF, G2=A / 2, G3=A + rod / 2, aG2=aA / 2, aG3=aA + (1j * phdd - phd**2) * rod / 2, aB=xdd + 0j)
    k = {n: ROT * v for n, v in k.items()}
    return dict(k, th=th + BETA, thd=thd, thdd=thdd, phdd=phdd, s=x - x[0], sd=xd, sdd=xdd)


def newton_euler(k, i, crank_driven):
    """At sample i: ``{(link, joint): force on the link}`` (N, complex) and the drive's
    effort, from the 9 x 9 Newton-Euler system of the three links.  Unknowns: the ground's
    force on the crank at O2, the crank's on the rod at A, the rod's on the piston at B, the
    guide's normal force (along i ROT) and moment on the piston, and the drive's effort (a
    torque on the crank, or a force on the piston along ROT)."""
    A, B, G2, G3 = k["A"][i], k["B"][i], k["G2"][i], k["G3"][i]
    n = 1j * ROT
    rows, rhs = [], []

    def body(force_cols, moment_cols, force_known, moment_known):
        f = np.zeros(9, complex)
        for c, v in force_cols:
            f[c] += v
        m = np.zeros(9)
        for c, v in moment_cols:
            m[c] += v
        rows.extend([f.real, f.imag, m])
        rhs.extend([force_known.real, force_known.imag, moment_known])

    fo2 = [(0, 1.0), (1, 1j)]
    fa = [(2, 1.0), (3, 1j)]
    fb = [(4, 1.0), (5, 1j)]
    arm = lambda r, cols, s=1.0: [(c, s * cross(r, v)) for c, v in cols]  # noqa: E731
    neg = lambda cols: [(c, -v) for c, v in cols]  # noqa: E731
    body(fo2 + neg(fa), arm(-G2, fo2) + arm(A - G2, fa, -1.0) + ([(8, 1.0)] if crank_driven else []),
         M2 * k["aG2"][i] + 1j * M2 * G, M2 * R * R / 12 * k["thdd"][i])
    body(fa + neg(fb), arm(A - G3, fa) + arm(B - G3, fb, -1.0), M3 * k["aG3"][i] + 1j * M3 * G,
         M3 * L * L / 12 * k["phdd"][i] - M_ROD)
    body(fb + [(6, n)] + ([] if crank_driven else [(8, ROT)]), [(7, 1.0)], M4 * k["aB"][i] + 1j * M4 * G - F_GAS, 0.0)
    x = np.linalg.solve(np.array(rows), np.array(rhs))
    F_O2, F_A, F_B = x[0] + 1j * x[1], x[2] + 1j * x[3], x[4] + 1j * x[5]
    guide = x[6] * n + (0.0 if crank_driven else x[8] * ROT)
    forces = {("crank", "O2"): F_O2, ("ground", "O2"): -F_O2, ("crank", "A"): -F_A, ("rod", "A"): F_A,
              ("rod", "B"): -F_B, ("piston", "B"): F_B, ("piston", "piston on ground"): guide,
              ("ground", "piston on ground"): -guide}
    return forces, x[8], x[6]


def slider_crank(crank_driven):
    k = kinematics(np.zeros(1))
    pts = {"O2": (0.0, 0.0), "A": (k["A"][0].real, k["A"][0].imag), "B": (k["B"][0].real, k["B"][0].imag)}
    return jm.Linkage(points=pts, links={"crank": "O2 A", "rod": "A B", "piston": "B"}, ground="O2",
                      driver="crank" if crank_driven else "piston", sliders={"piston": {"angle": BETA}},
                      mass={"crank": M2, "rod": M3, "piston": M4}, gravity=G,
                      forces={"B": {"force": (F_GAS.real, F_GAS.imag), "on": "piston"}}, moments={"rod": M_ROD})


@pytest.fixture(scope="module", params=["crank", "piston"])
def driven(request):
    crank_driven = request.param == "crank"
    lk, k = slider_crank(crank_driven), kinematics(T)
    s = jm.Samples(k["th"], k["thd"], k["thdd"], t=T) if crank_driven else jm.Samples(k["s"], k["sd"], k["sdd"], t=T)
    res = lk.inverse_dynamics(s)
    assert jm.status_counts(res.status) == {"CONVERGED": len(T)}
    return crank_driven, lk, k, res


def test_force_on_each_link_equals_numpy_newton_euler(driven):
    crank_driven, lk, k, res = driven
    np.testing.assert_allclose(np.asarray(res.points["B"][0]), k["B"], rtol=0, atol=1e-12)  # the same motion
    for i in range(len(T)):
        forces, effort, normal = newton_euler(k, i, crank_driven)
        scale = max(abs(f) for f in forces.values())
        for (link, joint), want in forces.items():
            got = complex(res.force_on(link, joint)[i])
            assert abs(got - want) <= RTOL * scale, (i, link, joint, got, want)
        assert abs(float(res.tau[i, 0]) - effort) <= RTOL * max(abs(effort), scale * R)
        assert abs(float(res.normal_force("piston on ground")[i]) - normal) <= RTOL * scale


def test_newtons_third_law_at_every_joint(driven):
    _, lk, _, res = driven
    assert {j.joint for j in res.joint_bodies} == set(lk.joints)
    for j in res.joint_bodies:
        np.testing.assert_array_equal(np.asarray(res.force_on(j.first, j.joint)), -np.asarray(res.force_on(j.second, j.joint)))
    drive = [j for j in res.joint_bodies if j.drive >= 0]
    assert [j.joint for j in drive] == ([] if driven[0] else ["piston on ground"])


def test_refusals_name_the_joint(driven):
    _, _, _, res = driven
    with pytest.raises(ValueError, match=r"joint 'B' joins 'rod' and 'piston'; ask for the force on one of them"):
        res.force_on("crank", "B")
    with pytest.raises(ValueError, match=r"no joint named 'C'; joints are \["):
        res.force_on("crank", "C")
    with pytest.raises(ValueError, match=r"'A' is not a slider or a slot; they are \['piston on ground'\]"):
        res.normal_force("A")


def test_statics_of_an_actuator_and_a_slot_balance_each_link():
    """At rest: the forces on each link through its joints balance its weight and loads (and
    their moments about a pivot); a slot's force is along its normal, its size the
    normal force."""
    boom = jm.Linkage(points={"O": (0.0, 0.0), "P": (1.0, 0.3), "C": (0.3, -0.4), "T": (2.5, 0.8)},
                      links={"boom": "O P T"}, ground="O C", actuators={"cyl": ("C", "P")}, driver="cyl",
                      mass={"boom": 50.0}, centre={"boom": (1.2, 0.35)}, gravity=9.81, forces={"T": (0.0, -1000.0)})
    res = boom.statics(boom.input_at_drawing)
    loads = -50.0 * 9.81j - 1000j
    on_boom = complex(res.force_on("boom", "O")[0]), complex(res.force_on("boom", "cyl")[0])
    assert abs(sum(on_boom) + loads) <= RTOL * 1000
    assert abs(cross(1.0 + 0.3j, on_boom[1]) + cross(1.2 + 0.35j, -50.0 * 9.81j) + cross(2.5 + 0.8j, -1000j)) <= RTOL * 2500
    assert abs(complex(res.force_on("ground", "cyl")[0]) + on_boom[1]) == 0.0

    qr = jm.Linkage(points={"O2": (0.0, 0.3), "A": (0.1, 0.3), "O4": (0.0, 0.0), "C": (0.0, 0.6)},
                    links={"crank": "O2 A", "rocker": "O4 C"}, ground="O2 O4", driver="crank",
                    slots={"A": {"on": "rocker", "angle": math.atan2(0.3, 0.1)}}, moments={"rocker": -5.0})
    u = np.radians([0.0, 90.0])
    res, sol = qr.statics(u), qr.solve(u)
    for i in range(2):
        slot = complex(res.force_on("rocker", "A in rocker")[i])
        assert abs(slot + complex(res.force_on("rocker", "O4")[i])) <= RTOL * abs(slot)
        arm = complex(res.points["A"][0][i]) - complex(res.points["O4"][0][i])
        assert abs(cross(arm, slot) - 5.0) <= RTOL * 5.0
        # the slot turns with the rocker: drawn at atan2(0.3, 0.1), the rocker at 90 deg
        n = 1j * np.exp(1j * (float(sol["theta_rocker"][i]) + math.atan2(0.3, 0.1) - math.pi / 2))
        N = float(res.normal_force("A in rocker")[i])
        assert abs(-slot - N * n) <= RTOL * abs(slot)  # the rocker's force on the pin: N along n
