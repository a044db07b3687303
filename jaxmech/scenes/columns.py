"""The columns of a scene's table, one function for every path: ``SceneResult.table``
(``run_scene``), the sweep kernels and ``jaxmech.design`` all name and order them here.

Column names are ``NAME[UNIT]`` (SI): time, the input with its rates, every coordinate
with ``_dot``/``_ddot``, the scene's outputs; ``status[-]`` is added by the callers.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING

import jax.numpy as jnp

from ..status import Status

if TYPE_CHECKING:  # a Scene is only read here (its mechanism, units)
    from ..kinematics import Motion
    from .base import Scene

__all__ = ["table_columns", "is_drive_column", "mask_failed"]


def table_columns(scene: Scene, mo: Motion, outputs: Mapping | None, xp=jnp) -> dict:
    """Columns ``NAME[UNIT]`` of ``SceneResult.table`` (without status), unmasked; `xp` is
    ``jax.numpy`` (traced) or ``numpy`` (outputs evaluated design by design)."""
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


def is_drive_column(scene: Scene, name: str) -> bool:
    """Whether a column is defined at failed samples too (time and the input's drive)."""
    return name == "t[s]" or name.split("[")[0] in {
        f"{scene.mechanism.inputs[0]}{s}" for s in ("", "_dot", "_ddot")
    }


def mask_failed(scene: Scene, cols: dict, status, xp=jnp) -> dict:
    """``cols`` with NaN at the samples that did not converge (drive columns kept)."""
    ok = status == Status.CONVERGED
    return {k: v if is_drive_column(scene, k) else xp.where(ok, v, xp.nan) for k, v in cols.items()}
