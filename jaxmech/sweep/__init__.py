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

- ``sweep_scene``: every table column of every design, gathered in memory (``SweepResult``).
- ``sweep_dataset``: streamed to a Parquet dataset, one file per chunk, resumable; in
  trace mode (every column at every sample) or figures mode (``Figures``: per-design
  reductions over the stroke computed in the kernel, a few numbers per design).

Modules: ``evaluate`` (one design, traceable; figures), ``designs`` (grids, random
designs, value checks), ``kernel`` (compiled chunk kernels), ``result`` (``SweepResult``),
``dataset`` (the Parquet layout, resuming), ``run`` (the sweeps).
"""

from .designs import grid as grid
from .designs import random_designs as random_designs
from .evaluate import Figures as Figures
from .evaluate import design_columns as design_columns
from .evaluate import design_motion as design_motion
from .evaluate import design_status as design_status
from .result import SweepResult as SweepResult
from .run import SweepSummary as SweepSummary
from .run import sweep_dataset as sweep_dataset
from .run import sweep_scene as sweep_scene

__all__ = [
    "Figures",
    "SweepResult",
    "SweepSummary",
    "design_columns",
    "design_motion",
    "design_status",
    "grid",
    "random_designs",
    "sweep_dataset",
    "sweep_scene",
]
