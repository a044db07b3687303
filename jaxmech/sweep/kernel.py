"""The compiled chunk kernels of a sweep: one design vmapped over a chunk of designs,
laid out over the local devices, cached by everything that makes the program; the chunk
plan that fits a memory budget; and one chunk run (locally or as a Dask task).

A kernel returns either the table columns ``(chunk, N)`` of every design (trace mode) or
the figures ``(chunk,)`` reduced over the stroke inside the kernel (figures mode), so a
figures sweep moves a few numbers per design off the device.
"""

from __future__ import annotations

import dataclasses
import os
import types

import jax
import jax.numpy as jnp
import numpy as np

from ..continuation.solve import robust_size
from ..scenes.base import Scene
from ..solver.options import SolverOptions
from ..solver.status import Status
from .designs import reject
from ..scenes.columns import mask_failed, part_columns, table_columns
from ..scenes.evaluation import outputs_stage, repair_stage, repaired_part, scene_kinematics, scene_motion, stroke_stage
from ..scenes.outputs import output_units, run_outputs
from ..solver.xla import jit
from .evaluate import Figures, figure_names, stroke_figures

__all__ = ["ChunkData", "Job", "bytes_per_design_estimate", "outputs_mode", "default_budget", "lost_chunk",
           "plan_chunk", "run_chunk"]


@dataclasses.dataclass(frozen=True)
class Job:
    """What every chunk of one sweep runs; static (hashable), part of the kernel's identity.

    - `points`: samples along each stroke; `options`: solver settings.
    - `figures`: ``None`` (trace mode: every table column at every sample) or the
      ``Figures`` reduced over the stroke inside the kernel.
    - `chunk`: designs per compiled call; `outputs`: ``"vmap"`` (the scene's outputs are
      traced into the kernel) or ``"per design"`` (they are not traceable: evaluated on
      the host, design by design, from the kernel's motion).
    """

    points: int
    options: SolverOptions
    figures: Figures | None
    chunk: int
    outputs: str = "vmap"


@dataclasses.dataclass
class ChunkData:
    """One chunk's results on the host (numpy), designs ``start .. start + n - 1``.

    `columns`: ``{name: (n, N)}`` table columns (trace mode, NaN at failed samples) or
    ``{name: (n,)}`` figures with ``failed_points[-]``; `status`: ``(n, N)`` per sample or
    ``(n,)`` per design; `errors`: ``{design index: message}`` for designs never solved.
    """

    start: int
    params: dict
    columns: dict
    status: np.ndarray
    errors: dict

    @property
    def n(self) -> int:
        return int(self.status.shape[0])


def _rest(scene: Scene, job: Job):
    """``(p, part) -> outputs``: a chunk kernel's second program, from the stroke stage's
    ``part`` (``scenes.evaluation.StrokePart``).  Trace mode: ``outputs_stage`` (what
    ``run_scene`` runs: a design's columns are cut from it on the host, so they are
    ``run_scene``'s bit for bit); figures mode: the figures ``(chunk,)`` and the status,
    reduced in the kernel; the motion alone where the outputs are per design."""
    if job.outputs != "vmap":
        return lambda p, part: scene_kinematics(scene, job.points, p, part)[0]
    if job.figures is None:
        with_outputs = scene.outputs is not None
        return lambda p, part: outputs_stage(scene, job.points, with_outputs, p, part)

    def figures(p, part):
        cols, status = part_columns(scene, job.points, p, part)
        figs = jax.vmap(lambda c, s, p1: stroke_figures(scene, job.figures, c, s, p1))(cols, status, p)
        status = figs.pop("status[-]")
        return figs, status

    return figures


def _chunk(scene: Scene, job: Job, p):
    """A chunk of designs (``p`` leaves ``(chunk,)``) as one traced function: the stroke
    (the walk and its repair) then ``_rest``; for shape and outputs checks."""
    return _rest(scene, job)(p, stroke_stage(scene, job.points, job.options, True, p))


def _trace_columns(scene: Scene, job: Job, mo, values, p) -> tuple[dict, np.ndarray]:
    """Masked columns ``{NAME[UNIT]: (n, N)}`` and status ``(n, N)`` (host numpy) from the
    trace-mode kernel's motion and output values, as ``SceneResult.table`` cuts them."""
    units = output_units(scene) if values else {}
    status = np.asarray(mo.status)
    cols = table_columns(scene, mo, {k: (values[k], u) for k, u in units.items()}, xp=np)
    cols = mask_failed(scene, cols, status, np)
    return {k: np.array(v) for k, v in cols.items()}, status.copy()


def in_scene_order(scene: Scene, figures: Figures, cols: dict) -> dict:
    """A figures kernel's ``cols`` in the figures' order (``evaluate.figure_names``): a
    compiled program returns its dict outputs with their keys sorted."""
    return {k: cols[k] for k in figure_names(scene, figures)}


def outputs_mode(scene: Scene, job: Job, param_names) -> str:
    """``"vmap"`` when the scene's outputs trace into the kernel, else ``"per design"``
    (``scenes.outputs.run_outputs`` tells, tracing one design's kernel)."""
    spec = {k: jax.ShapeDtypeStruct((1,), jnp.result_type(float)) for k in param_names}

    def run(traced: bool) -> str:
        mode = "vmap" if traced else "per design"
        jax.eval_shape(lambda p: _chunk(scene, dataclasses.replace(job, outputs=mode), p), spec)
        return mode

    return run_outputs(scene, run)


def bytes_per_design_estimate(scene: Scene, job: Job, param_names) -> float:
    """Host bytes of one design's motion, times 16 for the kernel's temporaries: a budget
    estimate where the kernel is compiled elsewhere (on Dask workers)."""
    one = jax.eval_shape(
        lambda p: scene_motion(scene, job.points, p, job.options)[0],
        {k: jax.ShapeDtypeStruct((1,), jnp.result_type(float)) for k in param_names},
    )
    return 16.0 * sum(x.size * x.dtype.itemsize for x in jax.tree_util.tree_leaves(one))


def _mesh_sharding():
    devices = np.asarray(jax.devices())
    mesh = jax.sharding.Mesh(devices, ("designs",))
    return jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("designs"))


_COMPILED: dict = {}  # (scene, job, devices, x64, names) -> compiled
_PER_DESIGN: dict = {}  # (scene, job without chunk, devices, x64) -> bytes per design


class _Staged:
    """A chunk kernel as ``run_scene`` runs a scene (``scenes.evaluation.evaluate``): the
    stroke's walk (``stroke_stage``) for the chunk, its repair (``repair_stage``) for the
    designs where a sample failed, gathered ``robust_size(chunk)`` at a time and compiled
    the first time one does, and the rest (``_rest``) for the chunk."""

    def __init__(self, scene: Scene, job: Job, spec: dict, sharding):
        self.scene, self.job, self.sharding = scene, job, sharding
        first = jit(lambda p: stroke_stage(scene, job.points, job.options, False, p), in_shardings=(sharding,), out_shardings=sharding)
        lowered = first.lower(spec)
        self.part_info = lowered.out_info
        part = jax.tree_util.tree_map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=sharding), lowered.out_info)
        second = jit(_rest(scene, job), in_shardings=(sharding, sharding), out_shardings=sharding).lower(spec, part)
        # Compiled one after the other on this thread: compiled at once on two threads, the
        # suite's workers crashed with jaxlib 0.10.2 (segfaults beside another thread's XLA
        # work, twice on fresh CI machines; see stored._store)
        self.second = second.compile()
        self.first = lowered.compile()
        self.size = round_up(robust_size(job.chunk), jax.device_count())
        self._repair = None

    def _put(self, tree):
        return jax.device_put(tree, self.sharding)  # one call for the whole pytree

    def _repair_rows(self, p, part):
        """The repair stage for ``self.size`` designs (host rows of ``p`` and ``part``)."""
        if self._repair is None:
            job, size, sh = self.job, self.size, self.sharding
            spec = lambda x: jax.ShapeDtypeStruct((size,) + tuple(x.shape[1:]), x.dtype, sharding=sh)  # noqa: E731
            fn = jit(lambda p_, part_: repair_stage(self.scene, job.points, job.options, p_, part_), in_shardings=(sh, sh), out_shardings=sh)
            self._repair = fn.lower({k: spec(v) for k, v in p.items()}, jax.tree_util.tree_map(spec, self.part_info)).compile()
        return self._repair(self._put(p), self._put(part))

    def __call__(self, p):
        part = repaired_part(self.first(p), p, self._repair_rows, self.size)
        return self.second(p, self._put(part))

    def memory_analysis(self):
        """The walk's and the rest's arguments, outputs and temporaries (the second's
        arguments are the first's outputs and the parameters, counted once)."""
        a, b = self.first.memory_analysis(), self.second.memory_analysis()
        return types.SimpleNamespace(
            argument_size_in_bytes=a.argument_size_in_bytes,
            output_size_in_bytes=a.output_size_in_bytes + b.output_size_in_bytes,
            temp_size_in_bytes=max(a.temp_size_in_bytes, b.temp_size_in_bytes),
        )


def compiled_kernel(scene: Scene, job: Job, param_names):
    """AOT-compiled kernel for a chunk of ``job.chunk`` designs, sharded over local devices."""
    sharding = _mesh_sharding()
    key = (scene, job, tuple(jax.devices()), jax.config.jax_enable_x64, tuple(param_names))
    hit = _COMPILED.get(key)
    if hit is not None:
        return hit, sharding
    dtype = jnp.result_type(float)
    spec = {k: jax.ShapeDtypeStruct((job.chunk,), dtype, sharding=sharding) for k in param_names}
    compiled = _Staged(scene, job, spec, sharding)
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


def default_budget() -> float:
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


def round_up(n: int, m: int) -> int:
    return -(-n // m) * m


def _first_compile(scene, job, names):
    """Compile the vmapped kernel, or the motion-only kernel where the scene's outputs do not
    trace (``scenes.outputs.run_outputs``: they are evaluated design by design)."""

    def run(traced: bool):
        j = dataclasses.replace(job, outputs="vmap" if traced else "per design")
        return compiled_kernel(scene, j, names)[0], j

    return run_outputs(scene, run)


def plan_chunk(scene: Scene, job: Job, names, d: int, chunk_size: int | None, budget: float):
    """The chunk size (``job.chunk`` is ignored) and output mode of a local sweep; compiles
    the kernel.  Returns ``(job, bytes per design)``."""
    ndev = jax.device_count()
    cache_key = (scene, dataclasses.replace(job, chunk=0), tuple(jax.devices()), jax.config.jax_enable_x64)
    if chunk_size is not None:
        chunk = round_up(int(chunk_size), ndev)
    else:
        # Powers of two: sweeps of similar sizes share one compiled kernel.
        accel = jax.devices()[0].platform != "cpu"
        cap = (65536 if accel else 1024) * ndev
        chunk = round_up(min(1 << max(0, (d - 1).bit_length()), cap), ndev)
        per = _PER_DESIGN.get(cache_key)
        if per is not None and per * chunk > budget:
            chunk = max(ndev, int(budget // per) // ndev * ndev)
    compiled, job = _first_compile(scene, dataclasses.replace(job, chunk=chunk), names)
    per = _bytes_per_design(compiled, chunk)
    if np.isfinite(per):
        _PER_DESIGN[cache_key] = per
        if per * chunk > budget and chunk_size is None:
            fit = max(ndev, int(budget // per) // ndev * ndev)
            if fit < chunk:
                job = dataclasses.replace(job, chunk=fit)
                compiled_kernel(scene, job, names)
    return job, per


def _outputs_per_design(scene: Scene, job: Job, mo_batch, params):
    """Fallback for scenes whose ``outputs`` cannot be vmapped: call them design by design."""
    n = mo_batch.status.shape[0]
    rows = []
    for i in range(n):
        mo = jax.tree_util.tree_map(lambda x: jnp.asarray(x[i]), mo_batch)
        p = {k: float(v[i]) for k, v in params.items()}
        outs = scene.outputs(p, mo)
        cols = table_columns(scene, mo, {k: (np.asarray(v), u) for k, (v, u) in outs.items()}, xp=np)
        cols = {k: np.asarray(v) for k, v in cols.items()}
        status = np.asarray(mo.status)
        if job.figures is None:
            rows.append((mask_failed(scene, cols, status, np), status))
        else:
            figs = stroke_figures(scene, job.figures, cols, status, p, np)
            rows.append((figs, figs.pop("status[-]")))
    cols = {k: np.stack([np.asarray(r[0][k]) for r in rows]) for k in rows[0][0]}
    return cols, np.stack([np.asarray(r[1]) for r in rows])


def _run_kernel(scene: Scene, job: Job, params: dict[str, np.ndarray]):
    """Run one chunk (padded to ``job.chunk`` designs by repeating its first) on the local
    devices; ``(columns, status)`` as numpy arrays with the chunk's own length."""
    names = tuple(params)
    n = len(next(iter(params.values())))
    # A Dask worker may have several devices; and at least two designs per device: XLA
    # compiles a batch of one as scalar code whose last-bit rounding differs from the
    # vectorised code (measured), and a design's result must not depend on its chunk.
    chunk = round_up(max(job.chunk, n, 2 * jax.device_count()), jax.device_count())
    job = dataclasses.replace(job, chunk=chunk)
    compiled, sharding = compiled_kernel(scene, job, names)
    dtype = jnp.result_type(float)
    padded = {k: np.concatenate([v, np.full(chunk - n, v[0])]).astype(dtype) for k, v in params.items()}
    out = compiled({k: jax.device_put(v, sharding) for k, v in padded.items()})
    if job.outputs == "vmap" and job.figures is None:
        mo, values = jax.tree_util.tree_map(lambda x: np.asarray(x)[:n], out)
        return _trace_columns(scene, job, mo, values, {k: v[:n] for k, v in padded.items()})
    if job.outputs == "vmap":
        cols, status = out
        cols = {k: np.asarray(v)[:n].copy() for k, v in cols.items()}  # writable host copies
        return in_scene_order(scene, job.figures, cols), np.asarray(status)[:n].copy()
    mo = jax.tree_util.tree_map(lambda x: np.asarray(x)[:n], out)
    return _outputs_per_design(scene, job, mo, {k: v[:n] for k, v in padded.items()})


def run_chunk(scene: Scene, job: Job, start: int, params: dict[str, np.ndarray]) -> ChunkData:
    """Designs ``start ..`` of a sweep: value checks, the kernel, rejected designs kept as
    failures (status ``NONFINITE``, NaN values, a message in ``errors``)."""
    errors = reject(scene, params, start)
    run = params
    if errors:
        idx = np.fromiter(errors, dtype=np.int64) - start
        run = {k: v.copy() for k, v in params.items()}
        for k, v in run.items():  # a harmless stand-in; its results are discarded below
            v[idx] = float(scene.defaults[k])
    cols, status = _run_kernel(scene, job, run)
    if errors:
        _fail_rows(cols, status, idx, job.points)
    return ChunkData(start=start, params=params, columns=cols, status=status, errors=errors)


def _fail_rows(cols: dict, status: np.ndarray, idx, points: int) -> None:
    status[idx] = Status.NONFINITE
    for k, v in cols.items():
        v[idx] = points if k == "failed_points[-]" else np.nan


def lost_chunk(job: Job, names, start: int, params: dict[str, np.ndarray], exc: BaseException, dtype=float) -> ChunkData:
    """A chunk whose run raised (or whose task died): every design kept, failed (status
    ``NONFINITE``, NaN values of `dtype`, the reason in ``errors``)."""
    n = len(next(iter(params.values())))
    shape = (n,) if job.figures is not None else (n, job.points)
    cols = {k: np.full(shape, job.points, np.int32) if k == "failed_points[-]" else np.full(shape, np.nan, dtype) for k in names}
    msg = f"lost with its chunk (designs {start}..{start + n - 1}): {type(exc).__name__}: {exc}"
    return ChunkData(start=start, params=params, columns=cols, status=np.full(shape, int(Status.NONFINITE), np.int32),
                     errors={start + i: msg for i in range(n)})
