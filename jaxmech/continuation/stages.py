"""The stages of a stroke's walk over its blocks, each a function of named state.

A stroke is cut into blocks of ``k`` points (``continuation``); one ``lax.scan`` step
(``walk_block``) solves one block for every design, in straight-line code:

1. ``block_guesses``: each point's guess from the anchor (``StrokeCarry``) by the guarded
   predictor (``point.predict``);
2. ``checked_block``: checked Newton steps per point (``point.checked_step``: up to
   ``CHECKED_STEPS``, ``FRESH_STEPS`` in the block that starts the walk);
3. ``block_derivatives``: every point's implicit derivatives (or the last point's);
4. ``next_anchor``: the block's last point becomes the next anchor if it converged; a
   failed one never does (gap handling: the last trusted pose is kept, its derivatives
   dropped).

The points this walk does not solve are ``repair``'s.  Shapes: ``D`` designs, ``k``
points per block, ``m`` coordinates, ``dof`` inputs.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp

from ..solver.implicit import input_derivatives
from ..solver.linalg import where
from ..mechanism.mechanism import Mechanism
from ..solver.options import SolverOptions
from ..solver.solution import Solution
from ..solver.status import Status
from .point import CHECKED_STEPS, FRESH_STEPS, checked_step, predict

__all__ = [
    "StrokeSetup", "StrokeCarry", "PointResults", "BlockInput", "Derivatives",
    "block_guesses", "checked_block", "point_derivatives", "block_derivatives", "next_anchor", "walk_block",
]


@dataclasses.dataclass(frozen=True)
class StrokeSetup:
    """What every stage of one stroke program reads (closed over by the scan step).

    - `mech`, `options`, `derivs` (every point's derivatives wanted), `shared` (one stroke
      ``(N, dof)`` for every design, not ``(D, N, dof)``): static.
    - `p`: the designs' parameters, leaves ``(D,)``, finite (non-finite ones replaced).
    - `b0`: requested branch signs ``(D,)`` or ``(D, n_branches)``.
    - `scales`: coordinate scales ``(D, m)`` (``newton.coord_scales``).
    """

    mech: Mechanism
    options: SolverOptions
    derivs: bool
    shared: bool
    p: dict
    b0: jax.Array
    scales: jax.Array

    @property
    def ax(self):
        """The design axis of a block's inputs: None for a shared stroke."""
        return None if self.shared else 0


class StrokeCarry(NamedTuple):
    """The scan's state between blocks: the anchor (`q_anchor (D, m)`, its ``dq/du``
    `d1 (D, m, dof)` and ``d2q/du2`` `d2 (D, m, dof, dof)`, zero after a gap, and its input
    `u_anchor (D, dof)`), and the blocks since the anchor's (`lost (D,)`, int32: 0 where the
    last block ended converged)."""

    q_anchor: jax.Array
    d1: jax.Array
    d2: jax.Array
    u_anchor: jax.Array
    lost: jax.Array


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class PointResults(Solution):
    """Per point of a block (or a stroke), ``(D, k, ...)``: the root record (``Solution``'s
    fields: the root `q`, the last iterate where not converged, `status`, Newton `steps`,
    scaled `residual`, `cond`, `branch` value; `flipped` is zero until ``attach`` reads the
    branch flips) and, with ``derivs``, ``dq/du`` `d1` and ``d2q/du2`` `d2` (None without)."""

    d1: jax.Array | None = None
    d2: jax.Array | None = None

    def _replace(self, **fields) -> PointResults:
        return dataclasses.replace(self, **fields)


class Derivatives(NamedTuple):
    """``dq/du`` `d1` and ``d2q/du2`` `d2` at every point of a block (None when not wanted)
    and at its last point (`end_d1`, `end_d2`: the next anchor's)."""

    d1: jax.Array | None
    d2: jax.Array | None
    end_d1: jax.Array
    end_d2: jax.Array


class BlockInput(NamedTuple):
    """One scan step's inputs: the block's inputs `u` (``([D,] k, dof)``) and whether it
    starts the walk (`fresh`: its anchor has no series, so its checked steps may take
    ``FRESH_STEPS``)."""

    u: jax.Array
    fresh: jax.Array


#: Blocks after a failed block end whose points get ``FRESH_STEPS`` (``walk_block``).
RETRY_BLOCKS = 2


# --------------------------------------------------------------------------- stages
def block_guesses(setup: StrokeSetup, carry: StrokeCarry, u_blk):
    """Each design's block of guesses ``(D, k, m)`` from its anchor by the guarded predictor
    (the series judged once per block, over its farthest point)."""
    max_step = setup.options.max_step
    one = lambda q_a, d1, d2, u_a, s, u_d: predict(q_a, d1, d2, u_d - u_a, s, max_step)  # noqa: E731
    return jax.vmap(one, (0, 0, 0, 0, 0, setup.ax))(carry.q_anchor, carry.d1, carry.d2, carry.u_anchor, setup.scales, u_blk)


def checked_block(setup: StrokeSetup, u_blk, guesses, fresh=False):
    """``point.checked_step`` for every point: a ``CheckedStep`` of ``(D, k, ...)``:
    up to ``CHECKED_STEPS`` Newton steps a point, or ``FRESH_STEPS`` where the guess has no
    series (``fresh``: the block that starts the walk, or per design ``(D,)``; may be
    traced).  Mapped over designs (outer) and the block's points (inner): what depends on
    the parameters alone is computed once per design (8% of the steady-state stroke,
    measured)."""
    most = jnp.broadcast_to(jnp.where(fresh, FRESH_STEPS, CHECKED_STEPS), guesses.shape[:1])
    step = lambda u, p_, b_, most_, g_: checked_step(setup.mech, setup.options, u, p_, g_, b_, most_)  # noqa: E731
    inner = lambda u_d, p_, b_, most_, g_d: jax.vmap(lambda u_, g_: step(u_, p_, b_, most_, g_))(u_d, g_d)  # noqa: E731
    return jax.vmap(inner, (setup.ax, 0, 0, 0, 0))(u_blk, setup.p, setup.b0, most, guesses)


# A nested jit: programs of a mechanism with the same shapes share its trace.
@functools.partial(jax.jit, static_argnums=(0, 1))
def point_derivatives(mech: Mechanism, shared: bool, q, u, p, ok):
    """``implicit.input_derivatives`` at ``q (D, k, m)``, ``u ([D,] k, dof)``: ``(d1, d2)``
    of ``(D, k, m, dof[, dof])``, zero where not ``ok``."""
    one = lambda q_, u_, p1, ok_: input_derivatives(mech, q_, u_, p1, ok_)  # noqa: E731
    return jax.vmap(jax.vmap(one, (0, 0, None, 0)), (0, None if shared else 0, 0, 0))(q, u, p, ok)


def block_derivatives(setup: StrokeSetup, q_eval, u_blk, good) -> Derivatives:
    """Every point's derivatives (None without ``derivs``) and the last point's (the next
    anchor's), at ``q_eval (D, k, m)`` where ``good`` (zero elsewhere)."""
    mech, shared = setup.mech, setup.shared
    if setup.derivs:  # every point's dq/du and d2q/du2 (the last one's also serve the next anchor)
        d1, d2 = point_derivatives(mech, shared, where(good[..., None], q_eval, 0.0), u_blk, setup.p, good)
        return Derivatives(d1, d2, d1[:, -1], d2[:, -1])
    e1, e2 = point_derivatives(mech, shared, where(good[:, -1:, None], q_eval[:, -1:], 0.0), u_blk[..., -1:, :], setup.p, good[:, -1:])
    return Derivatives(None, None, e1[:, 0], e2[:, 0])


def next_anchor(carry: StrokeCarry, points: PointResults, ders: Derivatives, u_blk) -> StrokeCarry:
    """The anchor for the next block.  A failed block end is never an anchor: the last
    trusted pose is kept, and its derivatives dropped (``ders.end_*`` are zero where the
    point failed), so the next block restarts from that pose instead of a series
    extrapolated across the gap."""
    last_ok = points.status[:, -1] == Status.CONVERGED
    q_next = where(last_ok[:, None], points.q[:, -1], carry.q_anchor)
    u_next = where(last_ok[:, None], u_blk[..., -1, :], carry.u_anchor)
    return StrokeCarry(q_next, ders.end_d1, ders.end_d2, u_next, where(last_ok, 0, carry.lost + 1).astype(carry.lost.dtype))


def walk_block(setup: StrokeSetup, carry: StrokeCarry, xs: BlockInput):
    """One block for every design: guesses, checked steps, the derivatives, the next anchor.
    Returns ``(StrokeCarry, PointResults)``; a point the checked steps do not bring home is
    ``MAX_STEPS`` here (``repair`` solves it again)."""
    u_blk = xs.u
    g = block_guesses(setup, carry, u_blk)
    # the first blocks after a failed block end predict from the last trusted pose without
    # its series: their guesses get the fresh start's steps, so that the walk closes the
    # points after one it missed (a four-bar near its toggle: 3 steps from a prediction
    # 0.02 rad off were one too few, and every later point failed with it); deeper in a gap
    # the plain steps fail as fast as before
    retry = (carry.lost >= 1) & (carry.lost <= RETRY_BLOCKS)
    chk = checked_block(setup, u_blk, g, xs.fresh | retry)
    status = where(chk.ok, Status.CONVERGED, Status.MAX_STEPS).astype(jnp.int32)
    points = PointResults(q=chk.q, status=status, steps=chk.steps, residual=chk.residual, cond=chk.cond, branch=chk.branch,
                          flipped=jnp.zeros_like(status))
    # at the reported root itself, not one Newton step before it
    ders = block_derivatives(setup, points.q, u_blk, points.status == Status.CONVERGED)
    points = points._replace(d1=ders.d1, d2=ders.d2)
    return next_anchor(carry, points, ders, u_blk), points
