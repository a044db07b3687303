"""Design sweeps: every output of a scene over a batch of parameter sets, in one call.

A sweep evaluates a scene (``jaxmech.scenes.Scene``) at ``D`` designs times ``N`` stroke
positions.  Per design it is exactly ``run_scene``: the stroke ``scene.stroke(p)`` is
sampled at ``points`` evenly spaced inputs, solved by continuation from
``scene.guess(p)`` (``solve_stroke``), and differentiated along the scene's constant-speed
drive to velocities, accelerations and the scene's ``outputs``.  Across designs it is
``jax.vmap``: one compiled kernel serves the whole batch.

The batch is cut into fixed-size chunks (one compilation) that fit a memory budget; each
chunk is laid out over every local device (``NamedSharding`` over a 1-D mesh of
``jax.devices()``), and with a Dask ``client`` the chunks become independent tasks on a
cluster.  A design that fails (cannot be assembled, singular, lost with its chunk) is
kept, with its status and NaN values; nothing is dropped.
"""

from __future__ import annotations

import dataclasses
import os
import sys
import time
from collections.abc import Mapping, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .continuation import stroke
from .kinematics import ConstantSpeed, Motion, sample_kinematics
from .scenes.base import Scene
from .options import SolverOptions
from .status import Status, status_counts

__all__ = ["SweepResult", "grid", "random_designs", "sweep_scene"]

#: Columns that are defined at every sample, converged or not (the drive).
_DRIVE_SUFFIXES = ("[s]",)
_PROGRESS_AFTER_S = 3.0  # show progress when a sweep is expected to run longer than this


# =========================================================================== design sets
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


# =========================================================================== one design
def _stroke_drive(scene: Scene, p, dtype):
    """Drive law of ``run_scene``: constant speed from the stroke start to its end."""
    u0, u1 = (jnp.asarray(x, dtype) for x in scene.stroke(p))
    w = jnp.where(u1 >= u0, scene.speed, -scene.speed).astype(dtype)
    return ConstantSpeed(u0, w), (u1 - u0) / w


def design_motion(scene: Scene, points: int, p, *, options: SolverOptions = SolverOptions(), anchors: int = 256):
    """One design's ``Motion`` over its stroke, traceable (works under ``jit``/``vmap``/``grad``).

    The same computation as ``run_scene`` (its stroke, drive and continuation), but the
    values at failed samples are finite placeholders (the coordinates of
    ``scene.guess(p)``, zero derivatives), so that any function of the motion stays
    finite and differentiable; ``status`` says which samples are real.

    **Arguments**

    - `scene`: the scene; `points`: samples along the stroke (both ends included).
    - `p`: ``{name: scalar}``, every parameter of the scene (SI units).

    **Returns** ``(motion, ok)``: a ``Motion`` with ``N = points`` samples and the boolean
    ``(N,)`` mask of converged samples.
    """
    mech = scene.mechanism
    dtype = jnp.result_type(*[jnp.asarray(v) for v in p.values()], float)
    p = {k: jnp.asarray(p[k], dtype) for k in mech.params}
    drive, duration = _stroke_drive(scene, p, dtype)
    t = jnp.linspace(0.0, duration, points)
    us = jax.vmap(drive)(t)
    guess = jnp.asarray(scene.guess(p), dtype)
    # one compiled pass: positions, dq/du and d2q/du2 (differentiable by the implicit rule)
    sol, e1, e2 = stroke(mech, us, p, guess, options, derivs=True, anchors=anchors)
    ok = sol.status == Status.CONVERGED
    # Mask the *inputs* of everything downstream: no NaN, not even in a branch not taken
    # (failed samples have zero derivatives).
    q = jnp.where(ok[:, None], sol.q, guess[None, :])
    d1 = jnp.where(ok[:, None, None], e1, 0.0)
    d2 = jnp.where(ok[:, None, None, None], e2, 0.0)
    u, ud, udd, qd, qdd, pts = jax.vmap(lambda t_, q_, a_, b_: sample_kinematics(mech, tuple(mech.points), drive, p, t_, q_, a_, b_))(t, q, d1, d2)
    mo = Motion(
        t=t, u=u, u_dot=ud, u_ddot=udd, q=q, q_dot=qd, q_ddot=qdd, dq_du=d1, d2q_du2=d2,
        points=pts, status=sol.status, coords=mech.coords, inputs=mech.inputs,
    )
    return mo, ok


def _columns(scene: Scene, mo: Motion, outputs: Mapping | None, xp=jnp) -> dict:
    """Columns ``NAME[UNIT]`` of ``SceneResult.table`` (without status), unmasked."""
    cols = {"t[s]": mo.t}
    uname = scene.mechanism.inputs[0]
    uu = scene.units[uname]
    cols[f"{uname}[{uu}]"] = mo.u[..., 0]
    cols[f"{uname}_dot[{uu}/s]"] = mo.u_dot[..., 0]
    cols[f"{uname}_ddot[{uu}/s^2]"] = mo.u_ddot[..., 0]
    for i, n in enumerate(scene.mechanism.coords):
        un = scene.units[n]
        cols[f"{n}[{un}]"] = mo.q[..., i]
        cols[f"{n}_dot[{un}/s]"] = mo.q_dot[..., i]
        cols[f"{n}_ddot[{un}/s^2]"] = mo.q_ddot[..., i]
    for n, (v, unit) in (outputs or {}).items():
        cols[f"{n}[{unit}]"] = xp.broadcast_to(xp.asarray(v), mo.t.shape)
    return cols


def _drive_column(scene: Scene, name: str) -> bool:
    """Whether a column is defined at failed samples too (time and the input's drive)."""
    return name == "t[s]" or name.split("[")[0] in {
        f"{scene.mechanism.inputs[0]}{s}" for s in ("", "_dot", "_ddot")
    }


def design_columns(scene: Scene, points: int, p, *, options: SolverOptions = SolverOptions(), anchors: int = 256):
    """One design's table columns, traceable: ``({NAME[UNIT]: (N,)}, status (N,))``.

    Columns are those of ``SceneResult.table`` (without ``status[-]``), and at failed
    samples they hold finite placeholders (see ``design_motion``): mask them with the
    status.  Used by the sweep kernel and by ``jaxmech.design.scene_figure``.
    """
    mo, _ = design_motion(scene, points, p, options=options, anchors=anchors)
    p = {k: jnp.asarray(v, mo.q.dtype) for k, v in p.items()}
    outs = scene.outputs(p, mo) if scene.outputs is not None else None
    return _columns(scene, mo, outs), mo.status


def _mask_columns(scene, cols, status, xp):
    ok = status == Status.CONVERGED
    return {k: v if _drive_column(scene, k) else xp.where(ok, v, xp.nan) for k, v in cols.items()}


# =========================================================================== the kernel
# Column order as the scene writes it (run_scene's order), recorded when the kernel is
# traced: a compiled program returns its dict outputs with their keys sorted.
_COLUMN_ORDER: dict = {}


def _in_scene_order(scene: Scene, cols: dict) -> dict:
    """``cols`` in the order ``run_scene``'s table has them (sorted back, where known)."""
    order = _COLUMN_ORDER.get(scene.name)
    if not order or set(order) != set(cols):
        return cols
    return {k: cols[k] for k in order}


def _kernel_full(scene, points, options, anchors, p):
    def one(p1):
        cols, status = design_columns(scene, points, p1, options=options, anchors=anchors)
        _COLUMN_ORDER[scene.name] = list(cols)
        return _mask_columns(scene, cols, status, jnp), status

    return jax.vmap(one)(p)


def _kernel_motion(scene, points, options, anchors, p):
    return jax.vmap(lambda p1: design_motion(scene, points, p1, options=options, anchors=anchors)[0])(p)


def _mesh_sharding():
    devices = np.asarray(jax.devices())
    mesh = jax.sharding.Mesh(devices, ("designs",))
    return jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("designs")), len(devices)


_COMPILED: dict = {}  # (scene, points, options, anchors, mode, chunk, devices, x64, names) -> compiled
_PER_DESIGN: dict = {}  # (scene, points, options, anchors, devices, x64) -> bytes per design


def _compiled(scene, points, options, anchors, mode, chunk, param_names):
    """AOT-compiled kernel for a chunk of ``chunk`` designs, sharded over local devices."""
    sharding, ndev = _mesh_sharding()
    key = (scene, points, options, anchors, mode, chunk, tuple(jax.devices()), jax.config.jax_enable_x64, param_names)
    hit = _COMPILED.get(key)
    if hit is not None:
        return hit, sharding
    fn = _kernel_full if mode == "full" else _kernel_motion
    dtype = jnp.result_type(float)
    spec = {k: jax.ShapeDtypeStruct((chunk,), dtype, sharding=sharding) for k in param_names}
    jitted = jax.jit(
        lambda p: fn(scene, points, options, anchors, p),
        in_shardings=(sharding,),
        out_shardings=sharding,
    )
    compiled = jitted.lower(spec).compile()
    if len(_COMPILED) > 32:
        _COMPILED.clear()
    _COMPILED[key] = compiled
    return compiled, sharding


def _bytes_per_design(compiled, chunk: int) -> float:
    """Device memory per design of a compiled chunk kernel (arguments, outputs, temporaries),
    summed over the devices (XLA reports one device's share of a sharded kernel)."""
    try:
        m = compiled.memory_analysis()
        total = m.argument_size_in_bytes + m.output_size_in_bytes + m.temp_size_in_bytes
    except Exception:  # noqa: BLE001 - not every backend reports one: no budget control then
        return float("nan")
    return total * jax.device_count() / chunk


def _default_budget() -> float:
    """A quarter of the memory of one device (accelerator) or of the host's free memory."""
    dev = jax.devices()[0]
    try:
        stats = dev.memory_stats() or {}
    except Exception:  # noqa: BLE001
        stats = {}
    if "bytes_limit" in stats:
        return 0.25 * stats["bytes_limit"] * jax.device_count()
    try:
        free = os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        free = 4 * 2**30
    return 0.25 * free


def _run_chunk(scene, points, options, anchors, mode, chunk, params: dict[str, np.ndarray]):
    """Run one chunk (padded to ``chunk`` designs by repeating its first) on the local devices.

    Returns ``(columns, status)`` as numpy arrays with the chunk's own length; in
    ``"motion"`` mode (outputs not vmappable) the outputs are computed design by design.
    """
    names = tuple(params)
    n = len(next(iter(params.values())))
    # A Dask worker may have several devices; and at least two designs per device: XLA
    # compiles a batch of one as scalar code whose last-bit rounding differs from the
    # vectorised code (measured), and a design's result must not depend on its chunk.
    chunk = _round_up(max(chunk, n, 2 * jax.device_count()), jax.device_count())
    compiled, sharding = _compiled(scene, points, options, anchors, mode, chunk, names)
    dtype = jnp.result_type(float)
    padded = {k: np.concatenate([v, np.full(chunk - n, v[0])]).astype(dtype) for k, v in params.items()}
    args = {k: jax.device_put(v, sharding) for k, v in padded.items()}
    out = compiled(args)
    if mode == "full":
        cols, status = out
        return {k: np.asarray(v)[:n] for k, v in cols.items()}, np.asarray(status)[:n]
    mo = jax.tree_util.tree_map(lambda x: np.asarray(x)[:n], out)
    return _outputs_per_design(scene, mo, {k: v[:n] for k, v in padded.items()})


def _outputs_per_design(scene, mo_batch, params):
    """Fallback for scenes whose ``outputs`` cannot be vmapped: call them design by design."""
    n = mo_batch.status.shape[0]
    rows = []
    for i in range(n):
        mo = jax.tree_util.tree_map(lambda x: jnp.asarray(x[i]), mo_batch)
        p = {k: float(v[i]) for k, v in params.items()}
        outs = scene.outputs(p, mo)
        cols = _columns(scene, mo, {k: (np.asarray(v), u) for k, (v, u) in outs.items()}, xp=np)
        rows.append(_mask_columns(scene, {k: np.asarray(v) for k, v in cols.items()}, np.asarray(mo.status), np))
    cols = {k: np.stack([r[k] for r in rows]) for k in rows[0]}
    return cols, np.asarray(mo_batch.status)


def _dask_task(scene_ref, points, options, anchors, mode, chunk, params, x64, cache_dir):
    """One chunk on a Dask worker: same compiled kernel.  The task itself switches float64
    on (and the persistent compilation cache, if the client uses one): a worker process
    does not inherit the client's JAX configuration."""
    if x64 and not jax.config.jax_enable_x64:
        jax.config.update("jax_enable_x64", True)
    if cache_dir and jax.config.jax_compilation_cache_dir != cache_dir:
        jax.config.update("jax_compilation_cache_dir", cache_dir)
    if isinstance(scene_ref, str):
        from .scenes import get_scene

        scene_ref = get_scene(scene_ref)
    return _run_chunk(scene_ref, points, options, anchors, mode, chunk, params)


# =========================================================================== the result
@dataclasses.dataclass(frozen=True)
class SweepResult:
    """A sweep's results as named arrays, with the parameters that produced them.

    - `scene`: the scene's name.
    - `params`: ``{name: (D,)}`` every parameter of every design (SI units).
    - `columns`: ``{NAME[UNIT]: (D, N)}``, the columns of ``SceneResult.table`` (time,
      input, coordinates with ``_dot``/``_ddot``, scene outputs); NaN where the sample
      did not converge (time and input columns excepted).
    - `status`: ``(D, N)`` int32 ``Status`` codes.
    - `errors`: ``{design index: message}`` for designs that were never solved: rejected
      before solving (a non-positive length, ``scene.validate``) or lost with their
      chunk (a worker died, a task raised or timed out).  Their status is ``NONFINITE``
      at every sample and their values are NaN.
    - `info`: how it ran: ``chunk_size``, ``n_chunks``, ``devices``, ``bytes_per_design``
      (device memory of the compiled kernel, NaN when unknown), ``seconds``, ``backend``
      (``"local"`` or ``"dask"``), ``outputs`` (``"vmap"`` or ``"per design"``).
    """

    scene: str
    params: dict
    columns: dict
    status: np.ndarray
    errors: dict = dataclasses.field(default_factory=dict)
    info: dict = dataclasses.field(default_factory=dict)

    @property
    def n_designs(self) -> int:
        return int(self.status.shape[0])

    @property
    def n_points(self) -> int:
        return int(self.status.shape[1])

    @property
    def ok(self) -> np.ndarray:
        """``(D,)`` designs that converged at every sample."""
        return np.all(self.status == Status.CONVERGED, axis=1)

    def design(self, i: int) -> dict[str, Any]:
        """Parameters of design ``i`` as ``{name: float}``."""
        return {k: float(v[i]) for k, v in self.params.items()}

    def table(self, i: int) -> dict[str, np.ndarray]:
        """Design ``i``'s columns, as ``SceneResult.table()`` (``status[-]`` included)."""
        return {**{k: v[i] for k, v in self.columns.items()}, "status[-]": self.status[i]}

    def summary(self) -> str:
        """Short text: designs, samples, status counts, and the designs that never ran."""
        lines = [
            f"sweep of scene {self.scene!r}: {self.n_designs} designs x {self.n_points} points; "
            f"{int(self.ok.sum())} designs converged everywhere",
            f"sample status: {status_counts(self.status)}",
        ]
        for i, msg in list(self.errors.items())[:10]:
            lines.append(f"design {i}: {msg}")
        if len(self.errors) > 10:
            lines.append(f"... and {len(self.errors) - 10} more designs with errors")
        return "\n".join(lines)

    # ------------------------------------------------------------------ export
    def to_csv(self, path) -> None:
        """Long format: one row per design x input point.

        Columns ``design``, ``point``, every parameter, every ``NAME[UNIT]`` column and
        ``status[-]``; floats with 17 significant digits (exact round trip), NaN as ``nan``.
        """
        d, n = self.status.shape
        head = ["design", "point", *self.params, *self.columns, "status[-]"]
        for h in head:
            if "," in h:
                raise ValueError(f"to_csv: column name {h!r} contains a comma")
        design = np.repeat(np.arange(d), n)
        point = np.tile(np.arange(n), d)
        data = np.column_stack(
            [design, point]
            + [np.repeat(np.asarray(v, float), n) for v in self.params.values()]
            + [np.asarray(v, float).reshape(-1) for v in self.columns.values()]
            + [self.status.reshape(-1)]
        )
        fmt = ["%d", "%d"] + ["%.17g"] * (len(self.params) + len(self.columns)) + ["%d"]
        np.savetxt(path, data, fmt=fmt, delimiter=",", header=",".join(head), comments="")

    @classmethod
    def from_csv(cls, path, scene: str = "") -> SweepResult:
        """Read ``to_csv`` output back (``errors`` are not stored in CSV)."""
        with open(path) as fh:
            head = fh.readline().strip().split(",")
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        design = data[:, 0].astype(int)
        point = data[:, 1].astype(int)
        d, n = design.max() + 1, point.max() + 1
        cols, params = {}, {}
        for j, h in enumerate(head[2:-1], start=2):
            v = np.empty((d, n))
            v[design, point] = data[:, j]
            (cols if "[" in h else params)[h] = v if "[" in h else v[:, 0]
        status = np.empty((d, n), np.int32)
        status[design, point] = data[:, -1].astype(np.int32)
        return cls(scene=scene, params=params, columns=cols, status=status)

    def to_npz(self, path) -> None:
        """Arrays by name: ``param:NAME``, ``column:NAME[UNIT]``, ``status``, ``scene`` and
        the ``errors`` as ``error_index``/``error_message``."""
        arrays = {f"param:{k}": np.asarray(v) for k, v in self.params.items()}
        arrays.update({f"column:{k}": np.asarray(v) for k, v in self.columns.items()})
        idx = np.array(list(self.errors), dtype=np.int64)
        msg = np.array([self.errors[i] for i in idx], dtype=str)
        np.savez(path, status=self.status, scene=np.array(self.scene), error_index=idx, error_message=msg, **arrays)

    @classmethod
    def from_npz(cls, path) -> SweepResult:
        """Read ``to_npz`` output back."""
        with np.load(path, allow_pickle=False) as z:
            params = {k[6:]: z[k] for k in z.files if k.startswith("param:")}
            cols = {k[7:]: z[k] for k in z.files if k.startswith("column:")}
            errors = {int(i): str(m) for i, m in zip(z["error_index"], z["error_message"])}
            return cls(scene=str(z["scene"]), params=params, columns=cols, status=z["status"], errors=errors)


# =========================================================================== the sweep
class _Progress:
    """Plain-text progress on stderr, shown when the sweep promises to last a few seconds."""

    def __init__(self, label: str, total: int, mode: bool | None):
        self.label, self.total, self.mode = label, total, mode
        self.start = time.perf_counter()
        self.last = -1.0
        self.shown = False
        self.tty = sys.stderr.isatty()

    def update(self, done_designs: int, done_chunks: int, n_chunks: int):
        now = time.perf_counter()
        elapsed = now - self.start
        if self.mode is False:
            return
        if self.mode is None and not self.shown:
            rate = done_designs / elapsed if elapsed > 0 and done_designs else 0.0
            expected = self.total / rate if rate > 0 else 0.0
            if expected < _PROGRESS_AFTER_S or done_designs >= self.total:
                return
        # A terminal line is rewritten in place; a log gets a line every 10 s at most.
        if now - self.last < (0.5 if self.tty else 10.0) and done_designs < self.total:
            return
        self.last, self.shown = now, True
        left = elapsed * (self.total - done_designs) / max(done_designs, 1)
        msg = (
            f"{self.label}: {done_designs}/{self.total} designs ({done_chunks}/{n_chunks} chunks), "
            f"{elapsed:.1f} s elapsed, ~{left:.1f} s left"
        )
        sys.stderr.write(("\r" + msg) if self.tty else msg + "\n")
        sys.stderr.flush()

    def close(self):
        if self.shown:
            elapsed = time.perf_counter() - self.start
            sys.stderr.write(("\r" if self.tty else "") + f"{self.label}: done, {self.total} designs in {elapsed:.1f} s\n")
            sys.stderr.flush()


def _design_table(scene: Scene, grid_: Mapping | None, table: Mapping | None) -> dict[str, np.ndarray]:
    if grid_ is not None and table is not None:
        raise ValueError("sweep_scene: give either grid or table, not both (combine them with grid() yourself)")
    given = grid(grid_) if grid_ is not None else dict(table) if table is not None else {}
    unknown = [k for k in given if k not in scene.defaults]
    if unknown:
        raise ValueError(
            f"sweep_scene: scene {scene.name!r} has no parameter(s) {unknown}; its parameters are: {', '.join(scene.defaults)}"
        )
    arrays = {}
    for k, v in given.items():
        a = np.asarray(v)
        if not np.issubdtype(a.dtype, np.number):
            raise ValueError(f"sweep_scene: parameter {k!r} must be numbers, got dtype {a.dtype}")
        arrays[k] = np.atleast_1d(a.astype(float))
        if arrays[k].ndim != 1:
            raise ValueError(f"sweep_scene: parameter {k!r} must be a 1-D array of designs, got shape {a.shape}")
    sizes = {k: len(v) for k, v in arrays.items()}
    if len(set(sizes.values())) > 1:
        raise ValueError(f"sweep_scene: table columns differ in length: {sizes}")
    d = next(iter(sizes.values())) if sizes else 1
    if d == 0:
        raise ValueError("sweep_scene: no designs to run")
    return {k: arrays[k] if k in arrays else np.full(d, float(v)) for k, v in scene.defaults.items()}


def _reject(scene: Scene, params: dict[str, np.ndarray]) -> dict[int, str]:
    """Per-design value checks (vectorised ``check_params``, then ``scene.validate``)."""
    mech = scene.mechanism
    errors: dict[int, str] = {}
    for k, v in params.items():
        bad = ~np.isfinite(v)
        for i in np.flatnonzero(bad):
            errors.setdefault(int(i), f"rejected: parameter {k!r} = {v[i]!r} is not finite")
        if k in mech.lengths and k not in mech.signed:
            for i in np.flatnonzero(~bad & (v <= 0)):
                errors.setdefault(int(i), f"rejected: length {k!r} = {v[i]!r} must be positive")
    if scene.validate is not None:
        d = len(next(iter(params.values())))
        for i in range(d):
            if i in errors:
                continue
            try:
                scene.validate({k: float(v[i]) for k, v in params.items()})
            except ValueError as e:
                errors[i] = f"rejected by scene.validate: {e}"
    return errors


def sweep_scene(
    scene,
    grid: Mapping[str, Any] | None = None,
    *,
    table: Mapping[str, Any] | None = None,
    points: int = 101,
    chunk_size: int | None = None,
    memory_budget: float | None = None,
    progress: bool | None = None,
    client=None,
    options: SolverOptions = SolverOptions(),
    anchors: int = 256,
    timeout: float | None = None,
) -> SweepResult:
    """Run a scene for a batch of designs, each over its whole stroke, in one call.

    Per design the computation is ``run_scene``'s (same stroke, drive, continuation and
    columns); the designs are vmapped through one compiled kernel, in chunks.

    **Arguments**

    - `scene`: a ``Scene`` or a registered scene name.
    - `grid`: ``{name: 1-D values}``, a full-factorial grid (see ``grid``); parameters not
      named keep the scene's defaults (SI units).
    - `table`: ``{name: (D,) values}``, an explicit list of designs (e.g. ``random_designs``).
      Neither: the default design alone.
    - `points`: samples along the stroke, both ends included.
    - `chunk_size`: designs per compiled chunk (rounded up to a multiple of the device
      count).  Default: the most that fits `memory_budget`, at most 1024 per device on a
      CPU and 65536 per device on an accelerator.
    - `memory_budget`: bytes of device memory a chunk may use (arguments, results and
      temporaries, from the compiled kernel's memory analysis).  Default: a quarter of the
      device memory (or of the free host memory on a CPU).  The gathered results on the
      host, ``D x N x columns x 8`` bytes, come on top.
    - `progress`: ``True``/``False`` to force the stderr progress line; ``None`` shows it
      when the sweep is expected to run longer than a few seconds.
    - `client`: a ``distributed.Client``: chunks become Dask tasks (each worker runs the
      same kernel, with float64 enabled when it is enabled here).  A chunk whose task
      fails or exceeds `timeout` stops nothing else: its designs are kept with status
      ``NONFINITE`` and the reason in ``errors``.
    - `options`, `anchors`: solver settings, as for ``solve_stroke``.
    - `timeout`: seconds to wait for the Dask tasks (``None``: no limit).

    **Returns** a ``SweepResult``.

    **Raises** ``ValueError`` for unknown parameter names, ragged tables or bad settings
    (before any tracing).  Per-design value problems (a non-positive length, a
    ``scene.validate`` refusal) do not raise: those designs are kept and reported.
    """
    if isinstance(scene, str):
        from .scenes import get_scene

        scene = get_scene(scene)
    if not isinstance(scene, Scene):
        raise ValueError(f"sweep_scene: scene must be a Scene or a scene name, got {type(scene).__name__}")
    if points < 2:
        raise ValueError(f"sweep_scene: points must be at least 2, got {points}")
    if chunk_size is not None and chunk_size < 1:
        raise ValueError(f"sweep_scene: chunk_size must be positive, got {chunk_size}")
    if memory_budget is not None and not memory_budget > 0:
        raise ValueError(f"sweep_scene: memory_budget must be a positive number of bytes, got {memory_budget}")
    params = _design_table(scene, grid, table)
    d = len(next(iter(params.values())))
    errors = _reject(scene, params)
    rejected = np.fromiter(errors, dtype=np.int64, count=len(errors))
    run_params = {k: v.copy() for k, v in params.items()}
    for k, v in run_params.items():  # run a harmless stand-in; its results are discarded below
        v[rejected] = float(scene.defaults[k])
    budget = float(memory_budget) if memory_budget is not None else _default_budget()
    progress_bar = _Progress(f"sweep {scene.name}", d, progress)
    t0 = time.perf_counter()
    if client is None:
        cols, status, chunk_errors, info = _sweep_local(scene, points, options, anchors, run_params, chunk_size, budget, progress_bar)
    else:
        cols, status, chunk_errors, info = _sweep_dask(client, scene, points, options, anchors, run_params, chunk_size, budget, timeout, progress_bar)
    progress_bar.close()
    status[rejected] = Status.NONFINITE
    for v in cols.values():
        v[rejected] = np.nan
    errors.update({i: m for i, m in chunk_errors.items() if i not in errors})
    info["seconds"] = time.perf_counter() - t0
    return SweepResult(
        scene=scene.name, params=params, columns=_in_scene_order(scene, cols), status=status, errors=dict(sorted(errors.items())), info=info
    )


def _round_up(n: int, m: int) -> int:
    return -(-n // m) * m


def _first_compile(scene, points, options, anchors, names, chunk):
    """Compile the vmapped kernel, or the motion-only kernel when outputs cannot be vmapped."""
    try:
        return "full", _compiled(scene, points, options, anchors, "full", chunk, names)[0]
    except jax.errors.JAXTypeError:
        # scene.outputs converts traced values to Python/numpy: evaluate it design by design.
        return "motion", _compiled(scene, points, options, anchors, "motion", chunk, names)[0]


def _chunk_plan(scene, points, options, anchors, names, d, chunk_size, budget):
    ndev = jax.device_count()
    if chunk_size is not None:
        chunk = _round_up(int(chunk_size), ndev)
    else:
        # Powers of two: sweeps of similar sizes share one compiled kernel.
        accel = jax.devices()[0].platform != "cpu"
        cap = (65536 if accel else 1024) * ndev
        chunk = _round_up(min(1 << max(0, (d - 1).bit_length()), cap), ndev)
        key = (scene, points, options, anchors, tuple(jax.devices()), jax.config.jax_enable_x64)
        per = _PER_DESIGN.get(key)
        if per is not None and per * chunk > budget:
            chunk = max(ndev, int(budget // per) // ndev * ndev)
    mode, compiled = _first_compile(scene, points, options, anchors, names, chunk)
    per = _bytes_per_design(compiled, chunk)
    if np.isfinite(per):
        _PER_DESIGN[(scene, points, options, anchors, tuple(jax.devices()), jax.config.jax_enable_x64)] = per
        if per * chunk > budget:
            fit = max(ndev, int(budget // per) // ndev * ndev)
            if fit < chunk:
                chunk = fit
                _compiled(scene, points, options, anchors, mode, chunk, names)
    return mode, chunk, per


def _mark_lost(errors: dict, s: int, e: int, exc: Exception) -> None:
    """Record designs ``s..e-1`` as lost with their chunk (they keep a failure status)."""
    for i in range(s, e):
        errors[i] = f"lost with its chunk (designs {s}..{e - 1}): {type(exc).__name__}: {exc}"


def _store_chunk(cols, status, d: int, points: int, s: int, e: int, c: dict, st):
    """Write one chunk's columns and statuses into the result arrays (made on first use)."""
    if cols is None:
        cols, status = _empty_results(d, points, c)
    for k, v in c.items():
        cols[k][s:e] = v
    status[s:e] = st
    return cols, status


def _empty_results(d, n, names):
    return {k: np.full((d, n), np.nan) for k in names}, np.full((d, n), int(Status.NONFINITE), np.int32)


def _sweep_local(scene, points, options, anchors, params, chunk_size, budget, progress_bar):
    d = len(next(iter(params.values())))
    names = tuple(params)
    mode, chunk, per = _chunk_plan(scene, points, options, anchors, names, d, chunk_size, budget)
    starts = list(range(0, d, chunk))
    cols = status = None
    errors: dict[int, str] = {}
    for j, s in enumerate(starts):
        e = min(s + chunk, d)
        part = {k: v[s:e] for k, v in params.items()}
        try:
            c, st = _run_chunk(scene, points, options, anchors, mode, chunk, part)
        except Exception as exc:  # noqa: BLE001 - a failed chunk stops nothing else
            _mark_lost(errors, s, e, exc)
            if cols is None and j == len(starts) - 1:
                raise
            continue
        cols, status = _store_chunk(cols, status, d, points, s, e, c, st)
        progress_bar.update(e, j + 1, len(starts))
    if cols is None:
        raise RuntimeError(f"sweep_scene: every chunk failed; first error: {next(iter(errors.values()))}")
    info = dict(chunk_size=chunk, n_chunks=len(starts), devices=jax.device_count(), bytes_per_design=per,
                backend="local", outputs="vmap" if mode == "full" else "per design")
    return cols, status, errors, info


def _sweep_dask(client, scene, points, options, anchors, params, chunk_size, budget, timeout, progress_bar):
    import distributed

    d = len(next(iter(params.values())))
    names = tuple(params)
    n_workers = max(1, len(client.scheduler_info().get("workers", {})))
    if chunk_size is None:
        # Enough tasks to balance the workers; each within the per-worker memory budget,
        # estimated from the shapes of one design's results (x16 for temporaries).
        one = jax.eval_shape(
            lambda p: _kernel_motion(scene, points, options, anchors, p),
            {k: jax.ShapeDtypeStruct((1,), jnp.result_type(float)) for k in names},
        )
        per = 16 * sum(x.size * x.dtype.itemsize for x in jax.tree_util.tree_leaves(one))
        chunk_size = max(1, min(-(-d // (4 * n_workers)), 1024, int(budget // per)))
    chunk = min(int(chunk_size), d)
    try:
        from .scenes import get_scene

        registered = get_scene(scene.name) is scene
    except ValueError:
        registered = False
    # A registered scene travels by name; any other is scattered once, so that every task
    # on a worker sees the same object (and hits the same compiled kernel).
    scene_ref = scene.name if registered else client.scatter(scene, broadcast=True)
    mode = "full"
    try:
        jax.eval_shape(
            lambda p: _kernel_full(scene, points, options, anchors, p),
            {k: jax.ShapeDtypeStruct((1,), jnp.result_type(float)) for k in names},
        )
    except jax.errors.JAXTypeError:
        mode = "motion"
    x64 = bool(jax.config.jax_enable_x64)
    cache_dir = jax.config.jax_compilation_cache_dir
    starts = list(range(0, d, chunk))
    futures = {}
    for s in starts:
        e = min(s + chunk, d)
        part = {k: v[s:e] for k, v in params.items()}
        fut = client.submit(_dask_task, scene_ref, points, options, anchors, mode, chunk, part, x64, cache_dir, pure=False)
        futures[fut] = (s, e)
    cols = status = None
    errors: dict[int, str] = {}
    done = 0
    finished = set()
    try:
        for fut in distributed.as_completed(list(futures), timeout=timeout):
            s, e = futures[fut]
            finished.add(fut)
            try:
                c, st = fut.result()
            except Exception as exc:  # noqa: BLE001 - a failed chunk stops nothing else
                _mark_lost(errors, s, e, exc)
                continue
            cols, status = _store_chunk(cols, status, d, points, s, e, c, st)
            done += e - s
            progress_bar.update(done, len(finished), len(starts))
    except TimeoutError:  # the remaining chunks are marked lost below
        pass
    for fut, (s, e) in futures.items():
        if fut not in finished:
            fut.cancel()
            for i in range(s, e):
                errors[i] = f"lost with its chunk (designs {s}..{e - 1}): not finished within timeout={timeout} s"
    if cols is None:
        raise RuntimeError(f"sweep_scene: every chunk failed; first error: {next(iter(errors.values()))}")
    info = dict(chunk_size=chunk, n_chunks=len(starts), devices=n_workers, bytes_per_design=float("nan"),
                backend="dask", outputs="vmap" if mode == "full" else "per design")
    return cols, status, errors, info
