"""A sweep streamed to a Parquet dataset: one file per finished chunk, a manifest of the
arguments, and what a rerun needs to skip the chunks already written.

Layout of ``DIR``::

    DIR/_manifest.json                  the sweep's arguments (a rerun must match them)
    DIR/part-000000000000.parquet       designs 0 .. chunk-1
    DIR/part-000000001024.parquet       designs 1024 .. 2047 (the number: the first design)
    DIR/part-000000002048.lost.parquet  a chunk whose run failed: its designs as failed
                                        rows; a rerun tries it again

Every file is written under a hidden temporary name and renamed when complete (atomic on
POSIX), so a sweep killed at any moment leaves only whole chunk files; readers
(``pyarrow.dataset``, pandas, polars, dask) skip names starting with ``.`` or ``_``.

Rows: figures mode, one per design (``design``, every parameter, the figures,
``status[-]``, ``failed_points[-]``, ``error``); trace mode, one per design and stroke
sample (``design``, ``point``, every parameter, every table column, ``status[-]``,
``error``).  ``status[-]`` holds ``jaxmech.Status`` codes (0 converged; the names are in
each file's metadata under ``jaxmech.status_codes``); ``error`` is null except for
designs never solved (rejected, or lost with their chunk).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
from pathlib import Path

import numpy as np

from ..status import Status
from .evaluate import design_status
from .kernel import ChunkData

__all__ = ["ChunkReport", "Dataset", "manifest_of", "open_dataset", "write_manifest", "written_counts"]

FORMAT = "jaxmech-sweep-dataset/1"
MANIFEST = "_manifest.json"
_PART = re.compile(r"^part-(\d{12})(\.lost)?\.parquet$")
_STATUS_CODES = json.dumps({int(s): s.name for s in Status})


@dataclasses.dataclass(frozen=True)
class ChunkReport:
    """What writing one chunk left: its designs, rows, design statuses and messages."""

    start: int
    designs: int
    rows: int
    counts: dict  # {status name: designs}
    errors: dict  # {design index: message}
    names: tuple  # result columns, in order
    lost: bool = False


def _counts(status: np.ndarray) -> dict:
    codes, n = np.unique(status, return_counts=True)
    return {Status(int(c)).name: int(k) for c, k in zip(codes, n)}


@dataclasses.dataclass(frozen=True)
class Dataset:
    """Where and how a sweep's chunks are written (picklable: Dask workers write too)."""

    path: str
    figures: bool
    points: int

    def file(self, start: int, lost: bool = False) -> Path:
        return Path(self.path) / f"part-{start:012d}{'.lost' if lost else ''}.parquet"

    def table(self, data: ChunkData):
        """The chunk's rows as a ``pyarrow.Table`` (see the module docstring)."""
        import pyarrow as pa

        n = data.n
        design = np.arange(data.start, data.start + n, dtype=np.int64)
        err = np.array([data.errors.get(int(i)) for i in design], dtype=object) if data.errors else None
        if self.figures:
            cols = {"design": design, **data.params, **{k: v for k, v in data.columns.items() if k != "failed_points[-]"},
                    "status[-]": data.status.astype(np.int32), "failed_points[-]": data.columns["failed_points[-]"]}
            dstatus = data.status
        else:
            m = data.status.shape[1]
            cols = {"design": np.repeat(design, m), "point": np.tile(np.arange(m, dtype=np.int32), n),
                    **{k: np.repeat(v, m) for k, v in data.params.items()},
                    **{k: v.reshape(-1) for k, v in data.columns.items()}, "status[-]": data.status.astype(np.int32).reshape(-1)}
            err = None if err is None else np.repeat(err, m)
            dstatus = design_status(data.status, np)
        rows = len(cols["design"])
        arrays = {k: pa.array(v) for k, v in cols.items()}
        arrays["error"] = pa.nulls(rows, pa.string()) if err is None else pa.array(err, pa.string())
        meta = {"jaxmech.status_codes": _STATUS_CODES, "jaxmech.design_status": json.dumps(_counts(dstatus))}
        return pa.table(arrays).replace_schema_metadata(meta), _counts(dstatus)

    def write(self, data: ChunkData, lost: bool = False) -> ChunkReport:
        """Write one chunk atomically (temporary name, then rename); a successful retry of
        a lost chunk replaces its ``.lost`` file."""
        import pyarrow.parquet as pq

        table, counts = self.table(data)
        final = self.file(data.start, lost)
        tmp = final.with_name(f".{final.name}.{os.getpid()}.tmp")
        pq.write_table(table, tmp)
        if not lost:
            # A kill between these two leaves the chunk missing (retried), never twice.
            self.file(data.start, True).unlink(missing_ok=True)
        os.replace(tmp, final)
        return ChunkReport(start=data.start, designs=data.n, rows=table.num_rows, counts=counts, errors=data.errors,
                           names=tuple(data.columns), lost=lost)


def manifest_of(scene, params: dict, *, figures, points: int, options, x64: bool) -> dict:
    """The arguments that make a sweep's rows: a rerun resumes only when they are equal."""
    digest = hashlib.sha256()
    for k, v in params.items():
        digest.update(k.encode())
        digest.update(memoryview(np.ascontiguousarray(v, np.float64)))
    fig = None if figures is None else {
        "columns": None if figures.columns is None else list(figures.columns),
        "reductions": list(figures.reductions),
        "functions": [f"{name}={getattr(fn, '__module__', '?')}.{getattr(fn, '__qualname__', repr(fn))}" for name, fn in figures.functions],
    }
    return {
        "format": FORMAT, "scene": scene.name, "mode": "trace" if figures is None else "figures", "figures": fig,
        "points": int(points), "options": repr(options), "float64": bool(x64),
        "designs": len(next(iter(params.values()))), "parameters": list(params), "parameters_sha256": digest.hexdigest(),
    }


def _write_json(path: Path, obj) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(obj, indent=1) + "\n", encoding="utf-8")
    os.replace(tmp, path)


def open_dataset(path, manifest: dict, chunk_size: int | None):
    """Prepare ``path`` for a sweep with these arguments.

    Returns ``(chunk, done, lost)``: the chunk size to use (the manifest's when resuming),
    ``{start: file}`` of the chunks already written and ``{start: file}`` of the lost
    chunks to retry.  Leftover temporary files of a killed run are removed.  The caller
    writes the manifest (``write_manifest``) once the chunk size is known.

    **Raises** ``ValueError`` when ``path`` is a file, holds files that are not a jaxmech
    sweep, or holds a sweep made with other arguments (naming them).
    """
    root = Path(path)
    if root.exists() and not root.is_dir():
        raise ValueError(f"sweep output {str(root)!r} is a file; give a folder name (DIR.parquet)")
    mpath = root / MANIFEST
    chunk = chunk_size
    if mpath.exists():
        old = json.loads(mpath.read_text(encoding="utf-8"))
        diff = [k for k in manifest if old.get(k) != manifest[k]]
        if diff:
            what = "; ".join("other design values" if k == "parameters_sha256" else
                             f"{k}: {_short(old.get(k))} there, {_short(manifest[k])} now" for k in diff)
            raise ValueError(
                f"{str(root)!r} holds a sweep made with other arguments ({what}); rerun with the same "
                f"arguments to resume it, or give another output folder"
            )
        if chunk_size is not None and int(chunk_size) != old["chunk_size"]:
            raise ValueError(
                f"{str(root)!r} was written in chunks of {old['chunk_size']} designs; resume it with "
                f"chunk size {old['chunk_size']} (or none), or give another output folder"
            )
        chunk = old["chunk_size"]
    elif root.exists() and any(_PART.match(e.name) for e in os.scandir(root)):
        raise ValueError(f"{str(root)!r} holds chunk files but no {MANIFEST}: not a resumable jaxmech sweep; give another output folder")
    done, lost = {}, {}
    if root.exists():
        for e in os.scandir(root):
            if e.name.startswith(".") and e.name.endswith(".tmp"):
                os.unlink(e.path)  # a chunk cut short by a kill: written again
                continue
            m = _PART.match(e.name)
            if m:
                (lost if m.group(2) else done)[int(m.group(1))] = Path(e.path)
    for s in [s for s in lost if s in done]:  # a retry that was renamed but not yet cleaned up
        lost.pop(s).unlink(missing_ok=True)
    return chunk, done, lost


def write_manifest(path, manifest: dict, chunk: int) -> None:
    root = Path(path)
    root.mkdir(parents=True, exist_ok=True)
    if not (root / MANIFEST).exists():
        _write_json(root / MANIFEST, {**manifest, "chunk_size": int(chunk)})


def written_counts(file: Path) -> dict:
    """``{status name: designs}`` of a chunk file already written (from its metadata)."""
    import pyarrow.parquet as pq

    meta = pq.read_schema(file).metadata or {}
    return json.loads(meta.get(b"jaxmech.design_status", b"{}"))


def _short(v) -> str:
    s = json.dumps(v)
    return s if len(s) <= 40 else s[:37] + "..."
