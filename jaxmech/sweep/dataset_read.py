"""Reading a sweep's Parquet dataset (``read_dataset``), in this layout or the first one
(``jaxmech-sweep-dataset/1``: a file per chunk, ``NAME[UNIT]`` column names, ``status[-]``
codes), and converting the first layout to this one (``convert_dataset``).  The layout is
described in ``jaxmech.sweep.dataset``.
"""

from __future__ import annotations

import dataclasses
import json
import os
from pathlib import Path

import numpy as np

from .dataset import (FORMAT, FORMAT_1, LOST_FILE, MANIFEST, PART_FILE, PART_FILE_1, ROWS_PER_FILE, ROWS_PER_GROUP,
                      Dataset, DatasetState, DatasetWriter, write_manifest)
from .kernel import ChunkData

__all__ = ["read_dataset", "convert_dataset"]


def read_manifest(root: Path) -> dict | None:
    """The manifest of the dataset in folder ``root`` (None: it has none)."""
    p = root / MANIFEST
    return json.loads(p.read_text(encoding="utf-8")) if p.exists() else None


def _files_1(root: Path) -> list[tuple[int, bool, Path]]:
    out = []
    for e in os.scandir(root):
        m = PART_FILE_1.match(e.name)
        if m:
            out.append((int(m.group(1)), bool(m.group(2)), Path(e.path)))
    return sorted(out)


def _parameter_units(scene_name: str, names) -> tuple:
    try:
        from ..scenes import get_scene

        scene = get_scene(scene_name)
        return tuple((k, scene.parameters.get(k, ("", ""))[0]) for k in names)
    except ValueError:
        return tuple((k, "") for k in names)


def _dataset_1(root: Path, manifest: dict | None) -> Dataset:
    first = _files_1(root)
    if manifest is None and not first:
        raise ValueError(f"{str(root)!r} holds no jaxmech sweep (no {MANIFEST}, no part files)")
    import pyarrow.parquet as pq

    names = pq.read_schema(first[0][2]).names if first else []
    if manifest is not None:
        figures, points, scene, params = manifest["mode"] == "figures", manifest["points"], manifest["scene"], manifest["parameters"]
    else:  # no manifest: the columns tell
        figures, scene = "point" not in names, ""
        params = [n for n in names if n not in ("design", "point", "error") and "[" not in n]
        points = 0 if figures else int(pq.read_table(first[0][2], columns=["point"]).column(0).to_numpy().max()) + 1
    return Dataset(path=str(root), figures=figures, points=points, scene=scene, parameter_units=_parameter_units(scene, params))


def _chunk_1(table, ds: Dataset) -> ChunkData:
    """A file of the first layout as the chunk that made it."""
    keys = [("design", "ascending")] + ([] if ds.figures else [("point", "ascending")])
    t = table.sort_by(keys)
    design = t.column("design").to_numpy()
    start, m = int(design[0]), 1 if ds.figures else ds.points
    n = len(design) // m
    params = {k: t.column(k).to_numpy()[::m] for k, _ in ds.parameter_units}
    skip = {"design", "point", "status[-]", "error", *params}

    def shaped(v):
        return v if ds.figures else v.reshape(n, m)
    cols = {k: shaped(t.column(k).to_numpy()) for k in t.column_names if k not in skip}
    status = shaped(t.column("status[-]").to_numpy().astype(np.int32))
    err = t.column("error").to_pylist()[::m] if "error" in t.column_names else [None] * n
    errors = {start + i: e for i, e in enumerate(err) if e is not None}
    return ChunkData(start=start, params=params, columns=cols, status=status, errors=errors)


def read_dataset(path, columns=None, *, sort: bool = True):
    """A sweep's dataset as one ``pyarrow.Table`` (``.to_pandas()``, ``polars.from_arrow``):
    plain column names, units in the field metadata, rows in design (and point) order.

    Reads this layout and the first one (``NAME[UNIT]`` names, a file per chunk), which it
    returns as if written today.  `columns`: the names to read (all by default).  Of an
    interrupted sweep it reads the finished files (and the lost chunks' failed rows), not
    the row groups still staged: rerun the sweep to finish it.
    """
    import pyarrow as pa
    import pyarrow.dataset as pads

    root = Path(path)
    if not root.is_dir():
        raise ValueError(f"{str(root)!r} is not a sweep dataset folder")
    manifest = read_manifest(root)
    if manifest is not None:
        first = manifest.get("format") == FORMAT_1
    else:  # no manifest: the file names tell
        first = bool(_files_1(root)) and not any(PART_FILE.match(e.name) for e in os.scandir(root))
    if first:
        import pyarrow.parquet as pq

        ds = _dataset_1(root, manifest)
        tables = [ds.table(_chunk_1(pq.read_table(f), ds))[0] for _, _, f in _files_1(root)]
        table = pa.concat_tables(tables)
        if columns is not None:
            table = table.select(list(columns))
    else:
        files = sorted(str(root / e.name) for e in os.scandir(root) if PART_FILE.match(e.name) or LOST_FILE.match(e.name))
        if not files:
            raise ValueError(f"{str(root)!r} holds no finished part file (an interrupted sweep: rerun it to finish)")
        import pyarrow.parquet as pq

        schema = pq.read_schema(files[0])
        table = pads.dataset(files, schema=schema, format="parquet").to_table(columns=columns)
    if sort and "design" in table.column_names:
        table = table.sort_by([("design", "ascending")] + ([("point", "ascending")] if "point" in table.column_names else []))
    return table


def convert_dataset(src, dst, *, rows_per_group: int = ROWS_PER_GROUP, rows_per_file: int = ROWS_PER_FILE) -> Path:
    """Rewrite a sweep of the first layout (``jaxmech-sweep-dataset/1``) in this one.

    `dst` (a new folder) gets the same rows, chunk by chunk, in files of about
    `rows_per_file` rows, and a manifest that lets ``sweep_dataset`` resume it with the
    sweep's arguments (an unfinished sweep: its missing and lost chunks are run then).
    `src` is left as it is.  Returns `dst` as a ``Path``.
    """
    import pyarrow.parquet as pq

    root, out = Path(src), Path(dst)
    manifest = read_manifest(root)
    if manifest is None or manifest.get("format") != FORMAT_1:
        raise ValueError(f"{str(root)!r} is not a sweep of the first layout ({FORMAT_1} in its {MANIFEST})")
    if out.exists():
        raise ValueError(f"convert_dataset: {str(out)!r} exists; give a new folder")
    ds = dataclasses.replace(_dataset_1(root, manifest), path=str(out))
    write_manifest(out, {**{k: v for k, v in manifest.items() if k != "chunk_size"}, "format": FORMAT}, manifest["chunk_size"])
    writer = DatasetWriter(ds, DatasetState(chunk=manifest["chunk_size"]), rows_per_group, rows_per_file)
    files = _files_1(root)
    done = {s for s, lost, _ in files if not lost}
    for s, lost, f in files:
        if lost and s in done:
            continue  # retried and written: the stale lost file of a killed run
        data = _chunk_1(pq.read_table(f), ds)
        if lost:
            writer.add_lost(data)
        else:
            writer.add(data)
    writer.close()
    return out
