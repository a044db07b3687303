"""Live exploration: time of one ``jaxmech.viz.live.update`` (a slider moved) after warm-up.

The live notebook (``notebooks/live_flap_msd.ipynb``) calls ``update(view, **params)`` from
its widget callback; here the same function is called without a browser.  A "slider move"
changes one flap_msd parameter (a link length or a load, cycling over them, by up to
+-10 % of its default) and includes everything the user waits for: the scene run
(``run_scene``: the compiled stroke, torque and outputs), moving the artists and
rendering the figure to PNG.  Pose-slider moves (no solve) are timed apart.  The first
call (the compile) is reported separately; the target is 100 ms after warm-up.

Run: ``python -m benchmarks.live [--quick]``; writes ``results/live.json``.
"""

from __future__ import annotations

import os
import time

import numpy as np

from benchmarks.common import base_parser, setup_jax, write_result

NAMES = ("a", "b", "c", "d", "p", "g", "h", "z", "U", "M", "m")
TARGET_MS = 100.0


def _stats(ms):
    ms = np.asarray(ms)
    return {"median_ms": float(np.median(ms)), "p95_ms": float(np.percentile(ms, 95)), "max_ms": float(ms.max()),
            "min_ms": float(ms.min()), "n": int(ms.size)}


def run(quick: bool) -> dict:
    from jaxmech.viz.live import live_view, update

    load_before = list(os.getloadavg())
    t0 = time.perf_counter()
    view = live_view("flap_msd", points=46)
    first_s = time.perf_counter() - t0
    defaults = view.scene.defaults
    rng = np.random.default_rng(0)
    n, warm = (30, 5) if quick else (200, 10)
    moves = [(NAMES[k % len(NAMES)], float(defaults[NAMES[k % len(NAMES)]]) * (1 + rng.uniform(-0.1, 0.1))) for k in range(n + warm)]
    params_ms, statuses, full0 = [], [], None
    for k, (name, value) in enumerate(moves):
        t = time.perf_counter()
        status = update(view, **{name: value})
        dt = 1e3 * (time.perf_counter() - t)
        if k == warm - 1:
            full0 = view.full_renders
        if k >= warm:
            params_ms.append(dt)
            statuses.append(view.ok)
    pose_ms = []
    for k in range(n):
        t = time.perf_counter()
        update(view, index=k % view.points)
        pose_ms.append(1e3 * (time.perf_counter() - t))
    t = time.perf_counter()
    bad = update(view, d=0.5 * float(defaults["d"]))  # a design that cannot be assembled
    bad_ms = 1e3 * (time.perf_counter() - t)
    params = _stats(params_ms)
    ok = np.asarray(statuses)
    return {
        "scene": "flap_msd", "points": view.points, "parameters_moved": list(NAMES),
        "first_call_s": first_s,
        "parameter_update": params,
        "pose_update": _stats(pose_ms),
        "unassemblable_update_ms": bad_ms, "unassemblable_status": bad,
        "assembled_fraction": float(np.mean(statuses)),
        "parameter_update_assembled": _stats(np.asarray(params_ms)[ok]),
        "parameter_update_unassemblable": _stats(np.asarray(params_ms)[~ok]) if (~ok).any() else None,
        "full_redraw_fraction": (view.full_renders - full0) / n,  # limits changed: axes redrawn too
        "target_ms": TARGET_MS, "median_under_target": params["median_ms"] < TARGET_MS,
        "load_average_before": load_before, "load_average_after": list(os.getloadavg()),
        "png_bytes": len(view.png), "last_status": status, "quick": quick,
    }


def main(argv=None):
    args = base_parser(__doc__.splitlines()[0]).parse_args(argv)
    setup_jax()
    res = run(args.quick)
    path = write_result("live", res, out_dir=args.out)
    p, q = res["parameter_update"], res["pose_update"]
    print(f"first call {res['first_call_s']:.1f} s; parameter update median {p['median_ms']:.1f} ms, "
          f"p95 {p['p95_ms']:.1f} ms; pose update median {q['median_ms']:.1f} ms; load {res['load_average_after']}")
    print("wrote", path)


if __name__ == "__main__":
    main()
