"""Running a sweep: chunks on the local devices or as Dask tasks, gathered in memory
(``sweep_scene``) or streamed to a Parquet dataset (``sweep_dataset``), with a progress
bar and a one-line summary.

Both entry points walk the same chunks through the same kernel (``kernel.run_chunk``):
locally one after another, or with a Dask ``client`` as independent tasks.  A chunk
whose run raises stops nothing else: its designs are kept as failed rows.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from collections.abc import Mapping
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..scenes.base import Scene, as_scene
from ..solver.options import SolverOptions
from ..scenes.evaluation import SCENE_OPTIONS
from ..solver.status import Status, status_counts
from .dataset import (
    ROWS_PER_FILE, ROWS_PER_GROUP, ChunkReport, Dataset, DatasetWriter, manifest_of, prepare_dataset, write_manifest,
)
from .designs import design_table
from .evaluate import Figures, design_status
from .kernel import (
    Job, bytes_per_design_estimate, default_budget, lost_chunk, outputs_mode, plan_chunk, run_chunk,
)
from .result import SweepResult

__all__ = ["SweepSummary", "sweep_dataset", "sweep_scene"]


# =========================================================================== chunks
def chunk_task(scene_ref, figures_ref, job: Job, start: int, params, x64: bool, cache_dir):
    """One chunk, locally or on a Dask worker: run it and return its arrays (a streamed
    sweep writes them where they are gathered).  On a worker the task itself switches
    float64 on (and the client's persistent compilation cache): a worker process does not
    inherit the client's JAX configuration.  The scene and the figures come by name or
    as scattered objects, so every task on a worker hits the same compiled kernel."""
    if x64 and not jax.config.jax_enable_x64:
        jax.config.update("jax_enable_x64", True)
    if cache_dir and jax.config.jax_compilation_cache_dir != cache_dir:
        jax.config.update("jax_compilation_cache_dir", cache_dir)
    if isinstance(scene_ref, str):
        from ..scenes import get_scene

        scene_ref = get_scene(scene_ref)
    return run_chunk(scene_ref, dataclasses.replace(job, figures=figures_ref), start, params)


def _local_chunks(scene, job, params, starts):
    d = len(next(iter(params.values())))
    for s in starts:
        part = {k: v[s:s + job.chunk] for k, v in params.items()}
        try:
            yield s, min(s + job.chunk, d), chunk_task(scene, job.figures, job, s, part, False, None)
        except Exception as exc:  # noqa: BLE001 - a failed chunk stops nothing else
            yield s, min(s + job.chunk, d), exc


def _dask_chunks(client, scene, job, params, starts, timeout):
    import distributed

    d = len(next(iter(params.values())))
    try:
        from ..scenes import get_scene

        registered = get_scene(scene.name) is scene
    except ValueError:
        registered = False
    # A registered scene travels by name; any other (and figures with user functions) is
    # scattered once, so that every task on a worker sees the same object.
    scene_ref = scene.name if registered else client.scatter(scene, broadcast=True)
    figures_ref = job.figures if job.figures is None or not job.figures.functions else client.scatter(job.figures, broadcast=True)
    x64, cache_dir = bool(jax.config.jax_enable_x64), jax.config.jax_compilation_cache_dir
    futures = {}
    for s in starts:
        part = {k: v[s:s + job.chunk] for k, v in params.items()}
        fut = client.submit(chunk_task, scene_ref, figures_ref, dataclasses.replace(job, figures=None), s, part, x64, cache_dir,
                            pure=False)
        futures[fut] = (s, min(s + job.chunk, d))
    finished = set()
    try:
        for fut in distributed.as_completed(list(futures), timeout=timeout):
            finished.add(fut)
            s, e = futures[fut]
            try:
                yield s, e, fut.result()
            except Exception as exc:  # noqa: BLE001 - a failed chunk stops nothing else
                yield s, e, exc
    except TimeoutError:  # the remaining chunks are lost below
        pass
    for fut, (s, e) in futures.items():
        if fut not in finished:
            fut.cancel()
            yield s, e, TimeoutError(f"not finished within timeout={timeout} s")


def _dask_job(client, scene, job, names, d, chunk_size, budget):
    n_workers = max(1, len(client.scheduler_info().get("workers", {})))
    if chunk_size is None:
        # Enough tasks to balance the workers, each within the per-worker memory budget.
        per = bytes_per_design_estimate(scene, job, names)
        chunk_size = max(1, min(-(-d // (4 * n_workers)), 1024, int(budget // per)))
    return dataclasses.replace(job, chunk=min(int(chunk_size), d), outputs=outputs_mode(scene, job, names)), n_workers


def _prepare(scene, points, chunk_size, memory_budget, who):
    scene = as_scene(scene, who)
    if points < 2:
        raise ValueError(f"{who}: points must be at least 2, got {points}")
    if chunk_size is not None and chunk_size < 1:
        raise ValueError(f"{who}: chunk_size must be positive, got {chunk_size}")
    if memory_budget is not None and not memory_budget > 0:
        raise ValueError(f"{who}: memory_budget must be a positive number of bytes, got {memory_budget}")
    return scene, float(memory_budget) if memory_budget is not None else default_budget()


def _figures(figures) -> Figures | None:
    if figures is None or figures is False:
        return None
    if figures is True:
        return Figures()
    if not isinstance(figures, Figures):
        raise ValueError(f"figures must be None, True or a Figures(...), got {type(figures).__name__}")
    return figures


# =========================================================================== progress
def _progress_bar(label: str, total: int, done: int, show: bool | None):
    """tqdm on stderr with rate and ETA; ``show=None``: only when stderr is a terminal."""
    from tqdm import tqdm

    on = sys.stderr.isatty() if show is None else bool(show)
    return tqdm(total=total, initial=done, desc=label, unit="design", unit_scale=total >= 10**5, file=sys.stderr,
                disable=not on, mininterval=0.5, smoothing=0.1, dynamic_ncols=True)


@dataclasses.dataclass(frozen=True)
class SweepSummary:
    """How a streamed sweep went (``sweep_dataset``'s return value).

    - `path`: the dataset folder; `designs`: designs in the sweep; `counts`: ``{status
      name: designs}`` over the whole dataset (a design's status: its first failing
      sample's, ``CONVERGED`` when none failed).
    - `rows_written`, `chunks_written`: this run; `chunks_skipped`: already written by an
      earlier run (resumed); `lost`: ``{first design: message}`` of the chunks whose run
      failed in this run (kept as failed rows; a rerun retries them).
    - `seconds`: wall time of this run; `info`: chunk size, chunks, backend, devices, mode,
      ``files`` (part files in the dataset), ``lost_files``, ``rows_per_group``, ``rows_per_file``.
    """

    path: str
    designs: int
    counts: dict
    rows_written: int
    chunks_written: int
    chunks_skipped: int
    lost: dict
    seconds: float
    info: dict

    def line(self) -> str:
        """The one-line summary printed at the end of a sweep."""
        return summary_line(self.info.get("label", "sweep"), self.designs, self.counts, self.seconds,
                            f"{self.rows_written} rows written to {self.path}"
                            + (f" ({self.info['files']} files)" if "files" in self.info else "")
                            + (f", {self.chunks_skipped} chunks already there" if self.chunks_skipped else "")
                            + (f", {len(self.lost)} chunks lost (rerun to retry)" if self.lost else ""))


def summary_line(label: str, designs: int, counts: dict, seconds: float, tail: str) -> str:
    ok = counts.get(Status.CONVERGED.name, 0)
    failed = ", ".join(f"{k} {v}" for k, v in sorted(counts.items()) if k != Status.CONVERGED.name) or "none"
    return f"{label}: {designs} designs, {ok} converged, failed: {failed}; {seconds:.1f} s; {tail}"


def _chunks(client, scene, job, params, starts, timeout):
    """The chunks starting at `starts`, ``(start, end, result or exception)``: run here one
    after another, or as Dask tasks of `client`."""
    return _local_chunks(scene, job, params, starts) if client is None else _dask_chunks(client, scene, job, params, starts, timeout)


class Gathered(NamedTuple):
    """A sweep's chunks gathered in memory (``gather_chunks``): `columns` ``{name: (D,
    N)}`` and `status` ``(D, N)`` (None when every chunk failed), the per-design `errors`
    and the first chunk's exception (`first_error`, None if none failed)."""

    columns: dict | None
    status: np.ndarray | None
    errors: dict
    first_error: BaseException | None


def gather_chunks(chunks, job: Job, params, points: int, bar) -> Gathered:
    """Every chunk's columns and statuses copied into ``(D, points)`` arrays; a failed
    chunk's designs stay ``NONFINITE`` with the reason in ``errors``."""
    d = len(next(iter(params.values())))
    cols = status = None
    errors: dict[int, str] = {}
    first_exc = None
    for s, e, res in chunks:
        if isinstance(res, BaseException):
            first_exc = first_exc or res
            errors.update(lost_chunk(job, (), s, {k: v[s:e] for k, v in params.items()}, res).errors)
        else:
            if cols is None:
                cols = {k: np.full((d, points), np.nan, v.dtype) for k, v in res.columns.items()}
                status = np.full((d, points), int(Status.NONFINITE), np.int32)
            for k, v in res.columns.items():
                cols[k][s:e] = v
            status[s:e] = res.status
            errors.update(res.errors)
        bar.update(e - s)
    return Gathered(cols, status, errors, first_exc)


class Streamed(NamedTuple):
    """What ``stream_chunks`` wrote: `rows` and `written` chunks, the `lost` chunks
    ``{start: exception}``, and the result columns' names (None if no chunk came back)."""

    rows: int
    written: int
    lost: dict
    names: tuple | None


def stream_chunks(chunks, writer: DatasetWriter, counts: dict, bar) -> Streamed:
    """Every finished chunk handed to `writer` (its statuses added to `counts`, in place);
    a failed one kept aside in ``lost``.  The bar counts every chunk but the last, whose
    designs are counted once the files are written (``write_chunks``): it ends with the work."""
    rows = written = 0
    lost: dict[int, BaseException] = {}
    names_out = None
    for s, e, res in chunks:
        if isinstance(res, BaseException):
            lost[s] = res
        else:
            rep = writer.add(res)
            names_out = names_out or rep.names
            rows, written = rows + rep.rows, written + 1
            for k, v in rep.counts.items():
                counts[k] = counts.get(k, 0) + v
        if bar.n + (e - s) < bar.total:  # the last chunk waits for the files (write_chunks)
            bar.update(e - s)
    return Streamed(rows, written, lost, names_out)


def write_lost(writer: DatasetWriter, lost: dict, names_out, state, job: Job, params, counts: dict, rows: int):
    """The lost chunks written as failed rows (``NONFINITE``, the error kept), with the
    result columns of this run, or as an earlier run wrote them.  Returns ``(rows,
    {start: message})``; `counts` updated in place."""
    if names_out is None:  # the result columns, as an earlier run wrote them
        import json

        import pyarrow.parquet as pq

        names_out = tuple(json.loads(pq.read_schema(state.example).metadata[b"jaxmech.result_columns"]))
    dtype = np.dtype(jnp.result_type(float))
    lost_msgs = {}
    for s, exc in sorted(lost.items()):
        part = {k: v[s:s + job.chunk] for k, v in params.items()}
        rep: ChunkReport = writer.add_lost(lost_chunk(job, names_out, s, part, exc, dtype))
        rows += rep.rows
        counts[Status.NONFINITE.name] = counts.get(Status.NONFINITE.name, 0) + rep.designs
        lost_msgs[s] = next(iter(rep.errors.values()))
    return rows, lost_msgs


def write_chunks(chunks, writer: DatasetWriter, state, job: Job, params, counts: dict, bar):
    """Stream `chunks` into `writer` (``stream_chunks``), then the lost ones as failed rows
    (``write_lost``), and close it; on any error (a Ctrl-C too) abort it, keeping the chunks
    in memory for a rerun.  Returns ``(rows, chunks written, {start: lost message})``."""
    lost_msgs = {}
    try:
        with bar:
            rows, written, lost, names_out = stream_chunks(chunks, writer, counts, bar)
            if lost:
                if names_out is None and not state.done:
                    first = next(iter(lost.values()))
                    raise RuntimeError(f"sweep_dataset: every chunk failed; first error: {type(first).__name__}: {first}") from first
                rows, lost_msgs = write_lost(writer, lost, names_out, state, job, params, counts, rows)
            writer.close()
            bar.update(bar.total - bar.n)  # the last chunk's designs: written
    except BaseException:
        writer.abort()  # the chunks in memory are kept: a rerun skips them
        raise
    return rows, written + len(lost), lost_msgs


def plan_dataset_job(client, scene, job: Job, names, d: int, state, budget):
    """``(job, devices)``: the chunk size an earlier run of the dataset chose (nothing to
    compile when it finished), or planned for the local devices or the Dask workers."""
    chunk, done = state.chunk, state.done
    devices = jax.device_count()
    if chunk is not None and all(s in done for s in range(0, d, chunk)):
        pass  # finished earlier: nothing to compile
    elif client is None:
        job, _ = plan_chunk(scene, job, names, d, chunk, budget)
    else:
        job, devices = _dask_job(client, scene, job, names, d, chunk, budget)
    return job, devices


def open_writer(out, manifest, scene, names, figures: bool, points: int, state, chunk: int, rows_per_group: int,
                rows_per_file: int) -> DatasetWriter:
    """The manifest written with the chunk size, and a writer of the dataset's row groups
    (`names`: the design parameters, their units from the scene)."""
    write_manifest(out, manifest, chunk)
    dataset = Dataset(path=str(out), figures=figures, points=points, scene=scene.name,
                      parameter_units=tuple((k, scene.parameters.get(k, ("", ""))[0]) for k in names))
    return DatasetWriter(dataset, state, rows_per_group, rows_per_file)


def writer_info(writer: DatasetWriter, rows_per_group, rows_per_file) -> dict:
    """The summary's file counts and row-group and file sizes."""
    return dict(files=len(writer.parts), lost_files=len(writer.lost_files), rows_per_group=int(rows_per_group),
                rows_per_file=int(rows_per_file))


def check_row_counts(rows_per_group, rows_per_file) -> None:
    """``ValueError`` unless both are positive integers."""
    for name, v in (("rows_per_group", rows_per_group), ("rows_per_file", rows_per_file)):
        if not isinstance(v, (int, np.integer)) or v < 1:
            raise ValueError(f"sweep_dataset: {name} must be a positive integer, got {v!r}")


# =========================================================================== in memory
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
    options: SolverOptions = SCENE_OPTIONS,
    timeout: float | None = None,
) -> SweepResult:
    """Run a scene for a batch of designs, each over its whole stroke, in one call; every
    table column of every design is gathered in host memory (``D x N x columns x 8``
    bytes: for large sweeps stream figures or traces to disk with ``sweep_dataset``).

    Per design the computation is ``run_scene``'s (same stroke, drive, continuation and
    columns); the designs are vmapped through one compiled kernel, in chunks.

    **Arguments**

    - `scene`: a ``Scene``, a registered scene name or a ``Linkage`` (``Linkage.scene()``).
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
      host come on top.
    - `progress`: ``True``/``False`` to force the progress bar (tqdm, stderr: rate and
      ETA) and the summary line; ``None``: shown when stderr is a terminal.
    - `client`: a ``distributed.Client``: chunks become Dask tasks (each worker runs the
      same kernel, with float64 enabled when it is enabled here).  A chunk whose task
      fails or exceeds `timeout` stops nothing else: its designs are kept with status
      ``NONFINITE`` and the reason in ``errors``.
    - `options`: solver settings, as for ``solve_stroke`` (default ``SCENE_OPTIONS``: 256
      anchors, as ``run_scene``).
    - `timeout`: seconds to wait for the Dask tasks (``None``: no limit).

    **Returns** a ``SweepResult``.

    **Raises** ``ValueError`` for unknown parameter names, ragged tables or bad settings
    (before any tracing).  Per-design value problems (a non-positive length, a
    ``scene.validate`` refusal) do not raise: those designs are kept and reported.
    """
    scene, budget = _prepare(scene, points, chunk_size, memory_budget, "sweep_scene")
    params = design_table(scene, grid, table)
    d = len(next(iter(params.values())))
    names = tuple(params)
    t0 = time.perf_counter()
    job = Job(points=points, options=options, figures=None, chunk=0)
    if client is None:
        job, per = plan_chunk(scene, job, names, d, chunk_size, budget)
        devices = jax.device_count()
    else:
        job, devices = _dask_job(client, scene, job, names, d, chunk_size, budget)
        per = float("nan")
    starts = list(range(0, d, job.chunk))
    bar = _progress_bar(f"sweep {scene.name}", d, 0, progress)
    shown = not bar.disable
    with bar:
        cols, status, errors, first_exc = gather_chunks(_chunks(client, scene, job, params, starts, timeout), job, params, points, bar)
    if cols is None:
        raise RuntimeError(f"sweep_scene: every chunk failed; first error: {type(first_exc).__name__}: {first_exc}") from first_exc
    seconds = time.perf_counter() - t0
    if shown:
        counts = status_counts(design_status(status, np))
        print(summary_line(f"sweep {scene.name}", d, counts, seconds, f"{d * points} rows in memory"), file=sys.stderr)
    info = dict(chunk_size=job.chunk, n_chunks=len(starts), devices=devices, bytes_per_design=per, seconds=seconds,
                backend="local" if client is None else "dask", outputs=job.outputs)
    return SweepResult(scene=scene.name, params=params, columns=cols, status=status, errors=dict(sorted(errors.items())), info=info)


# =========================================================================== streamed
def sweep_dataset(
    scene,
    out,
    grid: Mapping[str, Any] | None = None,
    *,
    table: Mapping[str, Any] | None = None,
    figures: Figures | bool | None = None,
    points: int = 101,
    chunk_size: int | None = None,
    memory_budget: float | None = None,
    progress: bool | None = None,
    client=None,
    options: SolverOptions = SCENE_OPTIONS,
    timeout: float | None = None,
    rows_per_group: int = ROWS_PER_GROUP,
    rows_per_file: int = ROWS_PER_FILE,
) -> SweepSummary:
    """Run a sweep of any size in bounded memory, streaming it to a Parquet dataset.

    Finished chunks of designs are gathered into row groups of about `rows_per_group`
    rows, and the row groups into files of about `rows_per_file` rows in folder `out`
    (with a Dask `client`, the workers send their chunks back and this process writes
    them), so host memory holds one row group, whatever the number of designs.  Columns
    have plain names (``theta4_max``, ``status``), their units in the Arrow field metadata;
    ``pandas.read_parquet(out)``, ``polars.read_parquet(f"{out}/*.parquet")`` or duckdb
    read it without jaxmech, ``jaxmech.sweep.read_dataset(out)`` with.  The layout
    and the columns are described in ``jaxmech.sweep.dataset``.

    Rerun with the same arguments after an interruption (a kill, a crash, a lost worker)
    and the chunks already written are skipped: the dataset ends with the same rows as an
    uninterrupted run's, none lost or repeated.  A kill loses at most the chunks of the row
    group in memory (they are run again); a Ctrl-C or an error writes them first.

    **Arguments** as ``sweep_scene``, and:

    - `out`: the dataset folder (conventionally ``NAME.parquet``); made if missing.
    - `figures`: ``None`` (trace mode: one row per design and stroke sample, every table
      column), ``True`` (figures mode with the default ``Figures()``: one row per design,
      the max, its position, the min, its position and the travel of every non-drive
      column) or a ``Figures``: reductions computed inside the compiled kernel.
    - `progress`: the progress bar (rate, ETA) and the summary line on stderr; ``None``:
      when stderr is a terminal.
    - `rows_per_group`, `rows_per_file`: rows of a Parquet row group (default 10^5) and of
      a file (default 10^6; a file holds whole row groups, a row group whole chunks).  They
      may change between a run and its rerun.

    **Returns** a ``SweepSummary`` (``.line()`` is the one-line summary).

    **Raises** ``ValueError`` for bad arguments (as ``sweep_scene``), when `out` is a file,
    when it holds a sweep made with other arguments (it names them), or one written in the
    first dataset layout (it says how to convert it).  Failed designs are rows with their
    status (and, if never solved, an ``error`` message), never dropped.
    """
    scene, budget = _prepare(scene, points, chunk_size, memory_budget, "sweep_dataset")
    check_row_counts(rows_per_group, rows_per_file)
    figures = _figures(figures)
    params = design_table(scene, grid, table, who="sweep_dataset")
    d, names, t0 = len(next(iter(params.values()))), tuple(params), time.perf_counter()
    manifest = manifest_of(scene, params, figures=figures, points=points, options=options,
                           x64=bool(jax.config.jax_enable_x64))
    state = prepare_dataset(out, manifest, chunk_size)
    done = state.done  # {start: designs} of the chunks an earlier run wrote
    job, devices = plan_dataset_job(client, scene, Job(points=points, options=options, figures=figures, chunk=state.chunk or 0),
                                    names, d, state, budget)
    writer = open_writer(out, manifest, scene, names, figures is not None, points, state, job.chunk, rows_per_group, rows_per_file)
    starts = [s for s in range(0, d, job.chunk) if s not in done]
    counts: dict[str, int] = dict(state.counts)
    label = f"sweep {scene.name}"
    bar = _progress_bar(label, d, sum(done.values()), progress)
    shown = not bar.disable
    rows, chunks_written, lost_msgs = write_chunks(_chunks(client, scene, job, params, starts, timeout), writer, state, job, params,
                                                   counts, bar)
    info = dict(label=label, chunk_size=job.chunk, n_chunks=-(-d // job.chunk), devices=devices, outputs=job.outputs,
                backend="local" if client is None else "dask", mode="trace" if figures is None else "figures",
                retried_lost=len(state.lost), **writer_info(writer, rows_per_group, rows_per_file))
    summary = SweepSummary(path=str(out), designs=d, counts=counts, rows_written=rows, chunks_written=chunks_written,
                           chunks_skipped=len(done), lost=lost_msgs, seconds=time.perf_counter() - t0, info=info)
    if shown:
        print(summary.line(), file=sys.stderr)
    return summary
