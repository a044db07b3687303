"""Sets of designs for a sweep: grids, random samples, a scene's full design table, and
the per-design value checks that keep a bad design as a reported row instead of an error."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..scenes.base import Scene

__all__ = ["design_table", "grid", "random_designs", "reject"]


def grid(axes: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """Full-factorial grid over named parameters, flattened to a table of designs.

    **Arguments**

    - `axes`: ``{name: 1-D values}`` (SI units).  Order matters: the last name varies
      fastest (C order, like ``np.meshgrid(..., indexing="ij")``).

    **Returns** ``{name: (D,) array}`` with ``D`` the product of the axis lengths.

    **Raises** ``ValueError`` for an empty or multi-dimensional axis.
    """
    if not isinstance(axes, Mapping) or not axes:
        raise ValueError("grid: give a non-empty mapping {parameter name: 1-D array of values}")
    arrays = {}
    for k, v in axes.items():
        a = np.atleast_1d(np.asarray(v, dtype=float))
        if a.ndim != 1 or a.size == 0:
            raise ValueError(f"grid: axis {k!r} must be a non-empty 1-D array, got shape {np.shape(v)}")
        arrays[k] = a
    mesh = np.meshgrid(*arrays.values(), indexing="ij")
    return {k: m.ravel() for k, m in zip(arrays, mesh)}


def random_designs(
    ranges: Mapping[str, tuple[float, float]],
    n: int,
    *,
    seed: int = 0,
    method: str = "uniform",
    log: Sequence[str] = (),
) -> dict[str, np.ndarray]:
    """A random sample of ``n`` designs inside a box.

    **Arguments**

    - `ranges`: ``{name: (low, high)}`` (SI units); each parameter drawn in ``[low, high]``.
    - `n`: number of designs.
    - `seed`: seed of ``numpy.random.default_rng`` (results are reproducible).
    - `method`: ``"uniform"`` (independent uniform draws) or ``"lhs"`` (Latin hypercube:
      each parameter's range cut into ``n`` strata, one draw per stratum).
    - `log`: names drawn uniformly in ``log`` (both bounds must be positive).

    **Returns** ``{name: (n,) array}``, a table for ``sweep_scene(table=...)``.
    """
    if n < 1:
        raise ValueError(f"random_designs: n must be at least 1, got {n}")
    if method not in ("uniform", "lhs"):
        raise ValueError(f"random_designs: method must be 'uniform' or 'lhs', got {method!r}")
    unknown = [k for k in log if k not in ranges]
    if unknown:
        raise ValueError(f"random_designs: log names {unknown} are not in ranges {list(ranges)}")
    rng = np.random.default_rng(seed)
    out = {}
    for k, bounds in ranges.items():
        lo, hi = (float(x) for x in bounds)
        if not (np.isfinite(lo) and np.isfinite(hi) and hi >= lo):
            raise ValueError(f"random_designs: range of {k!r} must be finite (low, high) with high >= low, got {bounds}")
        if method == "uniform":
            s = rng.random(n)
        else:
            s = (rng.permutation(n) + rng.random(n)) / n
        if k in log:
            if lo <= 0:
                raise ValueError(f"random_designs: {k!r} is drawn in log but its range {bounds} is not positive")
            out[k] = np.exp(np.log(lo) + s * (np.log(hi) - np.log(lo)))
        else:
            out[k] = lo + s * (hi - lo)
    return out


def design_table(scene: Scene, grid_: Mapping | None, table: Mapping | None, who: str = "sweep_scene") -> dict[str, np.ndarray]:
    """Every parameter of every design, ``{name: (D,) float}``: the grid or table given,
    the scene's defaults for the parameters not named.  ``ValueError`` for unknown names,
    non-numbers, ragged tables or an empty sweep."""
    if grid_ is not None and table is not None:
        raise ValueError(f"{who}: give either grid or table, not both (combine them with grid() yourself)")
    given = grid(grid_) if grid_ is not None else dict(table) if table is not None else {}
    unknown = [k for k in given if k not in scene.defaults]
    if unknown:
        raise ValueError(
            f"{who}: scene {scene.name!r} has no parameter(s) {unknown}; its parameters are: {', '.join(scene.defaults)}"
        )
    arrays = {}
    for k, v in given.items():
        a = np.asarray(v)
        if not np.issubdtype(a.dtype, np.number):
            raise ValueError(f"{who}: parameter {k!r} must be numbers, got dtype {a.dtype}")
        arrays[k] = np.atleast_1d(a.astype(float))
        if arrays[k].ndim != 1:
            raise ValueError(f"{who}: parameter {k!r} must be a 1-D array of designs, got shape {a.shape}")
    sizes = {k: len(v) for k, v in arrays.items()}
    if len(set(sizes.values())) > 1:
        raise ValueError(f"{who}: table columns differ in length: {sizes}")
    d = next(iter(sizes.values())) if sizes else 1
    if d == 0:
        raise ValueError(f"{who}: no designs to run")
    return {k: arrays[k] if k in arrays else np.full(d, float(v)) for k, v in scene.defaults.items()}


def reject(scene: Scene, params: dict[str, np.ndarray], offset: int = 0) -> dict[int, str]:
    """Per-design value checks (vectorised ``check_params``, then ``scene.validate``):
    ``{offset + index: message}`` of the designs that must not be solved."""
    mech = scene.mechanism
    errors: dict[int, str] = {}
    for k, v in params.items():
        bad = ~np.isfinite(v)
        for i in np.flatnonzero(bad):
            errors.setdefault(offset + int(i), f"rejected: parameter {k!r} = {float(v[i])!r} is not finite")
        if k in mech.lengths and k not in mech.signed:
            for i in np.flatnonzero(~bad & (v <= 0)):
                errors.setdefault(offset + int(i), f"rejected: length {k!r} = {float(v[i])!r} must be positive")
    if scene.validate is not None:
        d = len(next(iter(params.values())))
        for i in range(d):
            if offset + i in errors:
                continue
            try:
                scene.validate({k: float(v[i]) for k, v in params.items()})
            except ValueError as e:
                errors[offset + i] = f"rejected by scene.validate: {e}"
    return dict(sorted(errors.items()))
