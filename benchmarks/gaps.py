"""Sweeps whose designs fail beside sweeps whose designs all assemble, side by side.

A design sweep exists to find where designs stop working, so real sweeps hold designs with a
gap (a stretch of the stroke where a loop cannot close).  Four ``sweep_scene`` cases, 37
points a stroke:

- ``fourbar_feasible``: the built-in four-bar, ``b`` in (2.8, 3.2), ``c`` in (2.3, 2.7): every
  design assembles over its whole turn;
- ``fourbar_gapped``: ``a`` in (0.9, 1.6), ``b`` in (2.5, 3.2), ``c`` in (2.0, 2.7): about one
  design in ten has a gap;
- ``watt_3pct``: the README's Watt six-bar ``Linkage`` (crank at 2 pi rad/s), its first three
  lengths +-3%: every design assembles;
- ``watt_10pct``: its ten geometric parameters (lengths, the plate angle, the ground pivots)
  +-10%: about a third of the designs have a gap.

Each case runs in a fresh Python process with an empty compile store (``first_call_s``: the
first ``sweep_scene`` call of a new process, its compiles included), then ``--repeat`` warm
calls of the same sweep (``warm_s``: the median).  Reported per case: designs/s warm, failed
designs and points, and per pair the gapped case's throughput and first call against the
feasible one's (the ratios the acceptance reads).  Beside them, the core kernel's steady
state: ``stroke_kinematics`` of the same feasible four-bar designs (one call, every design's
stroke, warm), poses/s against the sweep's.  The load average is recorded before and after.

Statuses: ``--statuses FILE.npz`` keeps every case's per-point statuses; ``--compare
FILE.npz`` counts, per case, the points whose status differs from that file's (the same
designs: the tables are seeded), and ``--package DIR`` runs the cases with another
checkout's ``jaxmech`` (its folder).  So ``python -m benchmarks.gaps --package OLD
--statuses old.npz`` then ``python -m benchmarks.gaps --compare old.npz`` says whether a
change moved any status.

Run: ``python -m benchmarks.gaps [--quick] [--designs D4] [--designs-six D6] [--repeat R]
[--statuses F] [--compare F] [--package DIR]``; writes ``results/gaps.json``.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
import time

from benchmarks.common import base_parser, write_result

POINTS = 37


def watt():
    """The README's Watt six-bar, as its drawing."""
    import jaxmech as jm

    return jm.Linkage(
        points={"O2": (0, 0), "A": (0.5, 0.866), "B": (3.15, 2.0), "O4": (3.5, 0), "E": (4.6, 1.6), "F": (6.2, 3.2), "O6": (7.0, 1.0)},
        links={"crank": "O2 A", "coupler": "A B", "rocker": "O4 B E", "link5": "E F", "link6": "O6 F"},
        ground="O2 O4 O6", driver="crank", mass={"crank": 1.0, "coupler": 3.0, "rocker": 4.0, "link5": 2.5, "link6": 2.0},
        gravity=9.81)


def geometric(scene) -> list[str]:
    """The drawing's geometric parameters of a linkage scene: lengths, angles, ground pivots."""
    return [k for k in scene.defaults if k.startswith(("len_", "ang_", "x_", "y_")) and "_G_" not in k and k not in ("x_O2", "y_O2", "y_O4")]


def case(name: str, d4: int, d6: int):
    """``(scene, table)`` of a case."""
    from jaxmech.sweep import random_designs

    if name.startswith("fourbar"):
        ranges = {"b": (2.8, 3.2), "c": (2.3, 2.7)} if name == "fourbar_feasible" else {"a": (0.9, 1.6), "b": (2.5, 3.2), "c": (2.0, 2.7)}
        return "fourbar", random_designs(ranges, d4, seed=0)
    lk = watt()
    # Linkage.scene (a checkout before it, --package: the function it calls)
    scene = lk.scene(speed=2 * math.pi) if hasattr(lk, "scene") else __import__("jaxmech.scenes.linkage_scene", fromlist=["x"]).linkage_scene(lk, speed=2 * math.pi)
    d = scene.defaults
    # sorted: the same table for any order of the scene's parameters (a seeded draw per name)
    names = sorted(k for k in d if k.startswith("len_") and "_G_" not in k)[:3] if name == "watt_3pct" else sorted(geometric(scene))
    frac = 0.03 if name == "watt_3pct" else 0.10
    ranges = {k: tuple(sorted((float(d[k]) * (1 - frac), float(d[k]) * (1 + frac)))) for k in names}
    return scene, random_designs(ranges, d6, seed=0)


def child(name: str, d4: int, d6: int, repeat: int, package: str | None = None, statuses: str | None = None) -> dict:
    if package:  # another checkout's jaxmech, before the installed one
        sys.path.insert(0, package)
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    from jaxmech.sweep import sweep_scene

    scene, table = case(name, d4, d6)
    d = len(next(iter(table.values())))
    t0 = time.perf_counter()
    res = sweep_scene(scene, table=table, points=POINTS, progress=False)
    first = time.perf_counter() - t0
    warm = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        sweep_scene(scene, table=table, points=POINTS, progress=False)
        warm.append(time.perf_counter() - t0)
    st = np.asarray(res.status)
    if statuses:
        np.save(statuses, st)
    out = dict(designs=d, points=POINTS, first_call_s=first, warm_s=float(np.median(warm)), warm_all_s=warm,
               designs_per_s=d / float(np.median(warm)), poses_per_s=d * POINTS / float(np.median(warm)),
               failed_designs=int(np.sum(np.any(st != 0, axis=1))), failed_points=int(np.sum(st != 0)),
               status_counts={int(k): int(v) for k, v in zip(*np.unique(st, return_counts=True))})
    if name == "fourbar_feasible":  # the core kernel's steady state on the same designs
        import jaxmech as jm
        from jaxmech.scenes import get_scene

        sc = get_scene("fourbar")
        p = {k: np.full(d, float(v)) for k, v in sc.defaults.items()}
        p.update(table)
        us = np.linspace(0.0, 2 * np.pi, POINTS)
        guess = np.asarray(sc.guess(sc.defaults))
        mech = sc.mechanism
        pm = {k: p[k] for k in mech.params}
        jax.block_until_ready(jm.stroke_kinematics(mech, us, pm, guess))
        times = []
        for _ in range(max(repeat, 3)):
            t0 = time.perf_counter()
            jax.block_until_ready(jm.stroke_kinematics(mech, us, pm, guess))
            times.append(time.perf_counter() - t0)
        out["core_stroke_kinematics_poses_per_s"] = d * POINTS / float(np.median(times))
    return out


def run_case(name: str, d4: int, d6: int, repeat: int, package: str | None = None):
    """``(figures, statuses (D, points))`` of a case, run in a fresh process."""
    import numpy as np

    with tempfile.TemporaryDirectory() as store:
        env = dict(os.environ, JAXMECH_COMPILE_CACHE=store, PYTHONPATH=os.pathsep.join([os.getcwd(), os.environ.get("PYTHONPATH", "")]))
        load = os.getloadavg()
        keep = os.path.join(store, "status.npy")
        cmd = [sys.executable, "-m", "benchmarks.gaps", "--child", name, "--designs", str(d4), "--designs-six", str(d6),
               "--repeat", str(repeat), "--status-file", keep] + (["--package", package] if package else [])  # fmt: skip
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise RuntimeError(f"{name} failed:\n{done.stderr[-3000:]}")
        out = json.loads(done.stdout.strip().splitlines()[-1])
        out["load_before_after"] = [load[0], os.getloadavg()[0]]
        return out, np.load(keep)


def main(argv=None):
    parser = base_parser(__doc__)
    parser.add_argument("--designs", type=int, default=2048, help="four-bar designs per sweep (default 2048)")
    parser.add_argument("--designs-six", type=int, default=1024, help="six-bar designs per sweep (default 1024)")
    parser.add_argument("--repeat", type=int, default=3, help="warm calls per case (median reported)")
    parser.add_argument("--statuses", default=None, help="keep every case's per-point statuses in this .npz")
    parser.add_argument("--compare", default=None, help="count the statuses that differ from this .npz's")
    parser.add_argument("--package", default=None, help="run the cases with the jaxmech of this checkout (its folder)")
    parser.add_argument("--child", default=None, help=argparse_hidden())
    parser.add_argument("--status-file", default=None, help=argparse_hidden())
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(child(args.child, args.designs, args.designs_six, args.repeat, args.package, args.status_file)))
        return
    import numpy as np

    d4, d6 = (256, 256) if args.quick else (args.designs, args.designs_six)
    cases, statuses = {}, {}
    for name in ("fourbar_feasible", "fourbar_gapped", "watt_3pct", "watt_10pct"):
        cases[name], statuses[name] = run_case(name, d4, d6, args.repeat, args.package)
        c = cases[name]
        print(f"{name:18s} {c['designs']:6d} designs  first call {c['first_call_s']:6.2f} s  warm {c['warm_s']:7.3f} s  "
              f"{c['designs_per_s']:8.0f} designs/s  failed designs {c['failed_designs']}", flush=True)
    ratios = {}
    for ok, gap in (("fourbar_feasible", "fourbar_gapped"), ("watt_3pct", "watt_10pct")):
        ratios[gap] = dict(throughput_vs_feasible=cases[gap]["designs_per_s"] / cases[ok]["designs_per_s"],
                           first_call_vs_feasible=cases[gap]["first_call_s"] / cases[ok]["first_call_s"])
        print(f"{gap}: designs/s {ratios[gap]['throughput_vs_feasible']:.2f}x the feasible sweep's, "
              f"first call {ratios[gap]['first_call_vs_feasible']:.2f}x")
    core = cases["fourbar_feasible"].get("core_stroke_kinematics_poses_per_s")
    if core:
        ratios["fourbar_feasible_sweep_vs_core_kernel"] = cases["fourbar_feasible"]["poses_per_s"] / core
        print(f"four-bar sweep {cases['fourbar_feasible']['poses_per_s']:.3g} poses/s, core stroke_kinematics {core:.3g} poses/s")
    if args.statuses:
        np.savez(args.statuses, **statuses)
    compared = None
    if args.compare:
        old = np.load(args.compare)
        compared = {k: dict(points_differing=int(np.sum(old[k] != v)), designs_differing=int(np.sum(np.any(old[k] != v, axis=1))))
                    for k, v in statuses.items() if k in old and old[k].shape == v.shape}  # fmt: skip
        print("statuses differing from", args.compare, compared)
    if args.package:
        print("(run with the jaxmech of", args.package, "- results not written)")
        return
    write_result("gaps", dict(cases=cases, ratios=ratios, quick=bool(args.quick), statuses_vs=compared), out_dir=args.out)


def argparse_hidden():
    import argparse

    return argparse.SUPPRESS


if __name__ == "__main__":
    main()
