"""What one Newton iteration of a vmapped loop costs per lane count: a developer's instrument.

Times ``solver.newton``'s iteration (``newton_iteration``) run a fixed number of times in a
``fori_loop`` over ``L`` lanes (the four-bar scene, or the README's Watt six-bar linkage),
warm, and prints the cost of one iteration (the difference of 50 and 10 iterations, over 40)
and per lane.  On a CPU a lane costs nearly as much idle as busy: what a repair's lane
utilisation is worth (``benchmarks/README.md``, gaps section).

Run from the repository root: ``python scripts/lane_cost.py fourbar|watt``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(name: str = "fourbar") -> None:
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    from benchmarks.gaps import watt
    from jaxmech.scenes import get_scene
    from jaxmech.mechanism.branches import branch_value, has_branch, on_branch
    from jaxmech.mechanism.structure import blocks
    from jaxmech.solver import newton
    from jaxmech.solver.options import SolverOptions, tolerances

    sc = get_scene("fourbar") if name == "fourbar" else watt().scene(speed=2 * np.pi)
    mech, opts = sc.mechanism, SolverOptions()
    p0 = {k: float(sc.defaults[k]) for k in mech.params}
    g0 = np.asarray(sc.guess(sc.defaults))

    def best(lanes: int, k: int) -> float:
        def lane(u, g):
            # newton.newton's problem and first state, without its while_loop: every lane
            # runs exactly k iterations
            xtol, ftol, _ = tolerances(opts, g.dtype)
            evaluate, s = newton.evaluator(mech, u, p0, g.dtype)
            b = jnp.sign(branch_value(mech, g, u, p0)) if has_branch(mech) else None

            def same(q, jac):
                return on_branch(b, branch_value(mech, q, u, p0, jac)) if has_branch(mech) else jnp.asarray(True)

            pb = newton.NewtonProblem(evaluate, s, same, blocks(mech), opts.max_step, xtol, ftol, opts)
            z, m = jnp.zeros((), g.dtype), g.shape[-1]
            st = newton.NewtonState(k=jnp.zeros((), jnp.int32), q=g, r=jnp.zeros((m,), g.dtype), rn=jnp.asarray(jnp.inf, g.dtype),
                                    js=jnp.eye(m, dtype=g.dtype), dz=jnp.zeros((m,), g.dtype), size=z, mu=z,
                                    slow=jnp.zeros((), jnp.int32), done=jnp.asarray(False), stalled=jnp.asarray(False),
                                    guard=jnp.asarray(True), crossed=jnp.asarray(False), on=jnp.asarray(False))
            return jax.lax.fori_loop(0, k, lambda i, st_: newton.newton_iteration(pb, st_), st).q

        f = jax.jit(jax.vmap(lane))
        u = jnp.linspace(0.0, 6.0, lanes).reshape(lanes, 1)
        g = jnp.asarray(g0)[None] + 0.3 * jnp.asarray(np.random.default_rng(0).normal(size=(lanes, mech.m)))
        jax.block_until_ready(f(u, g))
        times = []
        for _ in range(5):
            t0 = time.perf_counter()
            jax.block_until_ready(f(u, g))
            times.append(time.perf_counter() - t0)
        return min(times)

    for lanes in (1, 8, 32, 128, 512, 2048):
        per = (best(lanes, 50) - best(lanes, 10)) / 40
        print(f"{name} lanes {lanes:5d}: {per * 1e6:8.2f} us an iteration, {per / lanes * 1e6:7.3f} us a lane")


if __name__ == "__main__":
    main(*sys.argv[1:])
