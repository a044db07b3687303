"""Shared benchmark machinery: timing with compile separated, medians, JSON results.

Every benchmark in this folder times a function the same way:

1. ``compile_jax(fn, *args)`` lowers and compiles a jitted function once
   (``jax.jit(fn).lower(*args).compile()``) and reports the compile time on its own;
2. ``time_call(fn, *args)`` warms up, then calls the compiled function ``repeat`` times,
   each call followed by ``block_until_ready``, and reports the median (and the spread);
3. ``write_result(name, payload)`` writes ``benchmarks/results/<name>.json`` with the
   machine, the library versions and the date beside the numbers.

Nothing here imports jaxmech's internals; benchmarks use the public API.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

RESULTS = Path(__file__).resolve().parent / "results"

__all__ = [
    "RESULTS",
    "Timing",
    "compile_jax",
    "time_call",
    "time_python",
    "block",
    "machine_info",
    "write_result",
    "load_result",
    "base_parser",
    "peak_rss_mb",
]


def block(x):
    """Wait for every array in a pytree (JAX arrays are asynchronous)."""
    import jax

    return jax.tree_util.tree_map(lambda a: a.block_until_ready() if hasattr(a, "block_until_ready") else a, x)


class Timing(dict):
    """Median, min and max wall time of repeated calls (s), with the count; a plain dict for JSON."""

    @property
    def median(self) -> float:
        return self["median_s"]


def _stats(samples: list[float]) -> Timing:
    return Timing(
        median_s=statistics.median(samples),
        min_s=min(samples),
        max_s=max(samples),
        repeats=len(samples),
    )


def compile_jax(fn: Callable, *args, static_argnums=()) -> tuple[Callable, float]:
    """Jit, lower and compile ``fn`` for ``args``; returns ``(compiled, compile_seconds)``.

    The compiled object is called with the same (non-static) arguments.
    """
    import jax

    t0 = time.perf_counter()
    compiled = jax.jit(fn, static_argnums=static_argnums).lower(*args).compile()
    return compiled, time.perf_counter() - t0


def time_call(fn: Callable, *args, repeat: int = 5, warmup: int = 1, min_time: float = 0.0) -> Timing:
    """Median wall time of ``fn(*args)`` with ``block_until_ready`` (s).

    `warmup` calls are made first and discarded.  If `min_time` > 0, repeats continue until
    their sum exceeds it (useful for very fast calls), up to 50 repeats.
    """
    out = None
    for _ in range(warmup):
        out = block(fn(*args))
    samples: list[float] = []
    while len(samples) < repeat or (min_time > 0 and sum(samples) < min_time and len(samples) < 50):
        t0 = time.perf_counter()
        out = block(fn(*args))
        samples.append(time.perf_counter() - t0)
    del out
    return _stats(samples)


def time_python(fn: Callable, *args, repeat: int = 3, warmup: int = 1) -> Timing:
    """Median wall time of a plain (numpy/scipy) callable (s)."""
    for _ in range(warmup):
        fn(*args)
    samples = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn(*args)
        samples.append(time.perf_counter() - t0)
    return _stats(samples)


def pareto_front(points) -> list[tuple[float, float]]:
    """The (time, error) points no other point beats on both: sorted by time, error falling."""
    front, best = [], np.inf
    for x, y in sorted(points):
        if y < best:
            front.append((x, y))
            best = y
    return front


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far (MiB)."""
    import resource

    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return kb / 1024.0 if sys.platform != "darwin" else kb / 2**20


def _version(mod: str) -> str | None:
    try:
        from importlib.metadata import version

        return version(mod)
    except Exception:
        return None


def _git_rev() -> str | None:
    try:
        here = Path(__file__).resolve().parent
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=here, capture_output=True, text=True, timeout=5)
        return out.stdout.strip() or None
    except Exception:
        return None


def machine_info() -> dict[str, Any]:
    """Machine, versions and date, recorded with every result."""
    info: dict[str, Any] = {
        "date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "git": _git_rev(),
        # other processes compete for the cores: timings on a loaded machine are inflated
        "load_average_1_5_15min": list(os.getloadavg()) if hasattr(os, "getloadavg") else None,
    }
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    info["cpu_model"] = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        import jax

        info["jax_backend"] = jax.default_backend()
        info["jax_devices"] = [str(d) for d in jax.devices()]
        info["jax_enable_x64"] = bool(jax.config.jax_enable_x64)
    except Exception:
        pass
    info["versions"] = {
        m: _version(m)
        for m in ("jaxmech", "jax", "jaxlib", "numpy", "scipy", "optimistix", "pylinkage", "numba", "mechanism", "mpmath", "exudyn")
    }
    return info


def _jsonable(x):
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        v = float(x)
        return v if np.isfinite(v) else None if np.isnan(v) else ("inf" if v > 0 else "-inf")
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, np.bool_):
        return bool(x)
    return x


def write_result(name: str, payload: dict[str, Any], *, out_dir: Path | None = None) -> Path:
    """Write ``<out_dir>/<name>.json`` (default ``benchmarks/results``) with machine info."""
    out_dir = Path(out_dir) if out_dir is not None else RESULTS
    out_dir.mkdir(parents=True, exist_ok=True)
    doc = {"benchmark": name, "machine": machine_info(), **payload}
    path = out_dir / f"{name}.json"
    path.write_text(json.dumps(_jsonable(doc), indent=2) + "\n")
    return path


def load_result(name: str, *, out_dir: Path | None = None) -> dict[str, Any] | None:
    path = (Path(out_dir) if out_dir is not None else RESULTS) / f"{name}.json"
    if not path.exists():
        return None
    return json.loads(path.read_text())


def base_parser(description: str) -> argparse.ArgumentParser:
    """Command line every benchmark accepts: ``--quick`` and ``--out``."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--quick", action="store_true", help="small sizes and few repeats (a smoke run, under a minute)")
    ap.add_argument("--out", type=Path, default=RESULTS, help="folder for the JSON and PNG results")
    return ap


def setup_jax(x64: bool = True) -> None:
    """Enable float64 (benchmarks compare errors at 1e-12 scale) before any array exists."""
    import jax

    jax.config.update("jax_enable_x64", x64)
