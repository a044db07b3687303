"""Dynamics benchmarks: inverse-dynamics throughput and forward-dynamics speed against error.

Writes ``benchmarks/results/dynamics.json``.  Run: ``python benchmarks/dynamics.py [--quick]``.

1. Inverse dynamics: positions per second (position solve + driving torque + reactions) for a
   four-bar and a Watt II six-bar (two loops), batch of random crank states, float64.
   Compile time is measured apart (``lower().compile()``); run times are medians.
2. Forward dynamics: a four-bar with masses and gravity driven from rest by an inductive DC
   motor (stiff: L/R = 0.5 ms) for 0.5 s.  For each method and step, the error at the end
   (crank angle, rad) against a tight-tolerance reference (scipy Radau, rtol = atol = 1e-12, on
   the same right-hand side) and the run time per simulated second.  One compile per method:
   every step size runs the same compiled scan (the step is traced), the time is the median run
   time per step times the steps needed.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jaxmech  # noqa: E402
from jaxmech import Mechanism, cis  # noqa: E402
from jaxmech import dynamics as D  # noqa: E402
from jaxmech.actuators import DCMotor  # noqa: E402
from jaxmech.continuation import solve_stroke  # noqa: E402
from jaxmech.solver.options import SolverOptions  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))

# --------------------------------------------------------------------------- scenes
FOURBAR = Mechanism(
    name="fourbar",
    coords=("theta3", "theta4"),
    inputs=("theta2",),
    params=("a", "b", "c", "d", "m2", "J2", "m3", "J3", "m4", "J4", "g", "R_a", "K_m", "L_a", "V"),
    lengths=("a", "b", "c", "d"),
    constraints=lambda q, u, p: [p.a * cis(u.theta2) + p.b * cis(q.theta3) - p.c * cis(q.theta4) - p.d],
    points={
        "G2": lambda q, u, p: 0.5 * p.a * cis(u.theta2),
        "G3": lambda q, u, p: p.a * cis(u.theta2) + 0.5 * p.b * cis(q.theta3),
        "G4": lambda q, u, p: p.d + 0.5 * p.c * cis(q.theta4),
    },
    branch=lambda q, u, p: jnp.sin(q.theta4 - q.theta3),
)
FOURBAR_MODEL = D.Model(
    FOURBAR,
    bodies=[D.Body("G2", "m2", angle="theta2", inertia="J2"), D.Body("G3", "m3", angle="theta3", inertia="J3"),
            D.Body("G4", "m4", angle="theta4", inertia="J4")],
    loads=[D.Gravity()],
)
FOURBAR_P = dict(a=0.1, b=0.3, c=0.25, d=0.35, m2=0.5, J2=5e-4, m3=1.0, J3=8e-3, m4=0.8, J4=4e-3, g=9.81,
                 R_a=2.0, K_m=0.5, L_a=1e-3, V=12.0)

# Watt II six-bar: the four-bar's rocker is a ternary link; its point E drives a second dyad
# (coupler f, output rocker g about O6).  Loops:
#   a e^{i t2} + b e^{i t3} - c e^{i t4} - d = 0
#   d + e e^{i (t4 + gam)} + f e^{i t5} - g e^{i t6} - O6 = 0
WATT = Mechanism(
    name="watt2_sixbar",
    coords=("theta3", "theta4", "theta5", "theta6"),
    inputs=("theta2",),
    params=("a", "b", "c", "d", "e", "gam", "f", "g6", "x6", "y6", "m", "J", "g"),
    lengths=("a", "b", "c", "d", "e", "f", "g6", "x6", "y6"),
    signed=("x6", "y6"),
    constraints=lambda q, u, p: [
        p.a * cis(u.theta2) + p.b * cis(q.theta3) - p.c * cis(q.theta4) - p.d,
        p.d + p.e * cis(q.theta4 + p.gam) + p.f * cis(q.theta5) - p.g6 * cis(q.theta6) - (p.x6 + 1j * p.y6),
    ],
    points={
        "G2": lambda q, u, p: 0.5 * p.a * cis(u.theta2),
        "G3": lambda q, u, p: p.a * cis(u.theta2) + 0.5 * p.b * cis(q.theta3),
        "G4": lambda q, u, p: p.d + (p.c * cis(q.theta4) + p.e * cis(q.theta4 + p.gam)) / 3,
        "G5": lambda q, u, p: p.d + p.e * cis(q.theta4 + p.gam) + 0.5 * p.f * cis(q.theta5),
        "G6": lambda q, u, p: p.x6 + 1j * p.y6 + 0.5 * p.g6 * cis(q.theta6),
    },
)
WATT_MODEL = D.Model(
    WATT,
    bodies=[D.Body(f"G{k}", "m", angle=("theta2" if k == 2 else f"theta{k}"), inertia="J") for k in range(2, 7)],
    loads=[D.Gravity()],
)
WATT_P = dict(a=1.0, b=3.0, c=2.5, d=3.5, e=2.0, gam=0.5, f=3.0, g6=2.5, x6=6.5, y6=0.5, m=1.0, J=0.5, g=9.81)


def machine():
    return dict(platform=platform.platform(), processor=platform.processor(), python=platform.python_version(),
                cpu_count=os.cpu_count(), jax=jax.__version__, numpy=np.__version__, jaxmech=jaxmech.__version__,
                device=str(jax.devices()[0]), date=datetime.datetime.now(datetime.timezone.utc).isoformat())


def median_time(fn, repeats):
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(fn())
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts)), ts


# --------------------------------------------------------------------------- inverse dynamics
def bench_inverse(model, p, guess0, n, repeats):
    """States on the assembly branch: a crank turn solved by continuation gives the guesses."""
    mech = model.mechanism
    rng = np.random.default_rng(0)
    turn = jnp.linspace(0.0, 2 * np.pi, 721)
    stroke = solve_stroke(mech, turn, p, guess0)
    idx = rng.integers(0, 720, n)
    u = turn[idx] + rng.uniform(0, 2 * np.pi / 720, n)
    guess = stroke.q[idx]
    ud = rng.uniform(-5, 5, n)
    udd = rng.uniform(-20, 20, n)
    pj = {k: jnp.broadcast_to(jnp.asarray(v, jnp.float64), (n,)) for k, v in p.items()}
    args = (jnp.asarray(u)[:, None], jnp.asarray(ud)[:, None], jnp.asarray(udd)[:, None], pj, jnp.zeros(n), guess)
    t0 = time.perf_counter()
    compiled = D.inverse_dynamics_batch.lower(model, False, SolverOptions(), *args).compile()
    compile_s = time.perf_counter() - t0
    out = compiled(*args)
    ok = np.asarray(out["status"]) == 0
    med, ts = median_time(lambda: compiled(*args), repeats)
    return dict(mechanism=mech.name, loops=mech.m // 2, batch=n, compile_s=compile_s, run_median_s=med,
                run_s=ts, positions_per_s=n / med, success_rate=float(np.mean(ok)),
                finite_torque_rate=float(np.mean(np.isfinite(np.asarray(out["tau"][:, 0])))))


# --------------------------------------------------------------------------- forward dynamics
def reference_solution(model, p, motor, t_end, guess):
    """scipy Radau (rtol = atol = 1e-12) on the same right-hand side (jitted, loop closed by
    Newton from the last call's coordinates)."""
    from scipy.integrate import solve_ivp

    pj = {k: jnp.asarray(v, jnp.float64) for k, v in p.items()}
    integ = D.Integrator(model, actuators=((0, motor),), close_iters=8)
    rhs = jax.jit(lambda t, y, qg: (D.rhs(integ, pj, t, y, qg), D.close_loop(model.mechanism, y[:1], pj, qg, 8)[0]))
    jac = jax.jit(jax.jacfwd(lambda t, y, qg: D.rhs(integ, pj, t, y, qg), argnums=1))
    state = {"q": jnp.asarray(guess)}

    def f(t, y):
        out, q = rhs(t, jnp.asarray(y), state["q"])
        if np.all(np.isfinite(np.asarray(q))):
            state["q"] = q
        return np.asarray(out)

    sol = solve_ivp(f, (0.0, t_end), [0.0, 0.0, 0.0], method="Radau", rtol=1e-12, atol=1e-12,
                    jac=lambda t, y: np.asarray(jac(t, jnp.asarray(y), state["q"])))
    return sol.y[:, -1], sol.nfev


def bench_forward(t_end, steps_list, methods, repeats):
    model, p = FOURBAR_MODEL, FOURBAR_P
    motor = DCMotor("R_a", "K_m", inductance="L_a", voltage="V")
    guess = jnp.array([0.5, 1.6])
    from jaxmech.solver.positions import solve

    q0 = solve(FOURBAR, {"theta2": jnp.asarray(0.0)}, p, guess).q
    t0 = time.perf_counter()
    y_ref, nfev = reference_solution(model, p, motor, t_end, q0)
    ref_s = time.perf_counter() - t0
    n_max = max(steps_list)
    pj = {k: jnp.asarray(v, jnp.float64) for k, v in p.items()}
    y0 = jnp.zeros(3)
    inf = jnp.array([jnp.inf])
    rows = []
    for method in methods:
        integ = D.Integrator(model, method, n_max, actuators=((0, motor),), close_iters=5, newton_tol=1e-12, newton_max=12)
        fn = jax.jit(lambda h, integ=integ: D.integrate(integ, pj, 0.0, h, y0, q0, -inf, inf))
        t0 = time.perf_counter()
        compiled = fn.lower(jnp.asarray(t_end / n_max)).compile()
        compile_s = time.perf_counter() - t0
        for n in steps_list:
            h = jnp.asarray(t_end / n)
            ys, qs, status, t_stop, its = compiled(h)
            med, _ = median_time(lambda: compiled(h), repeats)
            y_end = np.asarray(ys[n])
            per_step = med / n_max
            rows.append(dict(method=method, h=t_end / n, steps=n, finite=bool(np.all(np.isfinite(np.asarray(ys[: n + 1])))),
                             compile_s=compile_s,
                error_theta2_rad=float(abs(y_end[0] - y_ref[0])), error_omega_rad_s=float(abs(y_end[1] - y_ref[1])),
                error_current_A=float(abs(y_end[2] - y_ref[2])), newton_mean=float(np.mean(np.asarray(its[:n]))),
                run_s_per_step=per_step, run_s_for_horizon=per_step * n))
    return dict(scene="fourbar + inductive DC motor from rest, gravity", t_end=t_end,
                reference=dict(method="scipy Radau", rtol=1e-12, atol=1e-12, nfev=int(nfev), wall_s=ref_s,
                               theta2=float(y_ref[0]), omega=float(y_ref[1]), current=float(y_ref[2])),
                runs=rows)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller batches and fewer steps (smoke test)")
    ap.add_argument("--out", default=os.path.join(HERE, "results", "dynamics.json"))
    args = ap.parse_args()
    # 4096: a batch of 8192 six-bar states hangs XLA CPU on the second execution (reported)
    n = 512 if args.quick else 4096
    repeats = 3 if args.quick else 7
    t_all = time.perf_counter()
    result = dict(benchmark="dynamics", machine=machine(), dtype="float64")
    result["inverse_dynamics"] = [
        bench_inverse(FOURBAR_MODEL, FOURBAR_P, jnp.array([0.5, 1.6]), n, repeats),
        bench_inverse(WATT_MODEL, WATT_P, jnp.array([0.2, 1.2, 0.0, 1.5]), n, repeats),
    ]
    for r in result["inverse_dynamics"]:
        print(f"inverse dynamics {r['mechanism']}: {r['positions_per_s']:.3g} positions/s "
              f"(compile {r['compile_s']:.1f} s, success {r['success_rate']:.3f})")
    steps = [25, 50, 100, 200] if args.quick else [25, 50, 100, 200, 400, 800]
    result["forward_dynamics"] = bench_forward(0.5, steps, ("radau5", "gauss4", "midpoint"), repeats)
    for r in result["forward_dynamics"]["runs"]:
        print(f"forward {r['method']:8s} h={r['h']:.2e}: error {r['error_theta2_rad']:.2e} rad, "
              f"{r['run_s_for_horizon'] * 1e3:.2f} ms, newton {r['newton_mean']:.1f}")
    result["total_wall_s"] = time.perf_counter() - t_all
    os.makedirs(os.path.dirname(args.out), exist_ok=True)
    with open(args.out, "w") as fh:
        json.dump(result, fh, indent=2)
    print(f"wrote {args.out} in {result['total_wall_s']:.0f} s")


if __name__ == "__main__":
    main()
