"""Speed against error for the four-bar (issue 6): which knobs buy accuracy, at what cost.

Against a high-precision reference (the closed form evaluated with mpmath at 40 digits on a
subsample of the crank positions), for N positions of one design:

- Newton iteration budget 1..8: a fixed-count Newton on jaxmech's residual, started from the
  continuation predictor's guess (the previous position's solution), float64 and float32;
  beside it the success rate of ``jaxmech.solve`` with ``max_iterations = k``;
- float32 against float64 for the full ``stroke_kinematics`` path;
- cold start (``solve``, one fixed guess for every position) against continuation
  (``solve_stroke``): time, error, status counts (a cold start may close on the wrong
  branch: those samples must carry the ``BRANCH`` status, never a silent wrong answer);
- derivatives by finite differences of the solved positions (central, on the crank grid)
  against the implicit-function autodiff (``stroke_kinematics``).

Writes ``results/speed_error.json`` and a Pareto plot ``results/speed_error.png``.

Hook: ``EXTRA_CASES`` holds further scenes (flap_msd, and an Exudyn comparison) once the
scene exists; each entry is a function ``(quick) -> dict`` returning the same row format.
"""

from __future__ import annotations

import numpy as np

from benchmarks.common import base_parser, compile_jax, pareto_front, setup_jax, time_call, write_result
from benchmarks.fourbar_reference import ALPHA, DESIGN, GUESS, OMEGA, closed_form_numpy


def reference_mp(th2, digits=40):
    """Closed form in mpmath: (t3, t4, w3, w4, al3, al4) as float64 arrays, exact to rounding."""
    import mpmath as mp

    mp.mp.dps = digits
    a, b, c, d = (mp.mpf(DESIGN[k]) for k in "abcd")
    w2, al2 = mp.mpf(OMEGA), mp.mpf(ALPHA)
    out = []
    for t in th2:
        t = mp.mpf(float(t))  # the float64 input exactly
        ax, ay = a * mp.cos(t), a * mp.sin(t)
        ex, ey = d - ax, -ay
        f2 = ex * ex + ey * ey
        f = mp.sqrt(f2)
        x = (b * b - c * c + f2) / (2 * f)
        h = mp.sqrt(b * b - x * x)
        ux, uy = ex / f, ey / f
        bx, by = x * ux - h * uy, x * uy + h * ux
        rx, ry = ax + bx - d, ay + by
        t3, t4 = mp.atan2(by, bx), mp.atan2(ry, rx)
        det = by * rx - bx * ry
        vx, vy = ay * w2, -ax * w2
        w3 = (vx * (-rx) - ry * vy) / det
        w4 = ((-by) * vy - bx * vx) / det
        gx = -(-ay * al2 - ax * w2 * w2 - bx * w3 * w3 + rx * w4 * w4)
        gy = -(ax * al2 - ay * w2 * w2 - by * w3 * w3 + ry * w4 * w4)
        out.append([t3, t4, w3, w4, (gx * (-rx) - ry * gy) / det, ((-by) * gy - bx * gx) / det])
    return np.array(out, dtype=float).T


def _err(x, ref):
    """Largest absolute error; angles wrapped; NaN samples excluded (counted separately)."""
    x = np.asarray(x, float)
    d = np.abs(np.angle(np.exp(1j * (x - ref)))) if ref is not None else x
    return float(np.nanmax(d)) if np.any(np.isfinite(d)) else float("nan")


def run(quick: bool = False) -> dict:
    setup_jax(True)
    import jax
    import jax.numpy as jnp

    import jaxmech as jm
    from jaxmech.scenes.classic import fourbar_mechanism as mech

    n = 10**4 if quick else 10**5
    n_ref = 64 if quick else 256
    repeat = 3
    us64 = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    pick = np.linspace(0, n - 1, n_ref).astype(int)
    ref = reference_mp(us64[pick])
    prev_np = closed_form_numpy(np.roll(us64, 1), **DESIGN)  # continuation guess: previous solution
    rows = []

    def err_row(name, t_s, q, qd=None, qdd=None, compile_s=0.0, **extra):
        q = np.asarray(q, float)[pick]
        row = {
            "method": name,
            "ns_per_position": t_s / n * 1e9,
            "compile_s": compile_s,
            "pos_err_rad": max(_err(q[:, 0], ref[0]), _err(q[:, 1], ref[1])),
            "nan_fraction": float(np.mean(~np.isfinite(q[:, 0]))),
        }
        if qd is not None:
            qd, qdd = np.asarray(qd, float)[pick], np.asarray(qdd, float)[pick]
            row["vel_err"] = float(np.nanmax(np.abs(qd - ref[2:4].T)))
            row["acc_err"] = float(np.nanmax(np.abs(qdd - ref[4:6].T)))
        row.update(extra)
        rows.append(row)
        print(f"{name:40s} {row['ns_per_position']:9.1f} ns/pos  pos err {row['pos_err_rad']:.2e}", flush=True)

    # ---- fixed Newton budget, float64 and float32
    for dtype in (jnp.float64, jnp.float32):
        for k in range(1, 9):
            def fixed(us, guess, p, k=k):
                def one(u, g):
                    res = lambda q: mech.residual(q, u[None], p)  # noqa: E731
                    for _ in range(k):
                        J = jax.jacfwd(res)(g)
                        r = res(g)
                        det = J[0, 0] * J[1, 1] - J[0, 1] * J[1, 0]  # explicit 2x2, as jaxmech
                        g = g - jnp.stack([J[1, 1] * r[0] - J[0, 1] * r[1], J[0, 0] * r[1] - J[1, 0] * r[0]]) / det
                    return g
                return jax.vmap(one)(us, guess)

            us = jnp.asarray(us64, dtype)
            g = jnp.asarray(np.stack(prev_np[:2], -1) + 1e-2, dtype)  # a predictor-quality guess, 1e-2 rad off
            p = {kk: jnp.asarray(v, dtype) for kk, v in DESIGN.items()}
            f, ct = compile_jax(fixed, us, g, p)
            t = time_call(f, us, g, p, repeat=repeat)
            err_row(f"newton_fixed_k{k}_{jnp.dtype(dtype).name}", t["median_s"], f(us, g, p), compile_s=ct,
                    family=f"fixed-budget Newton {jnp.dtype(dtype).name}", budget=k, dtype=jnp.dtype(dtype).name)

    # jaxmech.solve with max_iterations = k: its success rate (unconverged samples are NaN + status)
    g64 = jnp.asarray(np.stack(prev_np[:2], -1) + 1e-2)
    p64 = {kk: jnp.asarray(v) for kk, v in DESIGN.items()}
    for k in range(1, 9):
        opts = jm.SolverOptions(max_iterations=k)

        def s(us, g, p, opts=opts):
            sol = jm.solve(mech, us, p, g, options=opts)
            return sol.q, sol.status

        f, ct = compile_jax(s, jnp.asarray(us64), g64, p64)
        t = time_call(f, jnp.asarray(us64), g64, p64, repeat=repeat)
        q, st = f(jnp.asarray(us64), g64, p64)
        err_row(f"jaxmech_solve_max_steps{k}", t["median_s"], q, compile_s=ct, family="jaxmech.solve max_steps",
                budget=k, success_rate=float(np.mean(np.asarray(st) == 0)))

    # ---- stroke_kinematics in float64 and float32; cold start vs continuation
    for dtype in (jnp.float64, jnp.float32):
        us = jnp.asarray(us64, dtype)
        p = {kk: jnp.asarray(v, dtype) for kk, v in DESIGN.items()}
        g = jnp.asarray(GUESS, dtype)

        def kin(us, p, g):
            sol, d1, d2 = jm.stroke_kinematics(mech, us, p, g)
            q1, q2 = d1[..., 0], d2[..., 0, 0]
            return sol.q, q1 * OMEGA, q1 * ALPHA + q2 * OMEGA**2, sol.status

        f, ct = compile_jax(kin, us, p, g)
        t = time_call(f, us, p, g, repeat=repeat)
        q, qd, qdd, st = f(us, p, g)
        name = jnp.dtype(dtype).name
        err_row(f"continuation_autodiff_{name}", t["median_s"], q, qd, qdd, compile_s=ct, family="stroke_kinematics",
                dtype=name, success_rate=float(np.mean(np.asarray(st) == 0)))

        def cold(us, p, g):
            sol = jm.solve(mech, us, p, g)
            return sol.q, sol.status

        f, ct = compile_jax(cold, us, p, g)
        t = time_call(f, us, p, g, repeat=repeat)
        q, st = f(us, p, g)
        st = np.asarray(st)
        counts = jm.status_counts(st)
        # No silent wrong branch: every converged sample is on the guess's (open) branch.
        qn = np.asarray(q, float)
        conv = st == 0
        wrong = int(np.sum(conv & (np.sin(qn[:, 1] - qn[:, 0]) <= 0)))
        err_row(f"cold_start_{name}", t["median_s"], q, compile_s=ct, family="cold start (solve)", dtype=name,
                success_rate=float(np.mean(conv)), statuses=counts, converged_on_wrong_branch=wrong)

        def stroke(us, p, g):
            sol = jm.solve_stroke(mech, us, p, g)
            return sol.q, sol.status

        f, ct = compile_jax(stroke, us, p, g)
        t = time_call(f, us, p, g, repeat=repeat)
        q, st = f(us, p, g)
        err_row(f"continuation_{name}", t["median_s"], q, compile_s=ct, family="continuation (solve_stroke)", dtype=name,
                success_rate=float(np.mean(np.asarray(st) == 0)))

    # ---- derivatives: finite differences of positions against autodiff
    us = jnp.asarray(us64)
    g = jnp.asarray(GUESS)

    def fd(us, p, g):
        sol = jm.solve_stroke(mech, us, p, g)
        q = sol.q
        h = us[1] - us[0]
        # periodic central differences on the crank grid (a full turn), dq/du and d2q/du2
        qp, qm = jnp.roll(q, -1, 0), jnp.roll(q, 1, 0)
        q1 = (qp - qm) / (2 * h)
        q2 = (qp - 2 * q + qm) / h**2
        return q, q1 * OMEGA, q1 * ALPHA + q2 * OMEGA**2

    f, ct = compile_jax(fd, us, p64, g)
    t = time_call(f, us, p64, g, repeat=repeat)
    err_row("continuation_finite_differences", t["median_s"], *f(us, p64, g), compile_s=ct, family="derivatives by FD")

    extra = {}
    for name, case in EXTRA_CASES.items():
        try:
            extra[name] = case(quick)
        except NotImplementedError as e:
            extra[name] = {"skipped": str(e)}
    return {"rows": rows, "n_positions": n, "n_reference": n_ref, "reference": "mpmath closed form, 40 digits",
            "extra_cases": extra, "quick": quick}


def _flap_msd_case(quick):
    """Hook: the flap_msd scene against Exudyn (speed vs error), once the scene exists."""
    try:
        from jaxmech.scenes import flap_msd  # noqa: F401
    except ImportError:
        raise NotImplementedError("jaxmech.scenes.flap_msd not available yet") from None
    # --- flap_msd hook (added with benchmarks/flap_torque.py): that script runs the flap case
    # (jaxmech budgets/dtypes/cold start/FD and Exudyn); here its last result is attached.
    from benchmarks.common import load_result

    doc = load_result("flap_torque")
    if doc is None:
        raise NotImplementedError("run python -m benchmarks.flap_torque first (results/flap_torque.json)")
    return {"see": "results/flap_torque.json", "acceptance": doc.get("acceptance"), "rows": doc.get("rows"),
            "exudyn_rows": doc.get("exudyn_rows"), "quick": doc.get("quick")}


#: Further scenes for this benchmark: name -> function(quick) -> dict of rows.
EXTRA_CASES = {"flap_msd": _flap_msd_case}


def plot(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5.5))
    fams = list(dict.fromkeys(r["family"] for r in result["rows"]))
    for fam in fams:
        rs = [r for r in result["rows"] if r["family"] == fam]
        xs = [r["ns_per_position"] for r in rs]
        ys = [max(r["pos_err_rad"], 1e-17) if np.isfinite(r["pos_err_rad"] or np.nan) else np.nan for r in rs]
        ax.plot(xs, ys, "o-" if len(rs) > 1 else "s", label=fam)
        for r, x, y in zip(rs, xs, ys):
            if "budget" in r:
                ax.annotate(str(r["budget"]), (x, y), fontsize=6)
    # Pareto front over all rows (finite errors)
    front = pareto_front((r["ns_per_position"], r["pos_err_rad"]) for r in result["rows"] if r["pos_err_rad"] and np.isfinite(r["pos_err_rad"]))
    if front:
        ax.step(*zip(*front), where="post", color="k", lw=0.8, alpha=0.5, label="Pareto front")
    ax.set_xscale("log"); ax.set_yscale("log")
    ax.set_xlabel("time per position (ns)"); ax.set_ylabel("max position error vs mpmath reference (rad)")
    ax.set_title(f"four-bar speed vs error (N = {result['n_positions']})")
    ax.grid(True, which="both", alpha=0.3); ax.legend(fontsize=7)
    fig.tight_layout(); fig.savefig(path, dpi=110); plt.close(fig)


def main(argv=None):
    args = base_parser(__doc__.splitlines()[0]).parse_args(argv)
    res = run(args.quick)
    path = write_result("speed_error", res, out_dir=args.out)
    plot(res, args.out / "speed_error.png")
    print("wrote", path)


if __name__ == "__main__":
    main()
