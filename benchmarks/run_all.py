"""Run every benchmark, then print the Markdown summary.

``python -m benchmarks.run_all [--quick] [--only kinematics,scaling] [--out DIR]``
"""

from __future__ import annotations

import importlib
import inspect
import sys
import time
from pathlib import Path

from benchmarks.common import base_parser

_HERE = Path(__file__).resolve().parent
#: Every benchmark script: a module with ``main(argv)`` accepting ``--quick`` and ``--out``.
BENCHMARKS = tuple(
    n for n in ("latency", "kinematics", "speed_error", "scaling", "dynamics", "design", "sweep_scale", "gaps", "workflow", "flap_torque", "live") if (_HERE / f"{n}.py").exists()
)


def main(argv=None):
    ap = base_parser("Run every jaxmech benchmark and render the summary table.")
    ap.add_argument("--only", default="", help="comma-separated subset of " + ", ".join(BENCHMARKS))
    args = ap.parse_args(argv)
    names = [n for n in args.only.split(",") if n] or list(BENCHMARKS)
    for n in names:
        if n not in BENCHMARKS:
            raise SystemExit(f"unknown benchmark {n!r}; known: {', '.join(BENCHMARKS)}")
    for n in names:
        t0 = time.perf_counter()
        print(f"=== {n}", flush=True)
        mod = importlib.import_module(f"benchmarks.{n}")
        argv_n = (["--quick"] if args.quick else []) + ["--out", str(args.out)]
        if inspect.signature(mod.main).parameters:
            mod.main(argv_n)
        else:  # a script that parses sys.argv itself (its own --out convention): only --quick
            saved, sys.argv = sys.argv, [f"benchmarks/{n}.py", *(["--quick"] if args.quick else [])]
            try:
                mod.main()
            finally:
                sys.argv = saved
        print(f"=== {n} done in {time.perf_counter() - t0:.0f} s", flush=True)
    from benchmarks import summary

    summary.main(["--results", str(args.out)])


if __name__ == "__main__":
    main(sys.argv[1:])
