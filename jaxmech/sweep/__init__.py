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
- ``sweep_dataset``: streamed to a Parquet dataset (files of about 10^6 rows, row groups of
  about 10^5, plain column names with their units in the Arrow metadata), resumable; in
  trace mode (every column at every sample) or figures mode (``Figures``: per-design
  reductions over the stroke computed in the kernel, a few numbers per design).
- ``read_dataset``: a dataset (or an older one, named as the new) as a table;
  ``convert_dataset``: an older dataset rewritten in the current layout.

Modules: ``evaluate`` (figures; one design's columns come from ``scenes.columns``),
``designs`` (grids, random designs, value checks), ``kernel`` (compiled chunk kernels), ``result`` (``SweepResult``),
``dataset`` (the Parquet layout, resuming), ``run`` (the sweeps).
"""

from .dataset import convert_dataset as convert_dataset
from .dataset import read_dataset as read_dataset
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
    "convert_dataset",
    "read_dataset",
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
