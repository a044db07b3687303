"""Time to first answer: each case in a fresh Python process, cold and warm compile cache.

A user meets the compile before the steady state.  Every case runs as its own subprocess,
first with an empty persistent compilation cache (``cold``), then again with the cache the
first run filled (``warm``).  Inside the subprocess the time is split by JAX's own
``jax.monitoring`` duration events: import, tracing (jaxpr), lowering (jaxpr -> StableHLO),
XLA compile, and the rest (running, Python); cache hits are counted.  ``JAX_DUMP_IR_TO``
collects every compiled module, so the HLO size (StableHLO lines) of each compiled function
is recorded too.  Beside them, in the same run: the seeds' method for the four-bar job (a
scipy ``fsolve`` loop with 2x2 solves for velocity and acceleration, as a new user would
write it) and pylinkage's first call (when installed), each as a whole process.

The warm run of a case also counts the stored executables it loaded (``jaxmech._compile.stored``:
a new process calls the stored executable without tracing, lowering or compiling it).
``import jaxmech`` switches no JAX cache on (it did up to 7ceb4c3): by default a case runs
as a user who leaves JAX's persistent cache off, with the library's store alone;
``--jax-cache`` runs every case as a user who calls ``jaxmech.enable_compile_cache()`` (the
same folder; the command-line cases switch it on themselves).  ``--baseline DIR`` runs every
case a second time, interleaved, with the jaxmech package of another checkout (``DIR``, e.g.
``git worktree add DIR <commit>``), so before/after figures are taken side by side under the
same load; the load average is recorded around every case.

Run: ``python -m benchmarks.latency [--quick] [--cases a,b] [--baseline DIR] [--warm-repeats N] [--jax-cache]``; writes
``results/latency.json``.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

from benchmarks.common import base_parser, write_result

ROOT = Path(__file__).resolve().parents[1]

# --------------------------------------------------------------------------- what each subprocess runs
_PRELUDE = """
import json, os, sys, time
t_start = time.perf_counter()
import jax
jax.config.update("jax_enable_x64", True)
EVENTS = {}
HITS = [0]
def _on_duration(event, duration, **kw):
    EVENTS[event] = EVENTS.get(event, 0.0) + duration
def _on_event(event, **kw):
    if event == "/jax/compilation_cache/cache_hits":
        HITS[0] += 1
jax.monitoring.register_event_duration_secs_listener(_on_duration)
jax.monitoring.register_event_listener(_on_event)
import jax.numpy as jnp
import numpy as np
import jaxmech as jm
if os.environ.get("LATENCY_JAX_CACHE") == "1":  # --jax-cache: the user opts in to JAX's cache
    jm.enable_compile_cache()
t_import = time.perf_counter() - t_start
MARKS = {}
def mark(name, t0):
    MARKS[name] = time.perf_counter() - t0
"""

_EPILOGUE = """
t_job = time.perf_counter() - t_start - t_import
try:
    from jaxmech._compile.stored import store_stats as _stats, wait_for_stores
    wait_for_stores()  # after the job's time is taken: the stores run beside the answer
except ImportError:  # a checkout from before the stored executables (--baseline)
    try:
        from jaxmech.exported import export_stats as _stats
    except ImportError:  # ... or from before the export cache
        _stats = dict
out = {"stored_programs": _stats(), "import_s": t_import, "job_s": t_job, "marks": MARKS,
       "trace_s": EVENTS.get("/jax/core/compile/jaxpr_trace_duration", 0.0),
       "lower_s": EVENTS.get("/jax/core/compile/jaxpr_to_mlir_module_duration", 0.0),
       "xla_compile_s": EVENTS.get("/jax/core/compile/backend_compile_duration", 0.0),
       "cache_hits": HITS[0]}
print("LATENCY_JSON " + json.dumps(out))
"""

_FOURBAR = """
fourbar = jm.Mechanism(
    coords=("theta3", "theta4"), inputs=("theta2",), params=("a", "b", "c", "d"), lengths=("a", "b", "c", "d"),
    constraints=lambda q, u, p: [p.a * jm.cis(u.theta2) + p.b * jm.cis(q.theta3) - p.c * jm.cis(q.theta4) - p.d],
    branch=lambda q, u, p: jnp.sin(q.theta4 - q.theta3),
)
p = dict(a=1.0, b=3.0, c=2.5, d=3.5)
"""

CASES: dict[str, str] = {
    "fourbar_stroke": _FOURBAR + """
t0 = time.perf_counter()
sol, d1, d2 = jm.stroke_kinematics(fourbar, jnp.linspace(0, 2 * np.pi, 361), p, jnp.array([0.4, 1.7]))
jax.block_until_ready(d2)
mark("first_stroke_s", t0)
""",
    "fourbar_rebuild_and_resize": _FOURBAR + """
us = np.linspace(0, 2 * np.pi, 361)
jax.block_until_ready(jm.stroke_kinematics(fourbar, us, p, jnp.array([0.4, 1.7])))
t0 = time.perf_counter()
again = jm.Mechanism(
    coords=("theta3", "theta4"), inputs=("theta2",), params=("a", "b", "c", "d"), lengths=("a", "b", "c", "d"),
    constraints=lambda q, u, p: [p.a * jm.cis(u.theta2) + p.b * jm.cis(q.theta3) - p.c * jm.cis(q.theta4) - p.d],
    branch=lambda q, u, p: jnp.sin(q.theta4 - q.theta3),
)
jax.block_until_ready(jm.stroke_kinematics(again, us, p, jnp.array([0.4, 1.7])))
mark("rebuilt_identical_s", t0)
t0 = time.perf_counter()
jax.block_until_ready(jm.stroke_kinematics(again, np.linspace(0, 2 * np.pi, 362), p, jnp.array([0.4, 1.7])))
mark("one_more_point_s", t0)
""",
    "sixbar_stroke": """
sixbar = jm.Mechanism(
    name="watt_sixbar", coords=("theta3", "theta4", "theta5", "theta6"), inputs=("theta2",),
    params=("a", "b", "c", "d", "e", "f", "g", "h", "k", "gamma"), lengths=("a", "b", "c", "d", "e", "f", "g", "h", "k"),
    signed=("h", "k"),
    constraints=lambda q, u, p: [
        p.a * jm.cis(u.theta2) + p.b * jm.cis(q.theta3) - p.c * jm.cis(q.theta4) - p.d,
        p.d + p.e * jm.cis(q.theta4 + p.gamma) + p.f * jm.cis(q.theta5) - p.g * jm.cis(q.theta6) - (p.h + 1j * p.k),
    ],
)
p = dict(a=1.0, b=3.0, c=2.5, d=3.5, e=1.5, f=3.0, g=2.0, h=5.0, k=2.0, gamma=0.6)
t0 = time.perf_counter()
sol, d1, d2 = jm.stroke_kinematics(sixbar, jnp.linspace(0.3, 0.3 + 2 * np.pi, 361), p, jnp.array([0.6, 1.9, 1.06, 2.15]))
jax.block_until_ready(d2)
mark("first_stroke_s", t0)
""",
    "fourbar_inverse_dynamics": """
fourbar = jm.Mechanism(
    coords=("theta3", "theta4"), inputs=("theta2",), params=("a", "b", "c", "d", "m3", "J3", "g"),
    lengths=("a", "b", "c", "d"),
    constraints=lambda q, u, p: [p.a * jm.cis(u.theta2) + p.b * jm.cis(q.theta3) - p.c * jm.cis(q.theta4) - p.d],
    points={"G3": lambda q, u, p: p.a * jm.cis(u.theta2) + 0.5 * p.b * jm.cis(q.theta3)},
    branch=lambda q, u, p: jnp.sin(q.theta4 - q.theta3),
)
model = jm.Model(fourbar, bodies=[jm.Body("G3", "m3", angle="theta3", inertia="J3")], loads=[jm.Gravity()])
""",
    "sixbar_linkage_reactions": """
watt = jm.Linkage(
    points={"O2": (0, 0), "A": (0.5, 0.866), "B": (3.15, 2.0), "O4": (3.5, 0), "E": (4.6, 1.6), "F": (6.2, 3.2), "O6": (7.0, 1.0)},
    links={"crank": "O2 A", "coupler": "A B", "rocker": "O4 B E", "link5": "E F", "link6": "O6 F"},
    ground="O2 O4 O6", driver="crank", mass={"crank": 1.0, "coupler": 3.0, "rocker": 4.0, "link5": 2.5, "link6": 2.0}, gravity=9.81)
t0 = time.perf_counter()
s = np.linspace(0, 2 * np.pi, 361)
res = watt.inverse_dynamics(jm.Samples(1.05 + 1.2 * np.sin(s), 1.2 * np.cos(s), -1.2 * np.sin(s)))
jax.block_until_ready(res.joints)
mark("first_stroke_with_reactions_s", t0)
""",
    "fourbar_gradient": _FOURBAR + """
t0 = time.perf_counter()
def figure(p):
    sol, d1, d2 = jm.stroke_kinematics(fourbar, jnp.linspace(0, 2 * np.pi, 361), p, jnp.array([0.4, 1.7]))
    return jnp.max(jnp.abs(d1[:, 1, 0]))
g = jax.grad(figure)({k: jnp.asarray(v) for k, v in p.items()})
jax.block_until_ready(g)
mark("gradient_s", t0)
""",
}

for _scene in ("flap_msd", "landing_gear", "arc_track_flap", "sma_flap"):
    CASES[f"run_scene_{_scene}"] = f"""
from jaxmech.scenes import get_scene
from jaxmech.scenes.base import run_scene
t0 = time.perf_counter()
res = run_scene(get_scene("{_scene}"), 101)
jax.block_until_ready(jax.tree_util.tree_leaves(res))
mark("run_scene_s", t0)
"""

CLI_CASES = {"cli_run_fourbar": ["run", "fourbar"], "cli_run_flap_msd": ["run", "flap_msd"],
             # the same four-bar as a linkage file (its programs stored under the file's content)
             "cli_run_fourbar_file": ["run", "examples/linkages/fourbar.toml"]}

FSOLVE_FOURBAR = """
import numpy as np
from scipy.optimize import fsolve
a, b, c, d = 1.0, 3.0, 2.5, 3.5
def f(x, t2):
    t3, t4 = x
    return [a * np.cos(t2) + b * np.cos(t3) - c * np.cos(t4) - d, a * np.sin(t2) + b * np.sin(t3) - c * np.sin(t4)]
th = np.linspace(0, 2 * np.pi, 361)
q = np.zeros((361, 2)); qd = np.zeros_like(q); qdd = np.zeros_like(q); g = np.array([0.4, 1.7])
for i, t in enumerate(th):
    g = fsolve(f, g, args=(t,), xtol=1e-13); q[i] = g
    J = np.array([[-b * np.sin(g[0]), c * np.sin(g[1])], [b * np.cos(g[0]), -c * np.cos(g[1])]])
    qd[i] = np.linalg.solve(J, -np.array([-a * np.sin(t), a * np.cos(t)]))
    w3, w4 = qd[i]
    rhs = -np.array([-a * np.cos(t) - b * np.cos(g[0]) * w3**2 + c * np.cos(g[1]) * w4**2,
                     -a * np.sin(t) - b * np.sin(g[0]) * w3**2 + c * np.sin(g[1]) * w4**2])
    qdd[i] = np.linalg.solve(J, rhs)
"""

PYLINKAGE_FOURBAR = """
import pylinkage as pl
crank = pl.Crank(0, 1, joint0=(0, 0), angle=2 * 3.141592653589793 / 361, distance=1.0)
pin = pl.Revolute(3, 2, joint0=crank, joint1=(3.5, 0), distance0=3.0, distance1=2.5)
linkage = pl.Linkage(joints=(crank, pin), order=(crank, pin))
loci = list(linkage.step(iterations=361))
"""


def _script(case: str) -> str:
    body = CASES[case]
    if case == "fourbar_inverse_dynamics":
        body += """
p = dict(a=1.0, b=3.0, c=2.5, d=3.5, m3=2.0, J3=1.5, g=9.81)
t0 = time.perf_counter()
res = jm.inverse_dynamics(model, jm.ConstantSpeed(0.0, 1.0), jnp.linspace(0, 2 * jnp.pi, 361), p, jnp.array([0.4, 1.7]))
jax.block_until_ready(res.tau)
mark("inverse_dynamics_s", t0)
"""
    return _PRELUDE + textwrap.dedent(body) + _EPILOGUE


def _hlo_sizes(dump_dir: Path) -> dict[str, int]:
    """StableHLO lines of every module JAX lowered (``JAX_DUMP_IR_TO``), by function name."""
    sizes: dict[str, int] = {}
    for f in sorted(dump_dir.glob("*.mlir")):
        n = sum(1 for _ in f.open())
        sizes[f.stem] = n
    return sizes


def _env(cache: Path | None, dump: Path | None, tree: Path | None = None) -> dict[str, str]:
    env = dict(os.environ)
    env["LATENCY_JAX_CACHE"] = "1" if JAX_CACHE[0] else "0"
    if tree is not None:  # the jaxmech package of another checkout shadows this one
        env["PYTHONPATH"] = os.pathsep.join([str(tree), env.get("PYTHONPATH", str(ROOT))])
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    if cache is None:
        env["JAXMECH_COMPILE_CACHE"] = "0"
    else:
        env["JAXMECH_COMPILE_CACHE"] = str(cache)
    if dump is not None:
        env["JAX_DUMP_IR_TO"] = str(dump)
    env.setdefault("PYTHONPATH", str(ROOT))
    return env


def _run(args: list[str], env: dict[str, str], timeout: float = 600, tree: Path | None = None) -> tuple[float, str, int]:
    # run in the tree whose package is measured: ``-c`` and ``-m`` put the working folder first on sys.path
    t0 = time.perf_counter()
    proc = subprocess.run(args, env=env, cwd=tree or ROOT, capture_output=True, text=True, timeout=timeout)
    return time.perf_counter() - t0, proc.stdout + proc.stderr, proc.returncode


def _labels(warm_repeats: int) -> list[str]:
    return ["cold"] + [f"warm{i}" if i else "warm" for i in range(max(1, warm_repeats))]


def _median_warm(out: dict, warm_repeats: int) -> dict:
    """``warm``: the run of median process time among ``warm_repeats`` warm runs (all kept)."""
    if warm_repeats > 1:
        runs = sorted((out.pop(k) for k in _labels(warm_repeats)[1:]), key=lambda r: r["process_s"])
        out["warm"] = runs[len(runs) // 2]
        out["warm_process_s_all"] = [r["process_s"] for r in runs]
    return out


def run_case(case: str, cache: Path, tree: Path | None = None, warm_repeats: int = 1) -> dict:
    """One case, cold (empty ``cache``) then warm (the same ``cache``): the split per run."""
    out: dict = {"load_average_1min_before": os.getloadavg()[0]}
    for label in _labels(warm_repeats):
        dump = Path(tempfile.mkdtemp(prefix="jaxmech-ir-")) if label == "cold" else None
        wall, text, rc = _run([sys.executable, "-c", _script(case)], _env(cache, dump, tree), tree=tree)
        row: dict = {"process_s": wall, "returncode": rc}
        for line in text.splitlines():
            if line.startswith("LATENCY_JSON "):
                row.update(json.loads(line[len("LATENCY_JSON "):]))
        if rc != 0:
            row["error"] = text[-2000:]
        if dump is not None:
            row["hlo_lines"] = _hlo_sizes(dump)
            shutil.rmtree(dump, ignore_errors=True)
        out[label] = row
    out["load_average_1min_after"] = os.getloadavg()[0]
    return _median_warm(out, warm_repeats)


def run_cli(name: str, argv: list[str], cache: Path, out_dir: Path, tree: Path | None = None, warm_repeats: int = 1) -> dict:
    out: dict = {"load_average_1min_before": os.getloadavg()[0]}
    exe = [sys.executable, "-m", "jaxmech"]
    out_dir.mkdir(parents=True, exist_ok=True)  # --out makes only the folder it names (b2d2b5b)
    for label in _labels(warm_repeats):
        wall, text, rc = _run(exe + argv + ["--out", str(out_dir / label)], _env(cache, None, tree), tree=tree)
        out[label] = {"process_s": wall, "returncode": rc, **({"error": text[-2000:]} if rc else {})}
    out["load_average_1min_after"] = os.getloadavg()[0]
    return _median_warm(out, warm_repeats)


def _one(name: str, tmp: Path, tree: Path | None, warm_repeats: int) -> dict:
    tag = "baseline-" if tree is not None else ""
    cache = tmp / f"{tag}{name}"
    if name in CLI_CASES:
        return run_cli(name, CLI_CASES[name], cache, tmp / f"{tag}{name}-out", tree, warm_repeats)
    return run_case(name, cache, tree, warm_repeats)


def _line(name: str, c: dict) -> str:
    return (f"{name:32s} cold {c['cold']['process_s']:6.2f} s   warm {c['warm']['process_s']:6.2f} s"
            + ("" if c["cold"].get("returncode", 0) == 0 and c["warm"].get("returncode", 0) == 0 else "   FAILED"))


def run_reference(script: str) -> dict:
    wall, text, rc = _run([sys.executable, "-c", script], dict(os.environ))
    return {"process_s": wall, "returncode": rc, **({"error": text[-500:]} if rc else {})}


# --jax-cache: every case calls jaxmech.enable_compile_cache() after its import
JAX_CACHE = [False]


def run(quick: bool = False, cases: list[str] | None = None, baseline: Path | None = None, warm_repeats: int = 1,
        jax_cache: bool = False) -> dict:
    JAX_CACHE[0] = jax_cache
    names = cases or (["fourbar_stroke", "fourbar_rebuild_and_resize"] if quick else list(CASES) + list(CLI_CASES))
    result: dict = {"cases": {}, "reference": {}, "jax_cache_opt_in": jax_cache}
    result["reference"]["fsolve_fourbar"] = min((run_reference(FSOLVE_FOURBAR) for _ in range(3)), key=lambda r: r["process_s"])
    result["reference"]["python_empty"] = run_reference("pass")
    try:
        import pylinkage  # noqa: F401

        result["reference"]["pylinkage_fourbar"] = run_reference(PYLINKAGE_FOURBAR)
    except ImportError:
        result["reference"]["pylinkage_fourbar"] = {"skipped": "pylinkage not installed (pip install -e '.[bench]')"}
    if baseline is not None:
        result["baseline"] = {"tree": baseline.name, "cases": {}}
        result["after_over_baseline"] = {}
    with tempfile.TemporaryDirectory(prefix="jaxmech-latency-") as tmp:
        for name in names:
            if baseline is not None:  # before, then after, back to back under the same load
                b = result["baseline"]["cases"][name] = _one(name, Path(tmp), baseline, warm_repeats)
                print(_line(name + " (baseline)", b), flush=True)
            c = result["cases"][name] = _one(name, Path(tmp), None, warm_repeats)
            print(_line(name, c), flush=True)
            if baseline is not None:
                result["after_over_baseline"][name] = {k: c[k]["process_s"] / b[k]["process_s"] for k in ("cold", "warm")}
    fs = result["reference"]["fsolve_fourbar"]["process_s"]
    fb = result["cases"].get("fourbar_stroke")
    if fb:
        result["ratios"] = {
            "fourbar_process_vs_fsolve_process": fb["cold"]["process_s"] / fs,
            "fourbar_after_import_s": fb["cold"].get("job_s"),
        }
    return result


def main(argv=None):
    parser = base_parser(__doc__.splitlines()[0])
    parser.add_argument("--cases", default=None, help="comma-separated case names (default: all)")
    parser.add_argument("--baseline", default=None, help="a checkout of another commit: run every case with its jaxmech too, interleaved")
    parser.add_argument("--warm-repeats", type=int, default=1, help="warm runs per case; the median is reported (a shared machine is noisy)")
    parser.add_argument("--jax-cache", action="store_true", help="every case switches JAX's persistent cache on (jaxmech.enable_compile_cache)")
    args = parser.parse_args(argv)
    cases = args.cases.split(",") if args.cases else None
    baseline = Path(args.baseline).resolve() if args.baseline else None
    res = run(quick=args.quick, cases=cases, baseline=baseline, warm_repeats=args.warm_repeats, jax_cache=args.jax_cache)
    path = write_result("latency", res, out_dir=args.out)
    print(json.dumps(res.get("ratios", {}), indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
