"""The benchmark plots the documentation shows, redrawn from ``results/*.json`` (no
benchmark is run): ``python -m benchmarks.figures [--out docs/img/benchmarks]``.

Each benchmark script draws its plot beside its JSON in ``results/`` (ignored by git); the
documentation needs them committed, so this writes the same plots, from the same
``plot(result, path)`` functions, into ``docs/img/benchmarks/``.
"""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path

from benchmarks.common import load_result

ROOT = Path(__file__).resolve().parents[1]
PLOTTED = ("kinematics", "speed_error", "scaling", "flap_torque")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=ROOT / "docs" / "img" / "benchmarks")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for name in PLOTTED:
        res = load_result(name)
        if res is None:
            print(f"{name}: no results/{name}.json; skipped")
            continue
        importlib.import_module(f"benchmarks.{name}").plot(res, args.out / f"{name}.png")
        print(f"wrote {args.out / f'{name}.png'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
