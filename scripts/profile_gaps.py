"""Where a gapped sweep's time goes: a developer's instrument, not a benchmark.

Runs one of ``benchmarks/gaps.py``'s cases (``--case``, 37 points a stroke, float64) warm,
and reports, per warm call:

- ``stages``: the sweep kernel's walk, its repair programs (``repair_exec``), the gather and
  scatter around them, and the rest (kinematics, dynamics, figures);
- ``--lanes``: per kind of repair phase (fresh assemblies, two-sided solves, fill steps),
  how many Newton iterations ran one after the other (the sum over groups of the slowest
  lane), how many the lanes ran in all, and the lanes' utilisation (``all / (sequential x
  lanes)``);
- variants of the repair's constants, for a measured what-if (statuses change where they
  would): ``--probe N`` (``repair.PROBE``), ``--group G`` (lanes per group as a multiple of
  the designs of a call), ``--robust-size R`` (designs per repair call), ``--budget B`` (a
  start's iterations at most), ``--skip FRESH,TWO,FILL`` (phases not run).

It patches the library's internals in its own process (hence a script, not a benchmark).
Run from the repository root: ``python scripts/profile_gaps.py --case fourbar_gapped
[--lanes] [variants]``.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

KINDS = {0: "FRESH", 1: "TWO", 2: "FILL"}


def patch_source(module, old: str, new: str, env: dict | None = None) -> None:
    """Execute ``module``'s source again with ``old`` replaced by ``new`` (in its namespace)."""
    src = Path(module.__file__).read_text()
    if old not in src:
        raise SystemExit(f"{module.__name__}: the text to patch is gone; update this script")
    module.__dict__.update(env or {})
    exec(compile(src.replace(old, new), module.__file__, "exec"), module.__dict__)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="fourbar_gapped", help="a case of benchmarks/gaps.py")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--lanes", action="store_true", help="count the repair's sequential and lane iterations")
    parser.add_argument("--probe", type=int, default=None)
    parser.add_argument("--group", type=float, default=None)
    parser.add_argument("--robust-size", type=int, default=None)
    parser.add_argument("--budget", type=int, default=None)
    parser.add_argument("--skip", default="")
    args = parser.parse_args(argv)

    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    import jaxmech.continuation.point as point
    import jaxmech.continuation.repair as repair
    import jaxmech.continuation.solve as solve
    from jaxmech.sweep import kernel

    log = []
    if args.lanes:  # a start table's best result carries the iterations of every start run
        patch_source(point, "        return _Starts(j + 1, jax.tree_util.tree_map(pick, res, best),",
                     "        best_ = dataclasses.replace(jax.tree_util.tree_map(pick, res, best), steps=best.steps + where(run, res.steps, 0))\n"
                     "        return _Starts(j + 1, best_,", {"dataclasses": __import__("dataclasses")})
    if args.probe:
        repair.PROBE = args.probe
    if args.group:
        patch_source(repair, "group = min(size, GROUP * d)", f"group = max(1, min(size, int({args.group} * d)))")
    if args.lanes:
        patch_source(repair, "        take = live & (~flat(tried)[idx]",
                     "        jax.debug.callback(lambda s, l, m: LOG.append((int(m), np.asarray(s), np.asarray(l))), res.steps, live, mode)\n"
                     "        take = live & (~flat(tried)[idx]", {"LOG": log, "np": np})
    if args.budget:
        ms = repair.multistart

        def capped(*a, budget=None, **k):
            return ms(*a, budget=args.budget if budget is None else jnp.minimum(budget, args.budget), **k)

        repair.multistart = capped
    if args.skip:
        skipped = jnp.asarray([{v: k for k, v in KINDS.items()}[s] for s in args.skip.split(",")])
        solve_points = repair.solve_points

        def maybe(setup, ctx, pts, todo, mode, *rest):
            return jax.lax.cond(jnp.any(skipped == mode), lambda: pts, lambda: solve_points(setup, ctx, pts, todo, mode, *rest))

        repair.solve_points = maybe
    solve.repair = repair.repair
    if args.robust_size:
        kernel.robust_size = lambda d: args.robust_size

    times = collections.defaultdict(float)

    def timed(name, f):
        def run(*a, **k):
            t0 = time.perf_counter()
            out = jax.block_until_ready(f(*a, **k))
            times[name] += time.perf_counter() - t0
            return out

        return run

    solve._put_rows = timed("scatter", solve._put_rows)
    import jaxmech.scenes.evaluation as evaluation

    evaluation.take_rows = timed("gather", evaluation.take_rows)

    def call(self, p):
        walked = timed("walk", self.first)(p)
        part = timed("repaired_part", kernel.repaired_part)(walked, p, timed("repair_exec", self._repair_rows), self.size)
        return timed("rest", self.second)(p, self._put(part))

    kernel._Staged.__call__ = call
    from benchmarks.gaps import case
    from jaxmech.sweep import sweep_scene

    scene, table = case(args.case, 2048, 1024)
    res = sweep_scene(scene, table=table, points=37, progress=False)
    status = np.asarray(res.status)
    print(f"{args.case}: {status.shape[0]} designs, failed designs {int(np.sum(np.any(status != 0, axis=1)))}, "
          f"failed points {int(np.sum(status != 0))}")
    if args.lanes:
        agg = collections.defaultdict(lambda: [0, 0, 0, 0, 0])
        for mode, steps, live in log:
            a = agg[KINDS[mode]]
            a[0] += 1
            a[1] += int(steps[live].max()) if live.any() else 0
            a[2] += int(steps[live].sum())
            a[3] += int(live.sum())
            a[4] += (int(steps[live].max()) if live.any() else 0) * steps.size
        for kind, (groups, seq, total, solves, capacity) in agg.items():
            print(f"  {kind:5s} groups {groups:4d}  sequential iterations {seq:6d}  lane iterations {total:7d}  "
                  f"point solves {solves:6d}  utilisation {total / max(1, capacity):.2f}")
    for _ in range(args.repeat):
        times.clear()
        t0 = time.perf_counter()
        sweep_scene(scene, table=table, points=37, progress=False)
        total = time.perf_counter() - t0
        print(f"  warm {total:.3f} s: " + ", ".join(f"{k} {v:.4f}" for k, v in times.items()))


if __name__ == "__main__":
    main()
