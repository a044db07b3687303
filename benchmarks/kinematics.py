"""Four-bar positions, velocities and accelerations: jaxmech against its peers.

For N crank positions of one design (N = 1e3, 1e5, 1e6) and for 1e3 designs x 1e3 positions,
in one run:

- ``closed_jax``: the closed form, jitted and vmapped (the speed limit);
- ``closed_numpy``: the same closed form in numpy;
- ``jaxmech``: ``stroke_kinematics`` (continuation solve + implicit derivatives in one
  compiled pass), jitted together with the scaling to time derivatives;
- ``optimistix``: ``optx.root_find`` with ``optx.Newton``, vmapped, guessed with the previous
  position's exact solution (a continuation-quality guess), derivatives by its implicit rule;
- ``fsolve``: ``scipy.optimize.fsolve`` per position with continuation (the seeds' method);
  velocities and accelerations by the 2x2 linear solves; timed on a subsample;
- ``pylinkage``: ``Linkage.step_fast_with_kinematics`` (numba), pylinkage's fastest path;
- ``mechanism``: the ``mechanism`` PyPI package's ``Mechanism.iterate`` (fsolve for position,
  velocity and acceleration), on a subsample;
- ``exudyn``: the four-bar as three rigid bodies and four revolute joints in Exudyn, the crank
  angle prescribed, implicit generalized-alpha over one crank turn at several step counts
  (time stepping, the way the flap report used MBDyn).

Each row: median time per position (ns), compile time (s) separately, and the max error
against the numpy closed form in positions (rad), velocities (rad/s), accelerations (rad/s^2).

Run: ``python -m benchmarks.kinematics [--quick]``; writes ``results/kinematics.json`` and
``results/kinematics.png``.
"""

from __future__ import annotations

import time
import traceback

import numpy as np

from benchmarks.common import base_parser, compile_jax, setup_jax, time_call, time_python, write_result
from benchmarks.fourbar_reference import ALPHA, DESIGN, GUESS, OMEGA, angle_error, closed_form, closed_form_numpy, max_error, random_designs


def _errors(t3, t4, w3, w4, a3, a4, ref):
    r3, r4, rw3, rw4, ra3, ra4 = ref
    return {
        "pos_err_rad": max(angle_error(t3, r3), angle_error(t4, r4)),
        "vel_err": max(max_error(w3, rw3), max_error(w4, rw4)),
        "acc_err": max(max_error(a3, ra3), max_error(a4, ra4)),
    }


def _row(name, n, timing, compile_s, errs, **extra):
    per = timing["median_s"] / n
    return {"method": name, "n_positions": n, "time_s": timing, "ns_per_position": per * 1e9, "compile_s": compile_s, **errs, **extra}


# --------------------------------------------------------------------------- JAX methods
def _jax_methods():
    import jax
    import jax.numpy as jnp

    import jaxmech as jm
    from jaxmech.scenes.classic import fourbar_mechanism as mech

    def closed_jax(us, p):
        return closed_form(jnp, us, p["a"], p["b"], p["c"], p["d"])

    def jaxmech_one(us, p, guess):
        sol, d1, d2 = jm.stroke_kinematics(mech, us, p, guess)
        q1 = d1[..., 0]
        q2 = d2[..., 0, 0]
        qd = q1 * OMEGA
        qdd = q1 * ALPHA + q2 * OMEGA**2
        return sol.q, qd, qdd, sol.status

    def jaxmech_designs(us, p, guess):
        # D designs x N positions: continuation per design, derivatives in the same pass.
        sol, d1, d2 = jm.stroke_kinematics(mech, us, p, guess)
        q1, q2 = d1[..., 0], d2[..., 0, 0]
        return sol.q, q1 * OMEGA, q1 * ALPHA + q2 * OMEGA**2, sol.status

    return jax, jnp, jm, mech, closed_jax, jaxmech_one, jaxmech_designs


def _optimistix_fn(jax, jnp, mech):
    import optimistix as optx

    def fn(q, args):
        u, p = args
        return mech.residual(q, u[None], p)

    solver = optx.Newton(rtol=1e-13, atol=1e-13)

    def root(u, p, g):
        sol = optx.root_find(fn, solver, g, args=(u, p), max_steps=40, throw=False)
        return sol.value, sol.result == optx.RESULTS.successful

    def one(u, p, g):
        q, ok = root(u, p, g)
        f = lambda uu: root(uu, p, g)[0]  # noqa: E731
        # velocities and accelerations through optimistix's implicit rule (nested jvp)
        inner = lambda uu: jax.jvp(f, (uu,), (jnp.ones_like(uu),))[1]  # noqa: E731
        q1, q2 = jax.jvp(inner, (u,), (jnp.ones_like(u),))
        return q, q1 * OMEGA, q1 * ALPHA + q2 * OMEGA**2, ok

    def batched(us, p, guesses):
        return jax.vmap(lambda u, g: one(u, p, g))(us, guesses)

    return batched


# --------------------------------------------------------------------------- CPU peers
def _fsolve_stroke(us, p):
    from scipy.optimize import fsolve

    a, b, c, d = p["a"], p["b"], p["c"], p["d"]

    def loop(x, th2):
        t3, t4 = x
        return [a * np.cos(th2) + b * np.cos(t3) - c * np.cos(t4) - d, a * np.sin(th2) + b * np.sin(t3) - c * np.sin(t4)]

    out = np.empty((len(us), 6))
    g = np.array(GUESS)
    for i, th2 in enumerate(us):
        t3, t4 = fsolve(loop, g, args=(th2,), xtol=1e-13)
        g = np.array([t3, t4])
        # velocity and acceleration: the differentiated loop (2x2 linear), as the seeds do
        J = np.array([[-b * np.sin(t3), c * np.sin(t4)], [b * np.cos(t3), -c * np.cos(t4)]])
        rhs = np.array([a * OMEGA * np.sin(th2), -a * OMEGA * np.cos(th2)])
        w3, w4 = np.linalg.solve(J, rhs)
        rhs2 = np.array(
            [
                a * ALPHA * np.sin(th2) + a * OMEGA**2 * np.cos(th2) + b * w3**2 * np.cos(t3) - c * w4**2 * np.cos(t4),
                -a * ALPHA * np.cos(th2) + a * OMEGA**2 * np.sin(th2) + b * w3**2 * np.sin(t3) - c * w4**2 * np.sin(t4),
            ]
        )
        al3, al4 = np.linalg.solve(J, rhs2)
        out[i] = t3, t4, w3, w4, al3, al4
    return out.T


def _pylinkage_setup(p, n):
    from pylinkage.actuators import Crank
    from pylinkage.components import Ground
    from pylinkage.dyads import RRRDyad
    from pylinkage.simulation import Linkage

    O1 = Ground(0, 0, name="O1")
    O2 = Ground(float(p["d"]), 0, name="O2")
    crank = Crank(anchor=O1, radius=float(p["a"]), angular_velocity=2 * np.pi / n, name="crank")
    B = RRRDyad(anchor1=crank.output, anchor2=O2, distance1=float(p["b"]), distance2=float(p["c"]), name="B")
    L = Linkage([O1, O2, crank, B], name="fourbar")
    L.set_input_velocity(crank, omega=OMEGA, alpha=ALPHA)
    return L


def _pylinkage_angles(pos, vel, acc, d):
    """Joint Cartesian kinematics -> (th2, t3, t4, w3, w4, al3, al4)."""
    A, B = pos[:, 2], pos[:, 3]
    vA, vB = vel[:, 2], vel[:, 3]
    aA, aB = acc[:, 2], acc[:, 3]
    cross = lambda u, v: u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]  # noqa: E731
    BA = B - A
    R = B - np.array([d, 0.0])
    b2, c2 = np.sum(BA**2, 1), np.sum(R**2, 1)
    th2 = np.arctan2(A[:, 1], A[:, 0])
    t3, t4 = np.arctan2(BA[:, 1], BA[:, 0]), np.arctan2(R[:, 1], R[:, 0])
    w3, w4 = cross(BA, vB - vA) / b2, cross(R, vB) / c2
    al3, al4 = cross(BA, aB - aA) / b2, cross(R, aB) / c2
    return th2, (t3, t4, w3, w4, al3, al4)


def _exudyn_fourbar(n_steps, p=DESIGN, turn=2 * np.pi, spectral_radius=0.9):
    """The four-bar in Exudyn: crank, coupler, rocker as ObjectRigidBody2D (1 kg, 0.1 kg m^2,
    centred on each link), four ObjectJointRevolute2D, the crank angle prescribed as
    theta2(t) = OMEGA t + ALPHA t^2 / 2 by a CoordinateConstraint; implicit generalized-alpha
    (index 3) over the time to turn the crank by `turn`.  Returns (t, theta2, w2, (t3, t4, w3, w4, al3, al4), solve_s)."""
    import warnings

    import exudyn as exu
    from exudyn.itemInterface import (CoordinateConstraint, MarkerBodyPosition, MarkerNodeCoordinate, NodePointGround,
                                      NodeRigidBody2D, ObjectGround, ObjectJointRevolute2D, ObjectRigidBody2D, SensorNode)
    a, b, c, d = (p[k] for k in "abcd")
    T = (-OMEGA + np.sqrt(OMEGA**2 + 2 * ALPHA * turn)) / ALPHA  # OMEGA T + ALPHA T^2 / 2 = turn
    t3, t4, w3, w4, _, _ = (float(np.ravel(x)[0]) for x in closed_form_numpy(np.array([0.0]), **p, w2=OMEGA, al2=ALPHA))
    A = a + 0j
    B = A + b * np.exp(1j * t3)
    O4 = d + 0j
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground = mbs.AddObject(ObjectGround(referencePosition=[0.0, 0.0, 0.0]))

    def gmarker(z):
        return mbs.AddMarker(MarkerBodyPosition(bodyNumber=ground, localPosition=[z.real, z.imag, 0.0]))

    def link(z0, z1, ang, omega, v0):
        ref = 0.5 * (z0 + z1)
        vref = v0 + 1j * omega * (ref - z0)
        n = mbs.AddNode(NodeRigidBody2D(referenceCoordinates=[ref.real, ref.imag, ang], initialVelocities=[vref.real, vref.imag, omega]))
        bd = mbs.AddObject(ObjectRigidBody2D(mass=1.0, inertia=0.1, nodeNumber=n))

        def marker(z):
            loc = (z - ref) * np.exp(-1j * ang)
            return mbs.AddMarker(MarkerBodyPosition(bodyNumber=bd, localPosition=[loc.real, loc.imag, 0.0]))

        return n, marker

    vA = 1j * OMEGA * A
    n2, m2 = link(0j, A, 0.0, OMEGA, 0j)
    n3, m3 = link(A, B, t3, w3, vA)
    n4, m4 = link(O4, B, t4, w4, 0j)
    for x, y in ((gmarker(0j), m2(0j)), (m2(A), m3(A)), (m3(B), m4(B)), (gmarker(O4), m4(O4))):
        mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[x, y]))
    ng = mbs.AddNode(NodePointGround(referenceCoordinates=[0.0, 0.0, 0.0]))
    mg = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=ng, coordinate=0))
    mc = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=n2, coordinate=2))
    mbs.AddObject(CoordinateConstraint(markerNumbers=[mg, mc], offsetUserFunction=lambda mbs, t, i, off: OMEGA * t + 0.5 * ALPHA * t * t))
    sens = [mbs.AddSensor(SensorNode(nodeNumber=n, storeInternal=True, outputVariableType=v))
            for n in (n2, n3, n4) for v in (exu.OutputVariableType.Rotation, exu.OutputVariableType.AngularVelocity,
                                               exu.OutputVariableType.Coordinates_tt)]
    mbs.Assemble()
    s = exu.SimulationSettings()
    ti = s.timeIntegration
    ti.numberOfSteps, ti.endTime = n_steps, T
    ti.newton.relativeTolerance, ti.newton.absoluteTolerance = 1e-12, 1e-14
    ti.verboseMode = 0
    ti.generalizedAlpha.spectralRadius = spectral_radius
    s.solution.file.write = False
    s.solution.sensors.writePeriod = 0.999 * T / n_steps
    s.show.computationTime = False
    s.show.statistics = False
    t0 = time.perf_counter()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mbs.SolveDynamic(s)
    solve_s = time.perf_counter() - t0
    data = [mbs.GetSensorStoredData(k) for k in sens]
    tt = data[0][:, 0]
    rot = lambda k: np.asarray(data[k])[:, -1]  # noqa: E731  (last column: the z component)
    th2, w2 = rot(0), rot(1)
    out = (rot(3), rot(6), rot(4), rot(7), np.asarray(data[5])[:, 3], np.asarray(data[8])[:, 3])
    return tt, th2, w2, out, solve_s


def _mechanism_pkg(us, p):
    """The `mechanism` package (PyPI): vector loops solved by fsolve, per position."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from mechanism import Mechanism, Vector, get_joints

    O, A, B, C = get_joints("O A B C")
    a = Vector((O, A), r=p["a"])
    b = Vector((A, B), r=p["b"])
    c = Vector((C, B), r=p["c"])
    d = Vector((O, C), r=p["d"], theta=0, style="ground")

    def loops(x, i):
        return (a(i) + b(x[0]) - c(x[1]) - d()).flatten()

    n = len(us)
    mech = Mechanism(
        vectors=(a, b, c, d), origin=O, loops=loops, pos=us, vel=np.full(n, OMEGA), acc=np.full(n, ALPHA),
        guess=(np.array(GUESS), np.array([0.0, 0.0]), np.array([0.0, 0.0])),
    )
    mech.iterate()
    return b.pos.thetas, c.pos.thetas, b.vel.omegas, c.vel.omegas, b.acc.alphas, c.acc.alphas


# --------------------------------------------------------------------------- the run
def run(quick: bool = False) -> dict:
    setup_jax(True)
    jax, jnp, jm, mech, closed_jax, jaxmech_one, jaxmech_designs = _jax_methods()
    optx_batched = _optimistix_fn(jax, jnp, mech)
    sizes = [10**3, 10**4] if quick else [10**3, 10**5, 10**6]
    d_designs, n_per = (100, 100) if quick else (1000, 1000)
    repeat = 3 if quick else 5
    p = {k: jnp.asarray(v) for k, v in DESIGN.items()}
    g = jnp.asarray(GUESS)
    rows, notes = [], {}

    for n in sizes:
        print(f"-- N = {n}", flush=True)
        us_np = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
        us = jnp.asarray(us_np)
        ref = closed_form_numpy(us_np, **DESIGN)

        f, ct = compile_jax(closed_jax, us, p)
        t = time_call(f, us, p, repeat=repeat)
        rows.append(_row("closed_jax", n, t, ct, _errors(*map(np.asarray, f(us, p)), ref)))

        t = time_python(lambda: closed_form_numpy(us_np, **DESIGN), repeat=repeat)
        rows.append(_row("closed_numpy", n, t, 0.0, _errors(*ref, ref)))

        f, ct = compile_jax(jaxmech_one, us, p, g)
        t = time_call(f, us, p, g, repeat=repeat)
        q, qd, qdd, st = map(np.asarray, f(us, p, g))
        rows.append(
            _row("jaxmech", n, t, ct, _errors(q[:, 0], q[:, 1], qd[:, 0], qd[:, 1], qdd[:, 0], qdd[:, 1], ref),
                 success_rate=float(np.mean(st == 0)))
        )

        # continuation-quality guesses (the previous position's exact solution) for the
        # solvers that take one guess per position
        prev = np.stack([np.roll(ref[0], 1), np.roll(ref[1], 1)], -1)  # (wraps: a full turn)
        gs = jnp.asarray(prev)
        try:
            f, ct = compile_jax(optx_batched, us, p, gs)
            t = time_call(f, us, p, gs, repeat=max(2, repeat // 2))
            q, qd, qdd, ok = map(np.asarray, f(us, p, gs))
            rows.append(_row("optimistix_newton", n, t, ct, _errors(q[:, 0], q[:, 1], qd[:, 0], qd[:, 1], qdd[:, 0], qdd[:, 1], ref),
                             success_rate=float(np.mean(ok))))
        except Exception as e:  # pragma: no cover - recorded, not fatal
            notes["optimistix"] = f"failed: {type(e).__name__}: {e}"
            traceback.print_exc()

        try:
            t0 = time.perf_counter()
            L = _pylinkage_setup(DESIGN, n)
            L.step_fast_with_kinematics(iterations=8)  # numba compile (cached on disk after the first run)
            ct = time.perf_counter() - t0
            out = {}

            def pyl():
                L2 = _pylinkage_setup(DESIGN, n)
                out["r"] = L2.step_fast_with_kinematics(iterations=n)

            t = time_python(pyl, repeat=repeat)
            th2, vals = _pylinkage_angles(*out["r"], DESIGN["d"])
            rows.append(_row("pylinkage_step_fast", n, t, ct, _errors(*vals, closed_form_numpy(th2, **DESIGN))))
        except Exception as e:  # pragma: no cover
            notes["pylinkage"] = f"failed: {type(e).__name__}: {e}"
            traceback.print_exc()

    # per-position solvers in Python: a subsample, reported per position
    n_sub = 200 if quick else 2000
    us_np = np.linspace(0.0, 2 * np.pi, n_sub, endpoint=False)
    ref = closed_form_numpy(us_np, **DESIGN)
    t = time_python(lambda: _fsolve_stroke(us_np, DESIGN), repeat=3 if not quick else 1)
    rows.append(_row("scipy_fsolve", n_sub, t, 0.0, _errors(*_fsolve_stroke(us_np, DESIGN), ref), subsample=True))
    try:
        n_m = 100 if quick else 500
        us_m = np.linspace(0.0, 2 * np.pi, n_m, endpoint=False)
        res = {}
        t = time_python(lambda: res.__setitem__("r", _mechanism_pkg(us_m, DESIGN)), repeat=1, warmup=0)
        rows.append(_row("mechanism_pkg", n_m, t, 0.0, _errors(*res["r"], closed_form_numpy(us_m, **DESIGN)), subsample=True))
    except Exception as e:  # pragma: no cover
        notes["mechanism"] = f"failed: {type(e).__name__}: {e}"
        traceback.print_exc()

    # Exudyn (time stepping, as the flap report used MBDyn): its own time grid over one crank
    # turn; errors against the closed form at its (theta2, omega2) samples.  Exudyn's initial
    # accelerations ignore the prescribed crank acceleration (0.2 rad/s^2 off at t = 0), and
    # the generalized-alpha transient from it decays over ~20 steps: acceleration errors are
    # taken after the first 5 % of the turn (the full-turn figure is kept as acc_err_with_startup).
    for n_steps in ((360, 1440) if quick else (1440, 5760, 23040)):
        try:
            import warnings

            res = {}
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                t = time_python(lambda: res.__setitem__("r", _exudyn_fourbar(n_steps)), repeat=1 if quick else 3, warmup=0)
            tt, th2, w2, out, solve_s = res["r"]
            r_ex = closed_form_numpy(th2, **DESIGN, w2=w2, al2=ALPHA)
            k0 = max(1, len(tt) // 20)
            errs = _errors(*out[:4], out[4][k0:], out[5][k0:], (*r_ex[:4], r_ex[4][k0:], r_ex[5][k0:]))
            full = _errors(*out, r_ex)["acc_err"]
            rows.append(_row(f"exudyn_genalpha_{n_steps}_steps", len(tt), t, 0.0, errs, step_s=float(tt[1] - tt[0]),
                             solve_only_ns_per_position=solve_s / len(tt) * 1e9, acc_err_with_startup=full))
        except Exception as e:  # pragma: no cover
            notes[f"exudyn_{n_steps}"] = f"failed: {type(e).__name__}: {e}"
            traceback.print_exc()

    # ---- designs x positions
    print(f"-- {d_designs} designs x {n_per} positions", flush=True)
    n_tot = d_designs * n_per
    des = random_designs(d_designs)
    us_np = np.linspace(0.0, 2 * np.pi, n_per, endpoint=False)
    ref = closed_form_numpy(us_np[None, :], *[des[k][:, None] for k in "abcd"])
    us = jnp.asarray(us_np)
    pd = {k: jnp.asarray(v) for k, v in des.items()}
    gd = jnp.broadcast_to(g, (d_designs, 2))

    def closed_designs(us, p):
        return jax.vmap(lambda a, b, c, d: closed_form(jnp, us, a, b, c, d))(p["a"], p["b"], p["c"], p["d"])

    f, ct = compile_jax(closed_designs, us, pd)
    t = time_call(f, us, pd, repeat=repeat)
    rows.append(_row("closed_jax", n_tot, t, ct, _errors(*map(np.asarray, f(us, pd)), ref), case="designs"))
    t = time_python(lambda: closed_form_numpy(us_np[None, :], *[des[k][:, None] for k in "abcd"]), repeat=repeat)
    rows.append(_row("closed_numpy", n_tot, t, 0.0, _errors(*ref, ref), case="designs"))
    f, ct = compile_jax(jaxmech_designs, us, pd, gd)
    t = time_call(f, us, pd, gd, repeat=repeat)
    q, qd, qdd, st = map(np.asarray, f(us, pd, gd))
    rows.append(_row("jaxmech", n_tot, t, ct, _errors(q[..., 0], q[..., 1], qd[..., 0], qd[..., 1], qdd[..., 0], qdd[..., 1], ref),
                     case="designs", success_rate=float(np.mean(st == 0))))
    prev = np.stack([np.roll(ref[0], 1, axis=1), np.roll(ref[1], 1, axis=1)], -1)
    gs = jnp.asarray(prev.reshape(-1, 2))
    uflat = jnp.asarray(np.broadcast_to(us_np, (d_designs, n_per)).ravel())
    pflat = {k: jnp.asarray(np.repeat(v, n_per)) for k, v in des.items()}

    try:
        def optx_designs(u, p, g):
            return jax.vmap(lambda u_, p_, g_: optx_batched(u_[None], p_, g_[None]))(u, p, g)

        f, ct = compile_jax(optx_designs, uflat, pflat, gs)
        t = time_call(f, uflat, pflat, gs, repeat=max(2, repeat // 2))
        q, qd, qdd, ok = f(uflat, pflat, gs)
        q, qd, qdd = (np.asarray(x).reshape(d_designs, n_per, 2) for x in (q, qd, qdd))
        rows.append(_row("optimistix_newton", n_tot, t, ct, _errors(q[..., 0], q[..., 1], qd[..., 0], qd[..., 1], qdd[..., 0], qdd[..., 1], ref),
                         case="designs", success_rate=float(np.mean(np.asarray(ok)))))
    except Exception as e:  # pragma: no cover
        notes["optimistix_designs"] = f"failed: {type(e).__name__}: {e}"
    try:
        n_d = 10 if quick else 50  # designs timed; pylinkage builds one linkage per design
        out = []

        def pyl_designs():
            out.clear()
            for i in range(n_d):
                L = _pylinkage_setup({k: des[k][i] for k in des}, n_per)
                out.append(L.step_fast_with_kinematics(iterations=n_per))

        t = time_python(pyl_designs, repeat=max(1, repeat // 2))
        errs = []
        for i, r in enumerate(out):
            th2, vals = _pylinkage_angles(*r, des["d"][i])
            errs.append(_errors(*vals, closed_form_numpy(th2, *[des[k][i] for k in "abcd"])))
        worst = {k: max(e[k] for e in errs) for k in errs[0]}
        rows.append(_row("pylinkage_step_fast", n_d * n_per, t, 0.0, worst, case="designs", subsample=True))
    except Exception as e:  # pragma: no cover
        notes["pylinkage_designs"] = f"failed: {type(e).__name__}: {e}"

    for r in rows:
        r.setdefault("case", "one_design")
    summary = _ratios(rows)
    return {"rows": rows, "ratios": summary, "notes": notes, "quick": quick,
            "drive": {"omega_rad_s": OMEGA, "alpha_rad_s2": ALPHA}, "design": DESIGN}


def _ratios(rows):
    """jaxmech time per position / closed_jax's, and fsolve's / jaxmech's, per case and N."""
    out = []
    fs = [r for r in rows if r["method"] == "scipy_fsolve"]
    fs_ns = fs[0]["ns_per_position"] if fs else float("nan")
    for r in rows:
        if r["method"] != "jaxmech":
            continue
        cl = [c for c in rows if c["method"] == "closed_jax" and c["case"] == r["case"] and c["n_positions"] == r["n_positions"]]
        pyl = [c for c in rows if c["method"] == "pylinkage_step_fast" and c["case"] == r["case"] and (c["n_positions"] == r["n_positions"] or c.get("subsample"))]
        out.append({
            "case": r["case"], "n_positions": r["n_positions"],
            "jaxmech_over_closed_jax": r["ns_per_position"] / cl[0]["ns_per_position"] if cl else None,
            "fsolve_over_jaxmech": fs_ns / r["ns_per_position"],
            "pylinkage_over_jaxmech": pyl[0]["ns_per_position"] / r["ns_per_position"] if pyl else None,
        })
    return out


def plot(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = result["rows"]
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(12, 4.5))
    for m in methods:
        rs = [r for r in rows if r["method"] == m and r["case"] == "one_design"]
        if rs:
            ax1.plot([r["n_positions"] for r in rs], [r["ns_per_position"] for r in rs], "o-", label=m)
    ax1.set_xscale("log"); ax1.set_yscale("log")
    ax1.set_xlabel("positions N (one design)"); ax1.set_ylabel("time per position (ns)")
    ax1.set_title("four-bar: positions + velocities + accelerations"); ax1.legend(fontsize=7); ax1.grid(True, which="both", alpha=0.3)
    for m in methods:
        rs = [r for r in rows if r["method"] == m]
        if rs:
            err = [max(r["pos_err_rad"] or 0, 1e-17) for r in rs]
            ax2.scatter([r["ns_per_position"] for r in rs], err, label=m)
    ax2.set_xscale("log"); ax2.set_yscale("log")
    ax2.set_xlabel("time per position (ns)"); ax2.set_ylabel("max position error (rad)")
    ax2.set_title("error against the closed form"); ax2.grid(True, which="both", alpha=0.3); ax2.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def run_core(n: int = 10**6, rounds: int = 3) -> dict:
    """jaxmech against the jitted closed form alone at ``n`` positions, alternating, ``rounds``
    times: the steady-state ratio without the peers (no ``.[bench]`` extras needed)."""
    setup_jax(True)
    jax, jnp, jm, mech, closed_jax, jaxmech_one, _ = _jax_methods()
    p = {k: jnp.asarray(v) for k, v in DESIGN.items()}
    g = jnp.asarray(GUESS)
    us = jnp.asarray(np.linspace(0.0, 2 * np.pi, n, endpoint=False))
    fc, ctc = compile_jax(closed_jax, us, p)
    fj, ctj = compile_jax(jaxmech_one, us, p, g)
    rounds_out = []
    for _ in range(rounds):
        tc = time_call(fc, us, p, repeat=5)["median_s"]
        tj = time_call(fj, us, p, g, repeat=5)["median_s"]
        rounds_out.append({"closed_jax_ns": tc / n * 1e9, "jaxmech_ns": tj / n * 1e9, "ratio": tj / tc})
        print(f"closed form {tc / n * 1e9:6.0f} ns/pos   jaxmech {tj / n * 1e9:6.0f} ns/pos   ratio {tj / tc:.2f}", flush=True)
    return {"n_positions": n, "compile_s": {"closed_jax": ctc, "jaxmech": ctj}, "rounds": rounds_out}


def main(argv=None):
    parser = base_parser(__doc__.splitlines()[0])
    parser.add_argument("--core", action="store_true", help="only jaxmech against the jitted closed form at 1e6 positions")
    args = parser.parse_args(argv)
    if args.core:
        print("wrote", write_result("kinematics_core", run_core(), out_dir=args.out))
        return
    res = run(args.quick)
    path = write_result("kinematics", res, out_dir=args.out)
    plot(res, args.out / "kinematics.png")
    for r in res["rows"]:
        print(f"{r['case']:10s} {r['method']:26s} N={r['n_positions']:>8d} {r['ns_per_position']:12.1f} ns/pos "
              f"compile {r['compile_s']:6.2f}s  err pos {r['pos_err_rad']:.1e} vel {r['vel_err']:.1e} acc {r['acc_err']:.1e}")
    for r in res["ratios"]:
        print(r)
    print("notes:", res["notes"])
    print("wrote", path)


if __name__ == "__main__":
    main()
