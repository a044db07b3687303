"""A sweep's results in memory: named arrays, with CSV and NPZ round trips."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..solver.status import Status, status_counts

__all__ = ["SweepResult"]


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
