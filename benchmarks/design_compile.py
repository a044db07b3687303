"""What a design program costs to build: a scene figure, its gradient and its Hessian.

A design refinement (``jaxmech.design.refine``) and a tolerance study compile programs that
evaluate a scene figure with its first and second derivatives; on the README's Watt six-bar
those compiles are most of the design workflow's first call (``benchmarks/workflow.py``).
This benchmark takes them apart: the figure "peak crank torque" of the workflow's Watt
six-bar (``examples/design_workflow.py``) over ``--points`` samples of one design, as
``jax.jit`` of

- ``f``: the figure;
- ``gradient``: ``jax.grad`` of it over the ten geometric parameters;
- ``hessian``: ``jax.jacfwd`` of the gradient (forward over reverse, as the SQP's
  second-order evaluation).

For each: the jaxpr's equations (nested ones counted), the time to trace, to lower and to
compile (wall and process CPU), and the optimized HLO's lines.  Every program is built in
this one process, in that order, with the library's compile store off (so nothing is
loaded); the load average is recorded around each.

Run: ``python -m benchmarks.design_compile [--points N] [--quick]``; writes
``results/design_compile.json``.
"""

from __future__ import annotations

import math
import os
import time

from benchmarks.common import base_parser, setup_jax, write_result


def equations(jaxpr) -> int:
    """Equations of a jaxpr, those of its nested jaxprs included."""
    from jax.extend.core import jaxprs_in_params

    return sum(1 + sum(equations(sub) for sub in jaxprs_in_params(e.params)) for e in jaxpr.eqns)


def measure(label: str, fn, x0) -> dict:
    """Trace, lower and compile ``fn`` at ``x0``: counts and times."""
    import jax

    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    jaxpr = jax.make_jaxpr(fn)(x0)
    trace = time.perf_counter() - t0
    jitted = jax.jit(fn)
    t0 = time.perf_counter()
    lowered = jitted.lower(x0)
    lower = time.perf_counter() - t0
    t0, c0 = time.perf_counter(), time.process_time()
    compiled = lowered.compile()
    compile_wall, compile_cpu = time.perf_counter() - t0, time.process_time() - c0
    row = {"equations": equations(jaxpr.jaxpr), "trace_s": trace, "lower_s": lower, "compile_s": compile_wall,
           "compile_cpu_s": compile_cpu, "hlo_lines": compiled.as_text().count("\n"), "load_before_after": [load, os.getloadavg()[0]]}
    print(f"{label:9s} {row['equations']:7d} eqns  trace {trace:6.2f} s  lower {lower:5.2f} s  compile {compile_wall:6.2f} s "
          f"({compile_cpu:6.2f} s CPU)  {row['hlo_lines']:6d} HLO lines", flush=True)
    return row


def main(argv=None):
    parser = base_parser(__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=37, help="samples along the stroke (default 37, the workflow's)")
    args = parser.parse_args(argv)
    os.environ["JAXMECH_COMPILE_CACHE"] = "0"  # build everything here: nothing loaded from the store
    setup_jax()
    import jax
    import jax.numpy as jnp

    from examples import design_workflow as wf
    from jaxmech.design import scene_figure

    points = 9 if args.quick else args.points
    linkage = wf.watt()
    scene = linkage.scene(speed=2 * math.pi)
    names = list(wf.box(linkage))
    figure = scene_figure(scene, wf.peak_torque, points=points)
    x0 = jnp.asarray([scene.defaults[k] for k in names])

    def f(x):
        return figure(dict(zip(names, x)))[0]

    rows = {}
    for label, fn in (("f", f), ("gradient", jax.grad(f)), ("hessian", jax.jacfwd(jax.grad(f)))):
        rows[label] = measure(label, fn, x0)
    write_result("design_compile", {"points": points, "parameters": names, "programs": rows, "quick": args.quick}, out_dir=args.out)


if __name__ == "__main__":
    main()
