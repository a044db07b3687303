"""A sweep streamed to a Parquet dataset: files of about a million rows, plain column
names with their units in the Arrow field metadata, and what a rerun needs to resume.

Layout of ``DIR`` (format ``jaxmech-sweep-dataset/2``)::

    DIR/_manifest.json            the sweep's arguments (a rerun must match them)
    DIR/part-000000.parquet       about ``rows_per_file`` rows (default 10^6) in row groups
    DIR/part-000001.parquet       of about ``rows_per_group`` rows (default 10^5)
    DIR/lost-000000002048.parquet a chunk whose run failed (the number: its first design):
                                  its designs as failed rows; a rerun tries it again
    DIR/.stage-000007.rows        one finished row group waiting for its file (hidden)

Read it with any Parquet reader, no jaxmech needed::

    pandas.read_parquet("DIR")                        # pyarrow.parquet.read_table("DIR")
    polars.read_parquet("DIR/*.parquet")              # a glob: the folder holds _manifest.json
    duckdb.sql("SELECT * FROM 'DIR/*.parquet'")

or with ``read_dataset`` (which also reads the first layout, below).  Rows are in design
order within a row group; a local run writes them in design order, a Dask run in the order
its chunks finish (sort by ``design`` when order matters).

**Columns.**  Figures mode, one row per design: ``design``, every parameter, the figures
(``theta4_max``, ``theta4_max_at``, ... and your figure functions), ``status``,
``status_code``, ``failed_points``, ``error``.  Trace mode, one row per design and stroke
sample: ``design``, ``point``, every parameter, every table column (``t``, ``theta2``,
``theta4_dot``, ...), ``status``, ``status_code``, ``error``.  A column is jaxmech's
``NAME[UNIT]`` without its unit: the unit is in the Arrow field metadata (``unit``, as
``"rad"``, ``"m"``, ``"rad/s"``; ``"-"`` for a pure number) next to jaxmech's own name
(``jaxmech.column``), and the schema metadata gathers them (``jaxmech.units``,
``jaxmech.parameter_units``: JSON) with ``jaxmech.scene``, ``jaxmech.version``,
``jaxmech.mode``, ``jaxmech.points`` and ``jaxmech.format``.  ``status`` is the
``jaxmech.Status`` name, dictionary-encoded over every name in code order (pandas reads it
as a ``Categorical`` whose ``.cat.codes`` are the codes; polars as ``Categorical``, duckdb
as ``VARCHAR``); ``status_code`` is the same as an ``int32`` (0 converged).  A design's
status in figures mode is its first failing sample's.  ``error`` is null except for
designs never solved (rejected, or lost with their chunk).  CSV output keeps the
``NAME[UNIT]`` headers (``SweepResult.to_csv``).

**Resuming.**  Chunks of designs are computed one by one and gathered in memory until they
make a row group; the row group is written to its own hidden file (``.stage-*.rows``), and
once the staged row groups reach ``rows_per_file`` rows they are copied into one
``part-*.parquet`` file, one row group each.  Every file is written under a hidden
temporary name and renamed when complete (atomic on POSIX), and each one's footer lists
the chunks it holds (``jaxmech.chunks``: ``[[first design, designs], ...]``).  A rerun
reads those footers: the chunks in part files and in staged row groups are skipped (the
staged ones go into its files), so a sweep killed at any moment loses at most the chunks
of one row group in memory (a Ctrl-C stages them first, losing none), never repeats a
design, and a file is never half there.  Readers skip the hidden and ``_`` names.

**The first layout** (``jaxmech-sweep-dataset/1``, jaxmech before this format: one
``part-<first design>.parquet`` per chunk, ``NAME[UNIT]`` column names, ``status[-]``
codes) is read by ``read_dataset`` as if written today, and ``convert_dataset(old, new)``
rewrites it in this layout, resumable with the sweep's arguments.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import re
from pathlib import Path

import numpy as np

from ..solver.status import Status, status_counts
from .evaluate import design_status
from .kernel import ChunkData

__all__ = [
    "FORMAT", "ChunkReport", "Dataset", "DatasetState", "DatasetWriter", "convert_dataset", "manifest_of",
    "prepare_dataset", "read_dataset", "split_unit", "write_manifest",
]

FORMAT = "jaxmech-sweep-dataset/2"
FORMAT_1 = "jaxmech-sweep-dataset/1"
MANIFEST = "_manifest.json"
ROWS_PER_GROUP = 100_000
ROWS_PER_FILE = 1_000_000
STATUS_NAMES = tuple(s.name for s in Status)  # index == code: the dictionary of `status`
assert [int(s) for s in Status] == list(range(len(STATUS_NAMES)))
RESERVED = ("design", "point", "status", "status_code", "failed_points", "error")

PART_FILE = re.compile(r"^part-(\d{6})\.parquet$")
LOST_FILE = re.compile(r"^lost-(\d{12})\.parquet$")
_STAGE = re.compile(r"^\.stage-(\d{6})\.rows$")
PART_FILE_1 = re.compile(r"^part-(\d{12})(\.lost)?\.parquet$")
_UNIT = re.compile(r"^(.+)\[([^\[\]]*)\]$")
_STATUS_CODES = json.dumps({int(s): s.name for s in Status})


def split_unit(name: str) -> tuple[str, str | None]:
    """``"theta4_max[rad]"`` -> ``("theta4_max", "rad")``; a name without ``[UNIT]`` has none."""
    m = _UNIT.match(name)
    return (m.group(1), m.group(2)) if m else (name, None)


@dataclasses.dataclass(frozen=True)
class ChunkReport:
    """What writing one chunk left: its designs, rows, design statuses and messages."""

    start: int
    designs: int
    rows: int
    counts: dict  # {status name: designs}
    errors: dict  # {design index: message}
    names: tuple  # result columns (jaxmech names), in order
    lost: bool = False


def _counts(status: np.ndarray) -> dict:
    return status_counts(status)


def _add_counts(into: dict, more: dict) -> dict:
    for k, v in more.items():
        into[k] = into.get(k, 0) + int(v)
    return into


@dataclasses.dataclass(frozen=True)
class Dataset:
    """What a sweep's rows look like: its mode, scene and parameter units (the table of a
    chunk, ``table``); ``DatasetWriter`` puts the tables in files."""

    path: str
    figures: bool
    points: int
    scene: str = ""
    parameter_units: tuple = ()  # ((name, SI unit or ""), ...)

    def file(self, name: str) -> Path:
        return Path(self.path) / name

    def table(self, data: ChunkData):
        """The chunk's rows as a ``pyarrow.Table`` and its ``{status name: designs}``."""
        import pyarrow as pa

        n = data.n
        design = np.arange(data.start, data.start + n, dtype=np.int64)
        err = np.array([data.errors.get(int(i)) for i in design], dtype=object) if data.errors else None
        m = 1 if self.figures else data.status.shape[1]

        def rows(v):  # a value per design -> a value per row
            return v if self.figures else np.repeat(v, m)
        status = data.status.reshape(-1)
        dstatus = data.status if self.figures else design_status(data.status, np)
        punits = dict(self.parameter_units)
        cols = [("design", rows(design), None, "design")]  # (name, values, unit, jaxmech name)
        if not self.figures:
            cols.append(("point", np.tile(np.arange(m, dtype=np.int32), n), None, "point"))
        cols += [(k, rows(np.asarray(v)), punits.get(k) or None, k) for k, v in data.params.items()]
        for k, v in data.columns.items():
            if k != "failed_points[-]":
                name, unit = split_unit(k)
                cols.append((name, v if self.figures else v.reshape(-1), unit, k))
        code = np.asarray(status, np.int32)
        cols.append(("status", pa.DictionaryArray.from_arrays(pa.array(code.astype(np.int8)), pa.array(STATUS_NAMES)), None, "status"))
        cols.append(("status_code", code, None, "status[-]"))
        if self.figures:
            cols.append(("failed_points", np.asarray(data.columns["failed_points[-]"], np.int32), "-", "failed_points[-]"))
        err = pa.nulls(n * m, pa.string()) if err is None else pa.array(rows(err), pa.string())
        cols.append(("error", err, None, "error"))
        names = [c[0] for c in cols]
        clash = sorted({x for x in names if names.count(x) > 1})
        if clash:
            raise ValueError(f"sweep dataset: column name(s) {clash} occur twice once the units are dropped "
                             f"({[c[3] for c in cols if c[0] in clash]}); rename a figure or a parameter "
                             f"(the names {', '.join(RESERVED)} are the dataset's own)")
        fields, arrays = [], []
        for name, values, unit, jname in cols:
            arr = values if isinstance(values, (pa.Array, pa.ChunkedArray)) else pa.array(values)
            meta = {"jaxmech.column": jname}
            if unit is not None:
                meta["unit"] = unit
            fields.append(pa.field(name, arr.type, metadata=meta))
            arrays.append(arr)
        units = {c[0]: c[2] for c in cols if c[2] is not None}
        result = [k for k in data.columns if k != "failed_points[-]"] + (["failed_points[-]"] if self.figures else [])
        schema = pa.schema(fields, metadata=self.schema_metadata(units, result))
        return pa.Table.from_arrays(arrays, schema=schema), _counts(dstatus)

    def schema_metadata(self, units: dict, result_columns: list) -> dict:
        from .. import __version__

        return {
            "jaxmech.format": FORMAT, "jaxmech.scene": self.scene, "jaxmech.version": __version__,
            "jaxmech.mode": "figures" if self.figures else "trace", "jaxmech.points": str(self.points),
            "jaxmech.parameter_units": json.dumps(dict(self.parameter_units)), "jaxmech.units": json.dumps(units),
            "jaxmech.status_codes": _STATUS_CODES, "jaxmech.result_columns": json.dumps(result_columns),
        }


def _file_meta(chunks, counts) -> dict:
    chunks = sorted((int(s), int(n)) for s, n in chunks)
    return {"jaxmech.chunks": json.dumps(chunks), "jaxmech.design_status": json.dumps(counts),
            "jaxmech.designs": str(sum(n for _, n in chunks))}


def _read_file_meta(path: Path):
    """``(chunks, counts, rows)`` from a written file's footer."""
    import pyarrow.parquet as pq

    md = pq.read_metadata(path)
    kv = md.metadata or {}
    if b"jaxmech.chunks" not in kv:
        raise ValueError(f"{str(path)!r} is not a file of a jaxmech sweep (no jaxmech.chunks in its footer); move it away")
    chunks = [tuple(c) for c in json.loads(kv[b"jaxmech.chunks"])]
    return chunks, json.loads(kv.get(b"jaxmech.design_status", b"{}")), md.num_rows


# Dictionary encoding only where values repeat (a float column of 10^5 distinct values
# written with a dictionary is 5x slower to write and a fifth larger); zstd for the files
# that stay, nothing for the staged row groups (written once, read once).
_DICTIONARY = ["status", "error", "point"]
_FINAL = {"use_dictionary": _DICTIONARY, "compression": "zstd"}
_STAGED = {"use_dictionary": _DICTIONARY, "compression": "none"}


def _write_parquet(final: Path, schema, tables, kv: dict, options=_FINAL) -> None:
    """Tables (an iterable, read one at a time) as one row group each, under a hidden
    temporary name renamed to `final` once the footer is written."""
    import pyarrow.parquet as pq

    tmp = final.with_name(f".{final.name}.{os.getpid()}.tmp")
    try:
        with pq.ParquetWriter(tmp, schema, **options) as w:
            for t in tables:
                w.write_table(t, row_group_size=max(1, t.num_rows))
            w.add_key_value_metadata(kv)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, final)


@dataclasses.dataclass
class DatasetState:
    """What a folder already holds (``prepare_dataset``)."""

    chunk: int | None = None  # the chunk size (the manifest's when resuming)
    done: dict = dataclasses.field(default_factory=dict)  # {first design: designs} in part files and staged row groups
    counts: dict = dataclasses.field(default_factory=dict)  # {status name: designs} of those
    staged: list = dataclasses.field(default_factory=list)  # [(path, chunks, rows, counts)]
    lost: dict = dataclasses.field(default_factory=dict)  # {first design: path} of lost chunks to retry
    parts: list = dataclasses.field(default_factory=list)  # part files
    next_stage: int = 0
    next_part: int = 0

    @property
    def example(self) -> Path | None:
        """A written file (its schema lists the result columns)."""
        return next(iter([*self.parts, *(s[0] for s in self.staged)]), None)


class DatasetWriter:
    """Writes a sweep's chunks (in the process that gathers them): chunks in memory until a
    row group is full, the row group staged in its own hidden file, staged row groups
    copied into a part file once they make ``rows_per_file`` rows (the module docstring)."""

    def __init__(self, dataset: Dataset, state: DatasetState, rows_per_group: int = ROWS_PER_GROUP,
                 rows_per_file: int = ROWS_PER_FILE):
        self.dataset, self.root = dataset, Path(dataset.path)
        self.root.mkdir(parents=True, exist_ok=True)
        self.rows_per_group, self.rows_per_file = int(rows_per_group), int(rows_per_file)
        self.pending: list = []  # (table, start, designs, counts)
        self.pending_rows = 0
        self.staged = list(state.staged)
        self.lost_files = dict(state.lost)
        self.next_stage, self.next_part = state.next_stage, state.next_part
        self.parts = list(state.parts)
        self.schema = None

    def add(self, data: ChunkData) -> ChunkReport:
        """A finished chunk: kept in memory, written with its row group."""
        table, counts = self.dataset.table(data)
        return self.add_table(table, data.start, data.n, counts, data.errors, tuple(data.columns))

    def add_table(self, table, start: int, designs: int, counts: dict, errors=None, names=()) -> ChunkReport:
        if self.schema is None:
            self.schema = table.schema
        elif not table.schema.equals(self.schema, check_metadata=True):
            table = table.cast(self.schema)
        self.pending.append((table, int(start), int(designs), counts))
        self.pending_rows += table.num_rows
        rep = ChunkReport(start=int(start), designs=int(designs), rows=table.num_rows, counts=counts, errors=errors or {}, names=names)
        if self.pending_rows >= self.rows_per_group:
            self.stage()
        if sum(s[2] for s in self.staged) >= self.rows_per_file:
            self.merge()
        return rep

    def add_lost(self, data: ChunkData) -> ChunkReport:
        """A chunk whose run failed: its failed rows in their own file (replaced by a retry)."""
        table, counts = self.dataset.table(data)
        final = self.dataset.file(f"lost-{data.start:012d}.parquet")
        _write_parquet(final, table.schema, [table], _file_meta([(data.start, data.n)], counts))
        self.lost_files[data.start] = final
        return ChunkReport(start=data.start, designs=data.n, rows=table.num_rows, counts=counts, errors=data.errors,
                           names=tuple(data.columns), lost=True)

    def stage(self) -> None:
        """The chunks in memory as one row group in a hidden file; the lost files of the
        chunks among them (retried) are removed once it is there."""
        import pyarrow as pa

        if not self.pending:
            return
        table = pa.concat_tables([p[0] for p in self.pending])
        chunks = [(p[1], p[2]) for p in self.pending]
        counts: dict = {}
        for p in self.pending:
            _add_counts(counts, p[3])
        path = self.dataset.file(f".stage-{self.next_stage:06d}.rows")
        _write_parquet(path, table.schema, [table], _file_meta(chunks, counts), _STAGED)
        self.next_stage += 1
        self.staged.append((path, chunks, table.num_rows, counts))
        self.pending, self.pending_rows = [], 0
        for s, _ in chunks:  # a kill before this leaves the chunk twice: the rerun drops the lost file
            lost = self.lost_files.pop(s, None)
            if lost is not None:
                lost.unlink(missing_ok=True)

    def merge(self) -> None:
        """The staged row groups, in design order, into the next part file; then they go."""
        import pyarrow.parquet as pq

        if not self.staged:
            return
        staged = sorted(self.staged, key=lambda s: min(c[0] for c in s[1]))
        schema = self.schema if self.schema is not None else pq.read_schema(staged[0][0])
        counts: dict = {}
        for s in staged:
            _add_counts(counts, s[3])
        final = self.dataset.file(f"part-{self.next_part:06d}.parquet")
        _write_parquet(final, schema, (pq.read_table(s[0], schema=schema) for s in staged),
                       _file_meta([c for s in staged for c in s[1]], counts))
        self.next_part += 1
        self.parts.append(final)
        for s in staged:  # a kill before this leaves them: the rerun finds their chunks in `final`
            s[0].unlink(missing_ok=True)
        self.staged = []

    def close(self) -> None:
        """Everything in memory and staged into part files."""
        self.stage()
        self.merge()

    def abort(self) -> None:
        """Interrupted (Ctrl-C, an error): stage the chunks in memory, so that a rerun skips
        them; any error doing so is dropped (the first one is the one raised)."""
        try:
            self.stage()
        except Exception:  # noqa: BLE001
            pass


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


def _convert_hint(root: Path) -> str:
    return (f"{str(root)!r} holds a sweep in the first dataset layout ({FORMAT_1}: a file per chunk, column names "
            f"with [unit]); convert it with jaxmech.sweep.convert_dataset({str(root)!r}, NEW_FOLDER) and rerun "
            f"with out=NEW_FOLDER to resume it (read it as it is with jaxmech.sweep.read_dataset)")


def prepare_dataset(path, manifest: dict, chunk_size: int | None) -> DatasetState:
    """Prepare ``path`` for a sweep with these arguments: what it already holds.

    Leftover temporary files of a killed run are removed, and so are staged row groups
    already copied into a part file and lost chunks already written again (a kill between
    two renames).  The caller writes the manifest (``write_manifest``) once the chunk size
    is known.

    **Raises** ``ValueError`` when ``path`` is a file, holds files that are not a jaxmech
    sweep, holds a sweep made with other arguments (naming them), or a sweep in the first
    layout (naming ``convert_dataset``).
    """
    root = Path(path)
    if root.exists() and not root.is_dir():
        raise ValueError(f"sweep output {str(root)!r} is a file; give a folder name (DIR.parquet)")
    mpath = root / MANIFEST
    state = DatasetState(chunk=chunk_size)
    if mpath.exists():
        old = json.loads(mpath.read_text(encoding="utf-8"))
        if old.get("format") == FORMAT_1:
            raise ValueError(_convert_hint(root))
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
        state.chunk = old["chunk_size"]
    elif root.exists() and any(PART_FILE.match(e.name) or PART_FILE_1.match(e.name) or LOST_FILE.match(e.name) for e in os.scandir(root)):
        raise ValueError(f"{str(root)!r} holds sweep files but no {MANIFEST}: not a resumable jaxmech sweep; give another output folder")
    if not root.exists():
        return state
    staged, parts = [], []
    for e in sorted(os.scandir(root), key=lambda e: e.name):
        if e.name.startswith(".") and e.name.endswith(".tmp"):
            os.unlink(e.path)  # a file cut short by a kill: its chunks are written again
        elif m := PART_FILE.match(e.name):
            parts.append(Path(e.path))
            state.next_part = max(state.next_part, int(m.group(1)) + 1)
        elif m := _STAGE.match(e.name):
            staged.append(Path(e.path))
            state.next_stage = max(state.next_stage, int(m.group(1)) + 1)
        elif m := LOST_FILE.match(e.name):
            state.lost[int(m.group(1))] = Path(e.path)
    where: dict = {}
    for f in parts:
        chunks, counts, _ = _read_file_meta(f)
        for s, n in chunks:
            if s in where:
                raise ValueError(f"{str(root)!r}: designs {s}.. are in both {where[s].name} and {f.name}; "
                                 f"was it written by two sweeps at once? Give another output folder")
            where[s] = f
            state.done[s] = n
        _add_counts(state.counts, counts)
        state.parts.append(f)
    for f in staged:
        chunks, counts, rows = _read_file_meta(f)
        if all(s in where for s, _ in chunks):
            # copied into a part file by a run killed before it removed this (or staged twice
            # by a run interrupted inside its own staging): the same rows, kept once
            f.unlink()
            continue
        for s, n in chunks:
            if s in where:
                raise ValueError(f"{str(root)!r}: designs {s}.. are in both {where[s].name} and {f.name}; give another output folder")
            where[s] = f
            state.done[s] = n
        _add_counts(state.counts, counts)
        state.staged.append((f, chunks, rows, counts))
    for s in [s for s in state.lost if s in state.done]:  # retried, then killed before the lost file went
        state.lost.pop(s).unlink(missing_ok=True)
    return state


def write_manifest(path, manifest: dict, chunk: int) -> None:
    root = Path(path)
    root.mkdir(parents=True, exist_ok=True)
    if not (root / MANIFEST).exists():
        _write_json(root / MANIFEST, {**manifest, "chunk_size": int(chunk)})


def _short(v) -> str:
    s = json.dumps(v)
    return s if len(s) <= 40 else s[:37] + "..."


# reading lives in dataset_read (which imports this module's names): re-exported here, where
# the first layout's users found them
from .dataset_read import convert_dataset, read_dataset  # noqa: E402
