"""What the gap repair's program costs to build: a developer's instrument, not a benchmark.

Traces, lowers and compiles ``continuation.solve.repair_stroke`` under ``jax.jit`` for 64
gapped designs of ``benchmarks/gaps.py``'s four-bar (or Watt six-bar) case, with the
library's compiler options (or those of ``COPTS``, a JSON dict), and prints each stage's
seconds, the jaxpr and StableHLO line counts and one warm run; then the same for the walk
alone.  Variants (``--drop``, comma-separated) take parts out of the program to see what they
cost: ``fold`` (the start across a fold), ``unwrap`` (whole turns), ``derivs`` (the repaired
points' derivatives), ``starts`` (one start a point instead of ``multistart``'s table).  It
patches internals in its own process (hence a script).

Run from the repository root: ``python scripts/repair_compile.py fourbar|watt [--drop a,b]``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("case", nargs="?", default="fourbar", choices=("fourbar", "watt"))
    parser.add_argument("--drop", default="")
    args = parser.parse_args(argv)
    drop = set(filter(None, args.drop.split(",")))
    import jax

    jax.config.update("jax_enable_x64", True)
    import numpy as np

    import jaxmech.continuation.point as point
    import jaxmech.continuation.repair as repair
    import jaxmech.continuation.solve as solve
    from benchmarks.gaps import case, watt
    from jaxmech.solver.xla import COMPILER_OPTIONS
    from jaxmech.scenes import get_scene
    from jaxmech.solver.newton import newton
    from jaxmech.solver.options import SolverOptions

    sc = get_scene("fourbar") if args.case == "fourbar" else watt().scene(speed=2 * np.pi)
    mech, opts = sc.mechanism, SolverOptions()
    _, table = case("fourbar_gapped" if args.case == "fourbar" else "watt_10pct", 2048, 1024)
    n_all = len(next(iter(table.values())))
    p_all = {k: np.full(n_all, float(sc.defaults[k])) for k in mech.params}
    p_all.update({k: np.asarray(v) for k, v in table.items() if k in p_all})
    g_all = np.broadcast_to(np.asarray(sc.guess(sc.defaults)), (n_all, mech.m))
    us = np.linspace(0, 2 * np.pi, 64).reshape(64, 1)  # 37 points, bucketed to 64
    n = np.int32(37)
    derivs = "derivs" not in drop
    walked_all = solve._stroke_program(mech, opts, derivs, False, False, us, p_all, g_all, n)
    bad = np.nonzero(np.any(np.asarray(walked_all[0].status)[:, :37] != 0, axis=1))[0][:64]
    p = {k: v[bad] for k, v in p_all.items()}
    g = g_all[bad]
    walked = solve._stroke_program(mech, opts, derivs, False, False, us, p, g, n)
    if "fold" in drop:
        repair.across_fold = point.across_fold = lambda mech, q, u, p: q
    if "unwrap" in drop:
        repair.unwrap = lambda setup, ctx, pts, moved: pts
    if "starts" in drop:
        def one(mech, opts, u, p, starts, caps, count, target, inputs_finite=False, skip=None, after_stall=None, budget=None, fold=None):
            return newton(mech, opts, u, p, starts[0], target, caps[0], skip=skip, inputs_finite=True, budget=budget), 0

        repair.multistart = one
    copts = json.loads(os.environ["COPTS"]) if "COPTS" in os.environ else COMPILER_OPTIONS
    print(f"{args.case}: {len(bad)} gapped designs, drop {sorted(drop) or 'nothing'}, compiler options {copts}")
    for name, fn, static, dyn in (("repair", solve.repair_stroke, (mech, opts, derivs), (us, p, g, n, walked)),
                                  ("walk", lambda *a: solve.walk(*a, False), (mech, opts, derivs), (us, p, g, n))):  # the walk alone
        jitted = jax.jit(fn, static_argnums=(0, 1, 2), compiler_options=copts)
        t0 = time.perf_counter()
        traced = jitted.trace(*static, *dyn)
        t1 = time.perf_counter()
        lowered = traced.lower()
        t2 = time.perf_counter()
        compiled = lowered.compile()
        t3 = time.perf_counter()
        jax.block_until_ready(compiled(*dyn))
        t4 = time.perf_counter()
        jax.block_until_ready(compiled(*dyn))
        run = time.perf_counter() - t4
        print(f"  {name:6s} trace {t1 - t0:.2f} s  lower {t2 - t1:.2f} s  compile {t3 - t2:.2f} s  warm run {run:.4f} s  "
              f"jaxpr {len(str(traced.jaxpr).splitlines())} lines  StableHLO {len(lowered.as_text().splitlines())} lines")


if __name__ == "__main__":
    main()
