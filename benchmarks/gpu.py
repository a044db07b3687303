"""Large sweeps on the accelerator JAX sees, float64 and float32, beside the same machine's CPU.

``stroke_kinematics`` (positions, velocities, accelerations) of D designs x 1000 crank positions,
for the four-bar (``kinematics.py``'s designs x positions case) and a Watt six-bar (``latency.py``'s).
Every (mechanism, platform, dtype) runs in a fresh process (``JAX_ENABLE_X64``, ``JAX_PLATFORMS``);
per row: compile_s, the median run time, poses/s, the fraction CONVERGED, and errors on the first
200 designs (saved by the children, compared here): float64 against the four-bar's closed form or
the six-bar's loop residuals, float32 against float64 on the same platform, the accelerator's
float64 against the CPU's.  Sizes shrink and rows are skipped to fit ``--budget-s``; the JSON is
rewritten after every row.  See README.md.

Run: ``python -m benchmarks.gpu [--quick] [--budget-s S] [--out DIR]``; writes ``DIR/gpu.json``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from benchmarks.common import base_parser, compile_jax, machine_info, time_call, write_result
from benchmarks.fourbar_reference import ALPHA, OMEGA, closed_form_numpy

ENV0 = dict(os.environ)  # the children's environment, before this process pins itself to the CPU
ROOT = Path(__file__).resolve().parents[1]
N_POS, KEEP = 1000, 200  # crank positions per design; designs saved for the error checks
SIX_P = dict(a=1.0, b=3.0, c=2.5, d=3.5, e=1.5, f=3.0, g=2.0, h=5.0, k=2.0, gamma=0.6)
MECHS = {  # base design, spread (+-), guess at the first position, first position
    "fourbar": (dict(a=1.0, b=3.0, c=2.5, d=3.5), dict(a=0.2, b=0.2, c=0.2, d=0.2), (0.2, 1.2), 0.0),
    "sixbar": (SIX_P, dict(a=0.2, b=0.2, c=0.2, d=0.2, e=0.1, f=0.1, g=0.1, h=0.1, k=0.1, gamma=0.05),
               (0.6, 1.9, 1.06, 2.15), 0.3),
}


def designs(mech: str, n: int) -> dict[str, np.ndarray]:
    """Design i (the same for every n): base + spread * (2 frac(0.5 + i sqrt(prime_k)) - 1)."""
    base, spread, _, _ = MECHS[mech]
    i = np.arange(n, dtype=np.float64)
    primes = (2, 3, 5, 7, 11, 13, 17, 19, 23, 29)
    return {k: base[k] + spread[k] * (2 * np.mod(0.5 + i * np.sqrt(pr), 1.0) - 1) for k, pr in zip(base, primes)}


# --------------------------------------------------------------------------- child process
def _mechanism(jm, name):
    if name == "fourbar":
        from jaxmech.scenes.classic import fourbar_mechanism

        return fourbar_mechanism
    return jm.Mechanism(
        name="watt_sixbar", coords=("theta3", "theta4", "theta5", "theta6"), inputs=("theta2",),
        params=tuple(SIX_P), lengths=("a", "b", "c", "d", "e", "f", "g", "h", "k"), signed=("h", "k"),
        constraints=lambda q, u, p: [
            p.a * jm.cis(u.theta2) + p.b * jm.cis(q.theta3) - p.c * jm.cis(q.theta4) - p.d,
            p.d + p.e * jm.cis(q.theta4 + p.gamma) + p.f * jm.cis(q.theta5) - p.g * jm.cis(q.theta6) - (p.h + 1j * p.k),
        ],
    )


def child(spec: dict) -> None:
    """Run one (mechanism, platform, dtype) at each size that fits the deadline; one JSON line per row."""
    import jax
    import jax.numpy as jnp

    import jaxmech as jm

    if (jnp.asarray(1.0).dtype == jnp.float64) != spec["x64"]:  # a jax that ignores JAX_ENABLE_X64
        jax.config.update("jax_enable_x64", spec["x64"])
    dev, dtype = jax.devices()[0], jnp.asarray(1.0).dtype
    mech = _mechanism(jm, spec["mech"])
    base = {"mech": spec["mech"], "platform": dev.platform, "device_kind": dev.device_kind,
            "device_count": jax.device_count(), "dtype": dtype.name, "positions": N_POS, "jax": jax.__version__}

    def emit(row):
        with open(spec["rows"], "a") as fh:
            fh.write(json.dumps({**base, **row}) + "\n")

    if spec["want"] != "cpu" and dev.platform == "cpu":
        return emit({"designs": 0, "skipped": "no accelerator in this process"})

    def fn(us, p, g):
        sol, d1, d2 = jm.stroke_kinematics(mech, us, p, g)
        q1, q2 = d1[..., 0], d2[..., 0, 0]
        return sol.q, q1 * OMEGA, q1 * ALPHA + q2 * OMEGA**2, sol.status

    reps = lambda t1: 5 if t1 < 0.5 else 3 if t1 < 5 else 2  # noqa: E731
    ns, comp = spec.get("hint_ns"), spec.get("hint_compile_s", 0.0)
    us = jnp.asarray(MECHS[spec["mech"]][3] + np.linspace(0.0, 2 * np.pi, N_POS, endpoint=False), dtype)
    for j, d in enumerate(spec["sizes"]):
        t1p = d * N_POS * (ns or 0.0) * 1e-9  # predicted: a compile, a first call and the repeats
        need = 1.2 * comp + t1p * (1 + reps(t1p)) + 2.0
        if (ns or j) and time.time() + need > spec["deadline"]:
            if not spec.get("pick_one") or j == len(spec["sizes"]) - 1:
                emit({"designs": d, "skipped": f"predicted {need:.0f} s, past this row's share of --budget-s"})
            continue
        try:
            pd = {k: jnp.asarray(v, dtype) for k, v in designs(spec["mech"], d).items()}
            g0 = MECHS[spec["mech"]][2]
            gd = jnp.broadcast_to(jnp.asarray(g0, dtype), (d, len(g0)))
            f, comp = compile_jax(fn, us, pd, gd)
            try:
                temp_mb = f.memory_analysis().temp_size_in_bytes / 2**20
            except Exception:
                temp_mb = None
            t0 = time.perf_counter()
            out = jax.block_until_ready(f(us, pd, gd))
            t1 = time.perf_counter() - t0
            n_st = jax.jit(lambda st: jnp.sum(st.reshape(-1, 1) == jnp.arange(6), axis=0))(out[3])  # per status code
            counts = {jm.Status(c).name: int(n) for c, n in enumerate(np.asarray(n_st))}
            s, npz = min(d, KEEP), spec["npz"] + f"_{d}.npz"
            np.savez(npz, us=np.asarray(us), **{k: np.asarray(v[:s]) for k, v in zip(("q", "qd", "qdd", "status"), out)},
                     **{k: np.asarray(v[:s]) for k, v in pd.items()})
            del out
            t = time_call(f, us, pd, gd, repeat=reps(t1), warmup=0)
            ns = t["median_s"] / (d * N_POS) * 1e9
            emit({"designs": d, "poses": d * N_POS, "compile_s": comp, "first_run_s": t1, "time_s": t, "run_s": t["median_s"],
                  "poses_per_s": d * N_POS / t["median_s"], "ns_per_pose": ns, "temp_mb": temp_mb, "npz": npz,
                  "converged_fraction": counts["CONVERGED"] / (d * N_POS), "statuses": {k: v for k, v in counts.items() if v},
                  "load_average": list(os.getloadavg())})
            del f
            if spec.get("pick_one"):
                break
        except Exception as e:  # out of memory on the device, say: recorded, the next size is tried
            emit({"designs": d, "error": f"{type(e).__name__}: {str(e)[:300]}"})


# --------------------------------------------------------------------------- errors (parent)
def _diff(x, ref, angle=False):
    x, ref = np.asarray(x, np.float64), np.asarray(ref, np.float64)
    d = np.angle(np.exp(1j * (x - ref))) if angle else x - ref
    a = float(np.nanmax(np.abs(d))) if np.isfinite(d).any() else None
    return {"abs": a, "rel": a / float(np.nanmax(np.abs(ref))) if a is not None else None}


def _compare(z, ref):
    """Largest differences of angles (rad), velocities (rad/s), accelerations (rad/s^2), both converged."""
    ok = (z["status"] == 0) & (ref["status"] == 0)
    m = lambda k: np.where(ok[..., None], z[k], np.nan)  # noqa: E731
    return {"pos": _diff(m("q"), ref["q"], True), "vel": _diff(m("qd"), ref["qd"]), "acc": _diff(m("qdd"), ref["qdd"]),
            "samples": int(ok.sum())}


def _closed(z):
    th = z["us"][None, :].astype(np.float64)
    t3, t4, w3, w4, a3, a4 = closed_form_numpy(th, *[z[k][:, None].astype(np.float64) for k in "abcd"])
    return {"q": np.stack([t3, t4], -1), "qd": np.stack([w3, w4], -1), "qdd": np.stack([a3, a4], -1), "status": np.zeros(t3.shape, int)}


def _sixbar_residual(z):
    """Max |loop| (m), |d loop/dt| (m/s), |d2 loop/dt2| (m/s^2) of both loops over converged samples."""
    p = {k: z[k][:, None].astype(np.float64) for k in SIX_P}
    q, w, al = (np.moveaxis(z[k].astype(np.float64), -1, 0) for k in ("q", "qd", "qdd"))
    th2 = np.broadcast_to(z["us"].astype(np.float64), q[0].shape)
    # (length, angle, angular velocity, angular acceleration) of each term of each loop, and the loop's constant
    loops = [([(p["a"], th2, OMEGA, ALPHA), (p["b"], q[0], w[0], al[0]), (-p["c"], q[1], w[1], al[1])], -p["d"]),
             ([(p["e"], q[1] + p["gamma"], w[1], al[1]), (p["f"], q[2], w[2], al[2]), (-p["g"], q[3], w[3], al[3])],
              p["d"] - p["h"] - 1j * p["k"])]
    out = np.zeros(3)
    for terms, const in loops:
        e = [(r * np.exp(1j * t), v, a) for r, t, v, a in terms]
        sums = (sum(x for x, _, _ in e) + const, sum(1j * v * x for x, v, _ in e), sum((1j * a - v * v) * x for x, v, a in e))
        for i, s in enumerate(sums):
            out[i] = max(out[i], np.nanmax(np.where(z["status"] == 0, np.abs(s), np.nan)))
    return dict(zip(("pos_m", "vel_m_s", "acc_m_s2"), out.tolist()))


_NPZ: dict = {}


def add_errors(rows):
    """Fill each row's errors from the saved first designs (arrays cached: the JSON is rewritten per row)."""
    load = lambda p: _NPZ[p] if p in _NPZ else _NPZ.setdefault(p, dict(np.load(p)))  # noqa: E731
    for r in (r for r in rows if r.get("npz")):
        z = load(r["npz"])
        if r["mech"] == "fourbar":
            r["err_vs_closed_form"] = _compare(z, _closed(z))
        elif r["dtype"] == "float64":
            r["f64_loop_residual"] = _sixbar_residual(z)
        # float32 against float64 on the same platform; an accelerator's float64 against the CPU's
        key, plat = ("err_vs_f64", r["platform"]) if r["dtype"] == "float32" else ("err_vs_cpu_f64", "cpu")
        refs = [x for x in rows if x.get("npz") and x["mech"] == r["mech"] and x["dtype"] == "float64" and x["platform"] == plat]
        if refs and not (key == "err_vs_cpu_f64" and r["platform"] == "cpu"):
            ref = load(min(refs, key=lambda x: abs(x["designs"] - r["designs"]))["npz"])
            s = min(len(ref["a"]), len(z["a"]))
            r[key] = _compare({k: v[:s] for k, v in z.items() if k != "us"}, {k: v[:s] for k, v in ref.items() if k != "us"})


# --------------------------------------------------------------------------- parent
def _probe(env):
    code = "import jax, json; d = jax.devices()[0]; print(json.dumps([d.platform, d.device_kind, jax.device_count()]))"
    try:
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
        return json.loads(out.stdout.strip().splitlines()[-1]) if out.returncode == 0 else None
    except Exception:
        return None


def _env(platform, x64):
    env = dict(ENV0, JAX_ENABLE_X64="1" if x64 else "0", JAXMECH_COMPILE_CACHE="0",
               PYTHONPATH=os.pathsep.join([str(ROOT)] + [x for x in [ENV0.get("PYTHONPATH")] if x]))
    env.pop("JAX_PLATFORMS", None)
    if platform:
        env["JAX_PLATFORMS"] = platform
    return env


def main(argv=None):
    ap = base_parser(__doc__.splitlines()[0])
    ap.add_argument("--budget-s", type=float, default=None, help="wall-clock budget of the whole run (default 200, quick 100)")
    ap.add_argument("--child", help="internal: run one configuration, given as JSON")
    args = ap.parse_args(argv)
    if args.child:
        return child(json.loads(args.child))
    t_start = time.time()
    budget = args.budget_s or (100.0 if args.quick else 200.0)
    os.environ["JAX_PLATFORMS"] = "cpu"  # this process (machine_info) must not take the accelerator's memory
    tmp = tempfile.mkdtemp(prefix="jaxmech_gpu_")
    acc, acc_env = None, None
    for plat in ("cuda", None):  # JAX_PLATFORMS=cuda first, then JAX's own choice
        got = _probe(_env(plat, False))
        if got and got[0] != "cpu":
            acc, acc_env = got, plat
            break
    print("accelerator:", acc or "none found (CPU rows only)", flush=True)
    machine = machine_info()
    machine.update(jax_backend=None, jax_devices=None, accelerator=acc, jax_enable_x64="per row (JAX_ENABLE_X64 in each child)")
    q = args.quick
    gpu4, cpu4, gpu6, cpu6 = ([1000], [100, 1000], [1000], [100]) if q else ([10**4, 10**5], [10**3, 10**4], [10**4, 10**5], [10**3, 10**4])
    # in order of priority, with each one's share (weight) of the budget left when it starts
    plan = [dict(mech=m, want=w, x64=x64, sizes=sz, weight=wt) for m, w, sz, wt in
            (("fourbar", "accelerator", gpu4, 5), ("fourbar", "cpu", cpu4, 2), ("sixbar", "accelerator", gpu6, 3), ("sixbar", "cpu", cpu6, 1.5))
            for x64 in (True, False) if acc or w == "cpu"]
    # the accelerator's largest four-bar size on this machine's CPU, or the largest that fits
    plan += [dict(mech="fourbar", want="cpu", x64=x64, sizes=None, weight=2, large=True) for x64 in (True, False)]
    rows, notes = [], {"accelerator": acc, "JAX_PLATFORMS_for_accelerator": acc_env}

    def save():
        add_errors(rows)
        payload = {"machine": machine, "quick": q, "budget_s": budget, "elapsed_s": time.time() - t_start,
                   "positions": N_POS, "error_designs": KEEP, "drive": {"omega_rad_s": OMEGA, "alpha_rad_s2": ALPHA},
                   "rows": [{k: v for k, v in r.items() if k != "npz"} for r in rows], "ratios": ratios(rows), "notes": notes}
        return write_result("gpu", payload, out_dir=args.out)

    for i, item in enumerate(plan):
        left = budget - (time.time() - t_start)
        tag = f"{item['mech']}_{item['want']}_{'f64' if item['x64'] else 'f32'}{'_large' if item.get('large') else ''}"
        if left < (15 if q else 25):
            notes[tag] = f"skipped: {left:.0f} s of the budget left"
            continue
        allow = max(15.0, left * item["weight"] / sum(x["weight"] for x in plan[i:]))
        spec = dict(mech=item["mech"], want=item["want"], x64=item["x64"], sizes=item["sizes"], deadline=time.time() + allow,
                    rows=os.path.join(tmp, tag + ".jsonl"), npz=os.path.join(tmp, tag))
        if item.get("large"):
            done = [r for r in rows if r.get("run_s") and r["mech"] == "fourbar"]
            cpu_same = [r for r in done if r["platform"] == "cpu" and r["dtype"] == ("float64" if item["x64"] else "float32")]
            top = max([r["designs"] for r in done if r["platform"] != "cpu"] or [(gpu4 if acc else [10 * cpu4[-1]])[-1]])
            if not cpu_same or top <= max(r["designs"] for r in cpu_same):
                notes[tag] = "skipped: no CPU timing to size it, or nothing larger than the CPU rows"
                continue
            ref = max(cpu_same, key=lambda r: r["designs"])
            spec.update(sizes=[x for x in (top, top // 2, top // 4) if x > ref["designs"]], pick_one=True,
                        hint_ns=ref["ns_per_pose"], hint_compile_s=ref["compile_s"])
        print(f"-- {tag}: sizes {spec['sizes']}, {allow:.0f} s allowed", flush=True)
        env = _env(acc_env if item["want"] != "cpu" else "cpu", item["x64"])
        with open(os.path.join(tmp, tag + ".log"), "w") as log:
            proc = subprocess.Popen([sys.executable, "-m", "benchmarks.gpu", "--child", json.dumps(spec)], cwd=ROOT, env=env,
                                    stdout=log, stderr=subprocess.STDOUT)
            seen, started, grace = 0, time.time(), (20 if q else 40)
            while True:  # a child past its share is killed; one with no row yet gets 2 minutes (a slow compile)
                kill_at = min(max(spec["deadline"] + grace, started + (0 if seen else 60 if q else 120)), t_start + budget + 15)
                rc = proc.poll()
                lines = open(spec["rows"]).read().split("\n")[:-1] if os.path.exists(spec["rows"]) else []  # whole lines
                for line in lines[seen:]:
                    rows.append(dict(json.loads(line), large_cpu_row=bool(item.get("large"))))
                    save()
                    print(f"   {_fmt(rows[-1])}", flush=True)
                seen = len(lines)
                if rc is not None:
                    break
                if time.time() > kill_at:
                    proc.kill()
                    proc.wait()
                    notes[tag] = "killed at the time budget"
                    break
                time.sleep(0.5)
        if proc.returncode not in (0, None) and tag not in notes:
            notes[tag] = f"exit {proc.returncode}: " + open(os.path.join(tmp, tag + ".log")).read()[-800:]
    path = save()
    shutil.rmtree(tmp, ignore_errors=True)
    print(f"\n{'mech':8s} {'platform':8s} {'dtype':8s} {'designs':>8s} {'poses':>10s} {'compile_s':>9s} {'run_s':>9s} "
          f"{'poses/s':>9s} {'pos_err':>8s} {'vel_err':>8s} {'acc_err':>8s}  {'error':18s} converged")
    for r in rows:
        print(_fmt(r))
    for x in ratios(rows):
        print(f"{x['mech']} {x['dtype']}: accelerator / CPU poses/s {x['accelerator_over_cpu']:.1f}x ({x['accelerator_poses_per_s']:.3g}"
              f" at D={x['accelerator_designs']} over {x['cpu_poses_per_s']:.3g} at D={x['cpu_designs']})")
    print(f"elapsed {time.time() - t_start:.0f} s; notes: {notes}\nwrote {path}")


def _fmt(r):
    head = f"{r['mech']:8s} {r['platform']:8s} {r['dtype']:8s} {r['designs']:>8d}"
    if not r.get("run_s"):
        return f"{head}  {r.get('skipped') or r.get('error')}"
    which = next((k for k in ("err_vs_f64", "err_vs_closed_form", "f64_loop_residual") if k in r), None)
    vals = [v["abs"] if isinstance(v, dict) else v for k, v in (r.get(which) or {}).items() if k != "samples"] or [None] * 3
    err = " ".join("     nan" if v is None else f"{v:8.1e}" for v in vals)
    return (f"{head} {r['poses']:>10.2e} {r['compile_s']:9.2f} {r['run_s']:9.4f} {r['poses_per_s']:9.3g} {err}  "
            f"{(which or '-'):18s} {r['converged_fraction']:.6f}")


def ratios(rows):
    """Accelerator over CPU throughput per mechanism and dtype: the accelerator's largest size, against the
    CPU at the same size if it ran it, else the CPU's largest."""
    out = []
    for mech in ("fourbar", "sixbar"):
        for dt in ("float64", "float32"):
            done = [r for r in rows if r.get("run_s") and r["mech"] == mech and r["dtype"] == dt]
            acc, cpu = [r for r in done if r["platform"] != "cpu"], [r for r in done if r["platform"] == "cpu"]
            if acc and cpu:
                g = max(acc, key=lambda r: r["poses"])
                c = max(cpu, key=lambda r: (r["poses"] == g["poses"], r["poses"]))
                out.append({"mech": mech, "dtype": dt, "accelerator_over_cpu": g["poses_per_s"] / c["poses_per_s"],
                            "accelerator_poses_per_s": g["poses_per_s"], "cpu_poses_per_s": c["poses_per_s"],
                            "accelerator_designs": g["designs"], "cpu_designs": c["designs"]})
    return out


if __name__ == "__main__":
    main()
