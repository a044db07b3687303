"""Scaling: time and memory of a position solve against batch size and number of loops.

1. Batch size B = 1 .. 1e6 (four-bar, ``jaxmech.solve``, a guess 1e-3 rad off the root):
   median time, XLA's memory analysis of the compiled function (arguments + outputs +
   temporaries, bytes) and the process's peak RSS; a least-squares fit
   ``time = fixed overhead + B * time per sample``.
2. Number of loops k = 1 .. 32: a chain of k four-bars written generically with
   ``jaxmech.Mechanism``, the rocker of loop j driving the crank of loop j+1
   (``m = 2k`` coordinates), solved for a batch of crank angles; a power-law fit
   ``time per sample ~ k^p``.

Run: ``python -m benchmarks.scaling [--quick]``; writes ``results/scaling.json`` and ``.png``.
"""

from __future__ import annotations

import numpy as np

from benchmarks.common import base_parser, compile_jax, peak_rss_mb, setup_jax, time_call, write_result
from benchmarks.fourbar_reference import DESIGN, closed_form_numpy


def chain_mechanism(k: int):
    """k coupled four-bar loops: loop j's crank angle is loop j-1's rocker angle (loop 1: u).

    Every loop is the crank-rocker ``DESIGN`` (any crank angle assembles), so the chain
    assembles for every input; coordinates ``th3_j, th4_j``.
    """
    from jaxmech import Mechanism, cis

    coords = tuple(n for j in range(k) for n in (f"th3_{j}", f"th4_{j}"))

    def constraints(q, u, p):
        loops, crank = [], u.theta2
        for j in range(k):
            t3, t4 = q[f"th3_{j}"], q[f"th4_{j}"]
            loops.append(p.a * cis(crank) + p.b * cis(t3) - p.c * cis(t4) - p.d)
            crank = t4
        return loops

    return Mechanism(name=f"chain{k}", coords=coords, inputs=("theta2",), params=("a", "b", "c", "d"),
                     lengths=("a", "b", "c", "d"), constraints=constraints)


def chain_solution(k: int, th2: np.ndarray) -> np.ndarray:
    """Exact chain coordinates (B, 2k) by the closed form, loop after loop."""
    cols, crank = [], th2
    for _ in range(k):
        t3, t4 = closed_form_numpy(crank, **DESIGN)[:2]
        cols += [t3, t4]
        crank = t4
    return np.stack(cols, -1)


def _mem(compiled) -> dict:
    try:
        m = compiled.memory_analysis()
        return {
            "argument_bytes": int(m.argument_size_in_bytes),
            "output_bytes": int(m.output_size_in_bytes),
            "temp_bytes": int(m.temp_size_in_bytes),
            "total_bytes": int(m.argument_size_in_bytes + m.output_size_in_bytes + m.temp_size_in_bytes),
        }
    except Exception as e:  # memory analysis is backend-dependent
        return {"error": f"{type(e).__name__}: {e}"}


def _fit_linear(x, y):
    A = np.stack([np.ones_like(x), x], 1)
    (c0, c1), *_ = np.linalg.lstsq(A, y, rcond=None)
    return float(c0), float(c1)


def run(quick: bool = False, out_dir=None) -> dict:
    setup_jax(True)
    import jax.numpy as jnp

    import jaxmech as jm

    rng = np.random.default_rng(0)
    batch_sizes = [1, 10, 100, 10**3, 10**4] if quick else [1, 10, 100, 10**3, 10**4, 10**5, 10**6]
    repeat = 3 if quick else 5
    p = {k: jnp.asarray(v) for k, v in DESIGN.items()}

    def solve_fn(mech):
        def f(u, g, p):
            sol = jm.solve(mech, u, p, g)
            return sol.q, sol.status, sol.steps
        return f

    batch_rows = []
    mech1 = chain_mechanism(1)
    for B in batch_sizes:
        th2 = rng.uniform(0, 2 * np.pi, B)
        g = jnp.asarray(chain_solution(1, th2) + 1e-3)
        u = jnp.asarray(th2)
        f, ct = compile_jax(solve_fn(mech1), u, g, p)
        t = time_call(f, u, g, p, repeat=repeat)
        q, st, steps = f(u, g, p)
        row = {"batch": B, "time_s": t, "ns_per_sample": t["median_s"] / B * 1e9, "compile_s": ct,
               "memory": _mem(f), "peak_rss_mb": peak_rss_mb(), "success_rate": float(np.mean(np.asarray(st) == 0)),
               "max_steps_used": int(np.max(np.asarray(steps)))}
        batch_rows.append(row)
        print(f"B={B:>8d} {row['ns_per_sample']:10.1f} ns/sample  compile {ct:.2f}s  mem {row['memory'].get('total_bytes')}", flush=True)
    xs = np.array([r["batch"] for r in batch_rows], float)
    ys = np.array([r["time_s"]["median_s"] for r in batch_rows])
    big = xs >= 1000
    c0, c1 = _fit_linear(xs[big], ys[big])
    batch_fit = {"fixed_overhead_s": float(ys[0]), "per_sample_s_fit_B_ge_1e3": c1, "intercept_s_fit_B_ge_1e3": c0,
                 "bytes_per_sample_largest": batch_rows[-1]["memory"].get("total_bytes", 0) / batch_rows[-1]["batch"]}

    loop_rows = []
    B = 10**2 if quick else 10**3
    ks = [1, 2, 4, 8] if quick else [1, 2, 4, 8, 16, 32]
    th2 = rng.uniform(0, 2 * np.pi, B)
    u = jnp.asarray(th2)
    for k in ks:
        mech = chain_mechanism(k)
        g = jnp.asarray(chain_solution(k, th2) + 1e-3)
        f, ct = compile_jax(solve_fn(mech), u, g, p)
        t = time_call(f, u, g, p, repeat=repeat)
        q, st, steps = f(u, g, p)
        err = float(np.nanmax(np.abs(np.angle(np.exp(1j * (np.asarray(q) - chain_solution(k, th2)))))))
        row = {"loops": k, "m": 2 * k, "batch": B, "time_s": t, "ns_per_sample": t["median_s"] / B * 1e9, "compile_s": ct,
               "memory": _mem(f), "success_rate": float(np.mean(np.asarray(st) == 0)), "max_error_rad": err,
               "max_steps_used": int(np.max(np.asarray(steps)))}
        loop_rows.append(row)
        # written after every k: a hang (seen on a loaded 2-core CPU with m > 2, all threads
        # asleep in futex waits inside XLA) then still leaves the rows measured so far
        write_result("scaling", {"batch": batch_rows, "batch_fit": batch_fit, "loops": loop_rows, "partial": True, "quick": quick},
                     out_dir=out_dir)
        print(f"k={k:>3d} {row['ns_per_sample']:10.1f} ns/sample  compile {ct:.2f}s  err {err:.1e}", flush=True)
    lk = np.log([r["loops"] for r in loop_rows])
    lt = np.log([r["ns_per_sample"] for r in loop_rows])
    slope, inter = np.polyfit(lk, lt, 1)
    loop_fit = {"time_per_sample_exponent": float(slope), "ns_per_sample_k1_fit": float(np.exp(inter))}
    return {"batch": batch_rows, "batch_fit": batch_fit, "loops": loop_rows, "loop_fit": loop_fit, "quick": quick}


def plot(result, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.2))
    b = result["batch"]
    ax1.plot([r["batch"] for r in b], [r["time_s"]["median_s"] for r in b], "o-", label="time (s)")
    mem = [r["memory"].get("total_bytes") for r in b]
    if all(m is not None for m in mem):
        ax1b = ax1.twinx()
        ax1b.plot([r["batch"] for r in b], np.array(mem) / 2**20, "s--", color="C1", label="XLA memory (MiB)")
        ax1b.set_yscale("log"); ax1b.set_ylabel("compiled memory (MiB)")
    ax1.set_xscale("log"); ax1.set_yscale("log"); ax1.set_xlabel("batch size"); ax1.set_ylabel("time (s)")
    ax1.set_title("four-bar solve vs batch size"); ax1.grid(True, which="both", alpha=0.3)
    lp = result["loops"]
    ax2.plot([r["loops"] for r in lp], [r["ns_per_sample"] for r in lp], "o-")
    ax2.set_xscale("log", base=2); ax2.set_yscale("log")
    ax2.set_xlabel("coupled four-bar loops k (m = 2k)"); ax2.set_ylabel("time per sample (ns)")
    ax2.set_title(f"chain of loops, batch {lp[0]['batch']}: ~k^{result['loop_fit']['time_per_sample_exponent']:.2f}")
    ax2.grid(True, which="both", alpha=0.3)
    fig.tight_layout(); fig.savefig(path, dpi=110); plt.close(fig)


def main(argv=None):
    args = base_parser(__doc__.splitlines()[0]).parse_args(argv)
    res = run(args.quick, args.out)
    path = write_result("scaling", res, out_dir=args.out)
    plot(res, args.out / "scaling.png")
    print(res["batch_fit"], res["loop_fit"])
    print("wrote", path)


if __name__ == "__main__":
    main()
