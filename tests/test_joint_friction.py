"""Joint friction (``Linkage(friction=...)``) against independent models written here in
numpy (no jaxmech code):

- an offset slider-crank with Coulomb friction at its three pins (friction circles) and at
  the guide, driven back and forth through two reversals: the per-body Newton-Euler
  equations with the friction loads written out, solved per sample by a numpy Newton
  (finite-difference Jacobian), the sign regularised as documented (``tanh(w / (width W))``,
  ``W`` the joint's largest speed over the stroke): the crank torque, every joint's force
  and the guide's normal force;
- the friction's dissipation at each joint against the drive's extra power (virtual power:
  ideal joints do no work, so ``(tau - tau_0) omega = sum mu r |F| |w|``);
- statics with friction (``holding``): the efforts driving on and holding back against
  the same numpy equations at rest with the senses of motion given;
- a pin in a circular slot of the frame with friction at both pins and in the slot
  (quasi-static, back and forth): the crank torque, the pins' forces and the slot's normal force;
- a screw jack unrolled as a wedge (a load on a vertical guide, its pin in a slot of a
  block sliding on a horizontal guide, the slot at the lead angle) with friction in the
  slot: ``ScrewJack``'s raise and lower torques and its self-locking;
- friction zero (or absent): bit for bit the frictionless results;
- the derivative of the peak crank torque in a friction coefficient, a pin radius and the
  rod's length against central differences;
- a wedge jammed by friction (no driving effort, self-locking), bad input; a linkage with
  friction made a scene carries its friction (``tests/test_friction_scenes.py`` runs it).
"""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from helpers import central_diff  # noqa: E402

import jaxmech as jm  # noqa: E402

TOL = 1e-10  # relative to the largest value of the quantity over the stroke

# Crank O-A (r), rod A-B (l), block at B on the line y = e; uniform bars, the block a point
# mass at B; a force on the block.
R, L, E = 0.12, 0.40, 0.03
SM = {"crank": 1.2, "rod": 2.5, "block_B": 0.8}
G = 9.81
LOAD = -300.0 + 50.0j
TH0 = 1.0
T = np.linspace(0.0, np.pi, 41)
MU = {"O": 0.10, "A": 0.12, "B": 0.20, "guide": 0.15}
RPIN = {"O": 0.010, "A": 0.008, "B": 0.012}
WIDTH = 1e-3
FRICTION = {"all": {"mu": 0.1, "radius": "10 mm"}, "A": {"mu": MU["A"], "radius": "8 mm"},
            "B": {"mu": MU["B"], "radius": "12 mm"}, "block_B": {"mu": MU["guide"]}, "width": WIDTH}


def cross(r, f):
    return (np.conj(r) * f).imag


def drive(t):
    """The crank's angle, speed and acceleration: back and forth, reversing at t = pi/4, 3pi/4."""
    return TH0 + 1.2 * np.sin(2 * t), 2.4 * np.cos(2 * t), -4.8 * np.sin(2 * t)


def slider_kinematics(th):
    """``A``, ``B`` (complex) and the rod's angle ``phi``, each as ``(x, dx/dth, d2x/dth2)``."""
    s, s1, s2 = R * np.sin(th) - E, R * np.cos(th), -R * np.sin(th)
    w = np.sqrt(L * L - s * s)
    w1 = -s * s1 / w
    w2 = -(s1 * s1 + s * s2) / w - (s * s1) ** 2 / w**3
    a = (R * np.exp(1j * th), 1j * R * np.exp(1j * th), -R * np.exp(1j * th))
    b = (R * np.cos(th) + w + 1j * E, -R * np.sin(th) + w1 + 0j, -R * np.cos(th) + w2 + 0j)
    phi = (np.arctan2(-s, w), -s1 / w, -(s2 * w - s1 * w1) / w**2)
    return a, b, phi


def motion_at(th, om, al):
    a, b, phi = slider_kinematics(th)
    acc = lambda x: x[2] * om**2 + x[1] * al  # noqa: E731
    mid = tuple(0.5 * (p + q) for p, q in zip(a, b))
    half = tuple(0.5 * p for p in a)
    return dict(A=a[0], B=b[0], vB=b[1] * om, G={"crank": half[0], "rod": mid[0], "block_B": b[0]},
                aG={"crank": acc(half), "rod": acc(mid), "block_B": acc(b)}, om=om, w3=phi[1] * om, al=al, al3=phi[2] * om**2 + phi[1] * al)


def speeds(mo):
    """Each joint's relative speed: the pins' ``omega_b - omega_a`` (rad/s), the block's along the guide (m/s)."""
    return {"O": mo["om"], "A": mo["w3"] - mo["om"], "B": -mo["w3"], "guide": mo["vB"].real}


def linear_system(mo):
    """The frictionless per-body system ``(m, rhs)`` in ``F_O, F_A, F_B`` (each on the second
    body: crank, rod, block), the guide's normal force ``N`` (+y), its moment and the torque."""
    J = {"crank": SM["crank"] * R * R / 12, "rod": SM["rod"] * L * L / 12}
    A, B, G_, aG = mo["A"], mo["B"], mo["G"], mo["aG"]
    gv = -1j * G
    m, rhs = np.zeros((9, 9)), np.zeros(9)

    def pin(row, col, sign, at, centre):
        m[row, col] += sign
        m[row + 1, col + 1] += sign
        r = at - centre
        m[row + 2, col] += -sign * r.imag
        m[row + 2, col + 1] += sign * r.real

    pin(0, 0, 1, 0j, G_["crank"])
    pin(0, 2, -1, A, G_["crank"])
    m[2, 8] = 1.0
    rhs[0:3] = [SM["crank"] * (aG["crank"] - gv).real, SM["crank"] * (aG["crank"] - gv).imag, J["crank"] * mo["al"]]
    pin(3, 2, 1, A, G_["rod"])
    pin(3, 4, -1, B, G_["rod"])
    rhs[3:6] = [SM["rod"] * (aG["rod"] - gv).real, SM["rod"] * (aG["rod"] - gv).imag, J["rod"] * mo["al3"]]
    pin(6, 4, 1, B, G_["block_B"])
    m[7, 6] += 1.0
    m[8, 7] = 1.0
    applied = SM["block_B"] * gv + LOAD
    rhs[6:9] = [SM["block_B"] * aG["block_B"].real - applied.real, SM["block_B"] * aG["block_B"].imag - applied.imag, 0.0]
    return m, rhs


def friction_loads(x, sg, visc=None):
    """The friction loads in the nine body equations (force x, y, moment per body) for the
    unknowns `x` and the signs `sg`: the friction circles' moments and the guide's force;
    `visc` ``{joint: c w}`` viscous terms added to them (N m at a pin, N in the guide)."""
    visc = visc or {}
    mag = {"O": abs(x[0] + 1j * x[1]), "A": abs(x[2] + 1j * x[3]), "B": abs(x[4] + 1j * x[5])}
    mom = {k: -MU[k] * RPIN[k] * mag[k] * sg[k] - visc.get(k, 0.0) for k in mag}  # on each pin's second body
    f_guide = -MU["guide"] * abs(x[6]) * sg["guide"] - visc.get("guide", 0.0)  # along +x on the block, at B
    out = np.zeros(9)
    out[2] = mom["O"] - mom["A"]
    out[5] = mom["A"] - mom["B"]
    out[6] = f_guide
    out[8] = mom["B"]
    return out


def solve_with_friction(m, rhs, sg, visc=None):
    """``m x + friction(x) = rhs`` by Newton's method (finite-difference Jacobian), from the frictionless ``x``."""
    x = np.linalg.solve(m, rhs)
    f = lambda y: m @ y + friction_loads(y, sg, visc) - rhs  # noqa: E731
    for _ in range(30):
        r = f(x)
        if np.max(np.abs(r)) <= 1e-14 * np.max(np.abs(rhs)):
            break
        jac = np.stack([(f(x + h) - f(x - h)) / 2e-7 for h in 1e-7 * np.eye(9)], axis=1)
        x = x - np.linalg.solve(jac, r)
    assert np.max(np.abs(f(x))) <= 1e-12 * np.max(np.abs(rhs))
    return x


def regularised_signs(motions):
    """Each sample's ``tanh(w / (width W))``, ``W`` the joint's largest ``|w|`` over the samples."""
    w = [speeds(mo) for mo in motions]
    scale = {k: max(abs(x[k]) for x in w) for k in w[0]}
    return [{k: np.tanh(x[k] / (WIDTH * scale[k])) for k in x} for x in w]


def linkage(**kw):
    a, b, _ = slider_kinematics(TH0)
    pts = {"O": (0, 0), "A": (a[0].real, a[0].imag), "B": (b[0].real, b[0].imag)}
    return jm.Linkage(points=pts, links={"crank": "O A", "rod": "A B"}, ground="O", driver="crank", sliders={"B": {"angle": 0.0}},
                      mass=SM, gravity=G, forces={"B": {"force": (LOAD.real, LOAD.imag), "on": "block_B"}}, **kw)


def samples():
    return jm.Samples(*drive(T), T)


def test_slider_crank_with_friction_everywhere_against_newton_euler():
    lk = linkage(friction=FRICTION)
    assert lk.params["mu_O"] == MU["O"] and lk.params["rpin_A"] == RPIN["A"] and lk.params["mu_block_B"] == MU["guide"]
    res = lk.inverse_dynamics(samples())
    assert np.all(np.asarray(res.status) == jm.Status.CONVERGED)
    motions = [motion_at(*drive(t)) for t in T]
    signs = regularised_signs(motions)
    xs = np.array([solve_with_friction(*linear_system(mo), sg) for mo, sg in zip(motions, signs)])
    # the reversals lie inside the band, every other sample outside it (the signs are +-1 there)
    pure = np.array([all(abs(abs(s) - 1.0) < 1e-15 for s in sg.values()) for sg in signs])
    assert 30 <= pure.sum() < len(T)
    tau = xs[:, 8]
    np.testing.assert_allclose(np.asarray(res.tau[:, 0]), tau, rtol=0, atol=TOL * np.max(np.abs(tau)))
    for joint, link, col in (("O", "crank", 0), ("A", "rod", 2), ("B", "block_B", 4)):
        want = xs[:, col] + 1j * xs[:, col + 1]
        np.testing.assert_allclose(np.asarray(res.force_on(link, joint)), want, rtol=0, atol=TOL * np.max(np.abs(want)))
    normal = xs[:, 6]
    np.testing.assert_allclose(np.asarray(res.normal_force("block_B on ground")), normal, rtol=0, atol=TOL * np.max(np.abs(normal)))
    # the guide's whole force on the block: its friction along +x and its normal force along +y
    guide = np.array([friction_loads(x, sg)[6] for x, sg in zip(xs, signs)]) + 1j * normal
    np.testing.assert_allclose(np.asarray(res.force_on("block_B", "block_B on ground")), guide, rtol=0, atol=TOL * np.max(np.abs(guide)))
    # friction changes the torque by far more than the tolerance, with the sign of the crank's speed
    bare = linkage().inverse_dynamics(samples())
    extra = np.asarray(res.tau[:, 0] - bare.tau[:, 0])
    om = np.array([mo["om"] for mo in motions])
    assert np.max(np.abs(extra)) > 1e-2 * np.max(np.abs(tau))
    assert np.all(extra[pure] * om[pure] > 0)
    # the jump across a reversal: the friction torque changes sign between neighbouring samples
    k = int(np.argmin(np.abs(T - np.pi / 4)))
    assert extra[k - 1] * extra[k + 1] < 0 and abs(extra[k]) < 1e-9 * np.max(np.abs(extra))


def test_viscous_joint_damping_with_friction_against_newton_euler():
    """Damping ``c w`` at pin A (N m s/rad) and in the guide (N s/m) on top of the Coulomb terms."""
    c_pin, c_guide = 0.8, 40.0
    lk = linkage(friction={**FRICTION, "A": {**FRICTION["A"], "damping": "0.8 N m s/rad"}, "block_B": {"mu": MU["guide"], "damping": c_guide}})
    assert lk.params["cv_A"] == c_pin and lk.params["cv_block_B"] == c_guide
    res = lk.inverse_dynamics(samples())
    motions = [motion_at(*drive(t)) for t in T]
    visc = [{"A": c_pin * speeds(mo)["A"], "guide": c_guide * speeds(mo)["guide"]} for mo in motions]
    xs = np.array([solve_with_friction(*linear_system(mo), sg, v) for mo, sg, v in zip(motions, regularised_signs(motions), visc)])
    tau = xs[:, 8]
    np.testing.assert_allclose(np.asarray(res.tau[:, 0]), tau, rtol=0, atol=TOL * np.max(np.abs(tau)))
    for joint, link, col in (("O", "crank", 0), ("A", "rod", 2), ("B", "block_B", 4)):
        want = xs[:, col] + 1j * xs[:, col + 1]
        np.testing.assert_allclose(np.asarray(res.force_on(link, joint)), want, rtol=0, atol=TOL * np.max(np.abs(want)))
    # the damping takes part: without it the torque differs by more than the tolerance
    plain = lk.inverse_dynamics(samples(), p={"cv_A": 0.0, "cv_block_B": 0.0})
    assert np.max(np.abs(np.asarray(plain.tau[:, 0]) - tau)) > 1e-3 * np.max(np.abs(tau))


def test_friction_dissipation_is_the_drives_extra_power():
    """Ideal joints do no work: the drive's extra power with friction is what friction
    dissipates, ``sum_j mu_j r_j |F_j| w_j tanh(w_j / (width W_j))`` (plus ``mu |N| v ...``
    at the guide), from jaxmech's own joint forces and the kinematics written here."""
    lk = linkage(friction=FRICTION)
    res, bare = lk.inverse_dynamics(samples()), linkage().inverse_dynamics(samples())
    motions = [motion_at(*drive(t)) for t in T]
    signs = regularised_signs(motions)
    mag = {j: np.abs(np.asarray(res.joints[j])) for j in ("O", "A", "B")}
    mag["guide"] = np.abs(np.asarray(res.normal_force("block_B on ground")))
    arm = {**RPIN, "guide": 1.0}
    lost = np.array([sum(MU[k] * arm[k] * mag[k][i] * sg[k] * speeds(mo)[k] for k in MU) for i, (mo, sg) in enumerate(zip(motions, signs))])
    extra = np.asarray(res.tau[:, 0] - bare.tau[:, 0]) * np.array([mo["om"] for mo in motions])
    assert np.all(lost >= 0)
    np.testing.assert_allclose(extra, lost, rtol=0, atol=TOL * np.max(np.abs(np.asarray(res.tau[:, 0]) * 2.4)))
    f = res.joint_friction  # each joint's friction load, the same as the law with jaxmech's forces
    np.testing.assert_allclose(np.asarray(f["A"]), -MU["A"] * RPIN["A"] * mag["A"] * np.array([sg["A"] for sg in signs]), rtol=0,
                               atol=1e-12 * np.max(mag["A"]))


def test_holding_efforts_against_newton_euler_at_rest():
    lk = linkage(friction=FRICTION)
    th = np.linspace(0.4, 1.4, 6)  # the rod turns one way, the block moves one way: no joint at rest
    h = lk.holding(th)
    up, back = [], []
    for x in th:
        m, rhs = linear_system(motion_at(x, 0.0, 0.0))
        sense = speeds(motion_at(x, 1.0, 0.0))  # the senses of motion per unit crank speed
        assert min(abs(v) for v in sense.values()) > 0.05
        up.append(solve_with_friction(m, rhs, {k: np.sign(v) for k, v in sense.items()})[8])
        back.append(solve_with_friction(m, rhs, {k: -np.sign(v) for k, v in sense.items()})[8])
    up, back = np.array(up), np.array(back)
    scale = np.max(np.abs(up))
    np.testing.assert_allclose(np.asarray(h.up.tau[:, 0]), up, rtol=0, atol=TOL * scale)
    np.testing.assert_allclose(np.asarray(h.back.tau[:, 0]), back, rtol=0, atol=TOL * scale)
    assert np.all(back < up)
    np.testing.assert_array_equal(np.asarray(h.self_locking), (back <= 0) & (up >= 0))


@pytest.mark.parametrize(("f", "thread_angle"), [(0.15, 0.0), (0.08, np.radians(14.5)), (0.03, 0.0)])
def test_screw_jack_as_a_wedge_with_slot_friction(f, thread_angle):
    """A screw's thread unrolled is a wedge at the lead angle ``tan(lambda) = l / (pi d_m)``:
    the load's pin in a slot of a block driven horizontally, friction ``f sec(alpha)`` in
    the slot; the block's force times ``d_m / 2`` is the screw's torque."""
    lead, dm, load = 0.006, 0.030, 5000.0
    lam = np.arctan(lead / (np.pi * dm))
    lk = jm.Linkage(points={"W": (0, 0), "P": (0.05, 0.02)}, links={}, driver="W",
                    sliders={"W": {"angle": 0.0}, "P": {"angle": np.pi / 2}}, slots={"P": {"on": "block_W", "angle": np.pi - lam}},
                    forces={"P": {"force": (0.0, -load), "on": "block_P"}}, friction={"P": {"mu": f / np.cos(thread_angle)}})
    h = lk.holding(np.linspace(0.0, 0.01, 3))
    jack = jm.ScrewJack(lead=lead, mean_diameter=dm, friction=f, thread_angle=thread_angle)
    raise_t, lower_t = float(jack.raise_torque(load, {})), float(jack.lower_torque(load, {}))
    np.testing.assert_allclose(np.asarray(h.up.tau[:, 0]) * dm / 2, raise_t, rtol=1e-12)
    np.testing.assert_allclose(-np.asarray(h.back.tau[:, 0]) * dm / 2, lower_t, rtol=1e-12)
    assert np.all(np.asarray(h.self_locking) == bool(jack.self_locking({})))


def test_zero_friction_is_bit_for_bit_no_friction():
    bare = linkage().inverse_dynamics(samples())
    lk = linkage(friction=FRICTION)
    zero = lk.inverse_dynamics(samples(), p={n: 0.0 for n in lk.params if n.startswith("mu_")})
    assert np.array_equal(np.asarray(zero.tau), np.asarray(bare.tau))
    for j in bare.joints:
        assert np.array_equal(np.asarray(zero.joints[j]), np.asarray(bare.joints[j])), j
    for j in bare.joint_moments:
        assert np.array_equal(np.asarray(zero.joint_moments[j]), np.asarray(bare.joint_moments[j])), j
    assert np.array_equal(np.asarray(zero.reactions), np.asarray(bare.reactions))
    # an empty friction table is no friction: the frictionless program itself
    assert linkage(friction={}).friction is None and linkage(friction=None).params == linkage().params


def test_statics_at_rest_with_friction_is_the_frictionless_effort():
    """At rest there is no sense of motion: friction's sign is zero, so ``statics`` gives the
    frictionless effort exactly (``holding`` gives the band around it)."""
    th = np.linspace(0.4, 1.4, 4)
    with_friction, bare = linkage(friction=FRICTION).statics(th), linkage().statics(th)
    assert np.array_equal(np.asarray(with_friction.tau), np.asarray(bare.tau))
    assert np.all(np.asarray(with_friction.joint_friction["B"]) == 0.0)


@pytest.mark.parametrize(("name", "value", "h"), [("mu_B", MU["B"], 1e-3), ("rpin_A", RPIN["A"], 1e-4), ("len_A_B", L, 1e-4)])
def test_gradient_of_the_peak_effort_in_friction_against_central_differences(name, value, h):
    lk = linkage(friction=FRICTION)
    s = samples()

    def peak(x):
        return jnp.max(lk.inverse_dynamics(s, p={name: x}).tau[:, 0])

    grad = float(jax.grad(peak)(value))
    fd = float(central_diff(lambda x: float(peak(x)), value, h=h))
    assert abs(grad - fd) <= 1e-7 * abs(fd) and abs(fd) > 1e-3


@pytest.mark.parametrize(("friction", "words"), [
    ({"Q": {"mu": 0.1}}, "'Q' is not a pin, slider or slot"),
    ({"A": {"mu": 0.1}}, "needs its radius"),
    ({"block_B": {"mu": 0.1, "radius": 0.01}}, "has no pin radius"),
    ({"all": {"mu": -0.1, "radius": 0.01}}, "mu must not be negative"),
    ({"all": {"mu": 0.1, "radius": 0.01, "rad": 1}}, "unknown key(s) ['rad']"),
    ({"all": {"mu": 0.1, "radius": 0.01}, "width": 2.0}, "width=2.0"),
])
def test_bad_friction_is_refused_naming_the_fix(friction, words):
    with pytest.raises(ValueError, match=None) as err:
        linkage(friction=friction)
    assert words in str(err.value)


def test_a_scene_of_a_linkage_with_friction_carries_its_friction():
    scene = linkage(friction=FRICTION).scene()
    names = [k for k in scene.defaults if k.startswith(("mu_", "rpin_", "cv_"))]
    assert names and all(scene.parameters[k][1] == "joint friction" for k in names)
    assert scene.outputs.status  # its outputs mark the samples friction jams
    bare = linkage().scene()  # without friction, as before: no friction parameter, no status of its own
    assert not bare.outputs.status and not any(k.startswith(("mu_", "rpin_", "cv_")) for k in bare.defaults)


def test_a_wedge_jammed_by_friction_has_no_driving_effort():
    """A wedge at 40 degrees with ``mu = 1.5`` (friction angle 56.3 degrees): ``lambda + phi >
    90`` degrees, no force drives it on (the friction's Newton has no root: ``MAX_STEPS``, NaN),
    while holding it back takes ``W tan(lambda - phi)``; with ``mu = 0.5`` it moves at ``W tan(lambda + phi)``."""
    lam, load = np.radians(40.0), 1000.0

    def wedge(mu):
        return jm.Linkage(points={"W": (0, 0), "P": (0.05, 0.02)}, links={}, driver="W",
                          sliders={"W": {"angle": 0.0}, "P": {"angle": np.pi / 2}}, slots={"P": {"on": "block_W", "angle": np.pi - lam}},
                          forces={"P": {"force": (0.0, -load), "on": "block_P"}}, friction={"P": {"mu": mu}}).holding([0.0, 0.01])

    moving, jammed = wedge(0.5), wedge(1.5)
    np.testing.assert_allclose(np.asarray(moving.up.tau[:, 0]), load * np.tan(lam + np.arctan(0.5)), rtol=1e-12)
    assert np.all(np.asarray(moving.up.status) == jm.Status.CONVERGED)
    assert np.all(np.asarray(jammed.up.status) == jm.Status.MAX_STEPS) and np.all(np.isnan(np.asarray(jammed.up.tau)))
    np.testing.assert_allclose(np.asarray(jammed.back.tau[:, 0]), load * np.tan(lam - np.arctan(1.5)), rtol=1e-12)
    # released, the jammed wedge stays put (it cannot go on, and must be pulled back): self-locking
    assert np.all(np.asarray(jammed.self_locking)) and not np.any(np.asarray(moving.self_locking))


# --------------------------------------------------------------------------- circular slot
# A crank O-A (driven) and an arm A-P whose pin P runs in a circular slot of the frame
# (centre C, radius RHO): quasi-static, under gravity and a force at P, back and forth.
CR, CL, RHO, CC = 0.10, 0.30, 0.12, 0.25 + 0.15j
CM = {"crank": 0.9, "arm": 1.6}
CF = 50.0 - 80.0j
CMU = {"O": 0.12, "A": 0.10, "slot": 0.2}
CRPIN = {"O": 0.006, "A": 0.005}


def slot_pose(th):
    """``(A, P)`` at crank angle `th` (the branch left of A -> C)."""
    A = CR * np.exp(1j * th)
    d = abs(CC - A)
    a = (CL**2 - RHO**2 + d**2) / (2 * d)
    return A, A + (a + 1j * np.sqrt(CL**2 - a**2)) * (CC - A) / d


def slot_speeds(th, om):
    """The arm's angular speed and the pin's speed along the slot's tangent ``i n``."""
    A, P = slot_pose(th)
    m = np.array([[(P - A).real, -(P - CC).real], [(P - A).imag, -(P - CC).imag]])
    rhs = -A * om  # from i A om + i (P - A) phi' = i (P - C) psi'
    w_arm, psi = np.linalg.solve(m, [rhs.real, rhs.imag])
    return {"O": om, "A": w_arm - om, "slot": RHO * psi}


def slot_newton_euler(th, sg):
    """``x = (F_O, F_A, N, tau)``: F_O ground on crank, F_A crank on arm, N the slot's normal
    force on the arm (out of the centre), tau on the crank; quasi-static, with friction."""
    A, P = slot_pose(th)
    g1, g2 = A / 2, (A + P) / 2
    n = (P - CC) / abs(P - CC)
    e = 1j * n
    grav = -1j * G

    def f(x):
        FO, FA, N, tau = x[0] + 1j * x[1], x[2] + 1j * x[3], x[4], x[5]
        mO = -CMU["O"] * CRPIN["O"] * abs(FO) * sg["O"]
        mA = -CMU["A"] * CRPIN["A"] * abs(FA) * sg["A"]  # on the arm
        fs = -CMU["slot"] * abs(N) * sg["slot"] * e
        crank = FO - FA + CM["crank"] * grav
        arm = FA + N * n + fs + CM["arm"] * grav + CF
        return np.array([crank.real, crank.imag, cross(-g1, FO) + cross(A - g1, -FA) + tau + mO - mA,
                         arm.real, arm.imag, cross(A - g2, FA) + cross(P - g2, N * n + fs + CF) + mA])

    x = np.zeros(6)
    for _ in range(40):
        r = f(x)
        if np.max(np.abs(r)) <= 1e-14 * 100:
            break
        jac = np.stack([(f(x + h) - f(x - h)) / 2e-7 for h in 1e-7 * np.eye(6)], axis=1)
        x = x - np.linalg.solve(jac, r)
    assert np.max(np.abs(f(x))) <= 1e-12 * 100
    return x


def test_pin_in_a_circular_slot_with_friction_against_newton_euler():
    th0 = 0.8
    A, P = slot_pose(th0)
    lk = jm.Linkage(points={"O": (0, 0), "A": (A.real, A.imag), "P": (P.real, P.imag), "C": (CC.real, CC.imag)},
                    links={"crank": "O A", "arm": "A P"}, ground="O C", driver="crank", slots={"P": {"on": "ground", "center": "C"}},
                    mass=CM, gravity=G, forces={"P": {"force": (CF.real, CF.imag), "on": "arm"}},
                    friction={"O": {"mu": CMU["O"], "radius": CRPIN["O"]}, "A": {"mu": CMU["A"], "radius": CRPIN["A"]},
                              "P": {"mu": CMU["slot"]}, "width": WIDTH})
    t = np.linspace(0.0, np.pi, 25)
    th, om = th0 + 0.9 * np.sin(2 * t), 1.8 * np.cos(2 * t)
    res = lk.inverse_dynamics(jm.Samples(th, om, np.zeros_like(t), t), quasi_static=True)
    w = [slot_speeds(a, b) for a, b in zip(th, om)]
    scale = {k: max(abs(x[k]) for x in w) for k in w[0]}
    xs = np.array([slot_newton_euler(a, {k: np.tanh(x[k] / (WIDTH * scale[k])) for k in x}) for a, x in zip(th, w)])
    tau = xs[:, 5]
    np.testing.assert_allclose(np.asarray(res.tau[:, 0]), tau, rtol=0, atol=TOL * np.max(np.abs(tau)))
    for joint, link, col in (("O", "crank", 0), ("A", "arm", 2)):
        want = xs[:, col] + 1j * xs[:, col + 1]
        np.testing.assert_allclose(np.asarray(res.force_on(link, joint)), want, rtol=0, atol=TOL * np.max(np.abs(want)))
    np.testing.assert_allclose(np.asarray(res.normal_force("P in ground")), xs[:, 4], rtol=0, atol=TOL * np.max(np.abs(xs[:, 4])))
    # friction takes part, the slot's most: without it the torque differs by more than the tolerance
    bare = lk.inverse_dynamics(jm.Samples(th, om, np.zeros_like(t), t), p={"mu_O": 0.0, "mu_A": 0.0, "mu_P": 0.0}, quasi_static=True)
    assert np.max(np.abs(np.asarray(res.tau[:, 0] - bare.tau[:, 0]))) > 1e-2 * np.max(np.abs(tau))
    assert np.max(np.abs(np.asarray(res.joint_friction["P in ground"]))) > 1.0  # N
