"""Assembly modes: the branch indicator of a mechanism, its own loops' by default.

A mechanism's ``branch`` (optional) names assembly modes by the signs of functions the user
wrote.  Every structural block of the equations that it leaves uncovered (``structure.blocks``:
a block none of whose coordinates the user's indicator reads, which is every block when
there is none) gets one more indicator, the sign of that block's Jacobian determinant
``det(dPhi_rows / dq_cols)``.  For a dyad (two links closing a loop) that determinant is
``l1 l2 sin(angle between them)`` up to sign: the classic assembly-mode test, which changes
sign only through a toggle, where the block is singular.  So no loop changes its mode
without a ``BRANCH`` status naming it, whether or not the user wrote an indicator for it.

The determinant is taken from the constraint Jacobian that the Newton kernel has already
evaluated wherever it can (``jac``): the test costs a few products, no new derivative.
Positive row and column scalings (the solver's scaled variables) leave its sign unchanged.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from ..solver.linalg import det_small, entries, where
from .mechanism import Mechanism
from .structure import blocks, coords_read

__all__ = ["branch_names", "has_branch", "branch_value", "on_branch", "flipped_mask"]


@functools.lru_cache(maxsize=256)
def auto_blocks(mech: Mechanism) -> tuple[tuple[tuple[int, ...], tuple[int, ...]], ...]:
    """The structural blocks ``((rows, cols), ...)`` whose assembly mode the mechanism's own
    ``branch`` does not cover (none of their coordinates read by it): each is checked by the
    sign of its Jacobian determinant."""
    if mech.m == 0:
        return ()
    order = blocks(mech)
    if mech.branch is None:
        return order
    try:
        read = frozenset().union(*coords_read(mech, mech.branch))
    except Exception:  # noqa: BLE001 - an indicator that does not trace: its error shows at solve time
        return ()
    return tuple(b for b in order if not read.intersection(b[1]))


def _block_name(mech: Mechanism, rows) -> str:
    names = [name for name, r in mech.equations if set(r) & set(rows)]
    return " + ".join(names) if names else "block " + ", ".join(mech.coords[i] for i in rows)


@functools.lru_cache(maxsize=256)
def branch_names(mech: Mechanism) -> tuple[str, ...]:
    """Names of every entry of ``branch_value``: the user's indicator's (``Mechanism.branches``),
    then one per uncovered block, named by its loops (``Mechanism.equations``)."""
    user = mech.branches
    auto = []
    for rows, _ in auto_blocks(mech):
        name = _block_name(mech, rows)
        auto.append(name if name not in user else f"{name} (assembly)")
    return tuple(user) + tuple(auto)


def has_branch(mech: Mechanism) -> bool:
    """Whether the mechanism has any branch indicator (its own or a block's)."""
    return mech.branch is not None or bool(auto_blocks(mech))


def branch_value(mech: Mechanism, q, u, p, jac=None):
    """Every branch indicator at one sample: the user's (``()`` for one value, as
    ``Mechanism.branch_value`` gives it) when it covers every block, else ``(n,)`` with the
    uncovered blocks' Jacobian determinants after the user's entries.  ``jac``: the
    constraint Jacobian ``dPhi/dq`` at ``q`` (any positive row and column scaling), when the
    caller has it; NaN (no indicator) when there is none."""
    auto = auto_blocks(mech)
    user = mech.branch_value(q, u, p)
    if not auto:
        return user
    if jac is None:
        jac = jax.jacfwd(mech.residual)(q, u, p)
    e = entries(jac)
    dets = [det_small(jnp.stack([jnp.stack([e[i][j] for j in cols]) for i in rows])) for rows, cols in auto]
    vals = ([] if mech.branch is None else list(jnp.atleast_1d(user))) + dets
    return jnp.stack([jnp.asarray(v, jac.dtype) for v in vals])


# --------------------------------------------------------------------------- signs
def off_branch(target, value):
    """Per branch entry: whether ``value``'s sign differs from the requested sign ``target``
    (``target`` 0 or NaN: that entry is free).  Shapes ``()`` or ``(n_branches,)``."""
    return (target != 0) & jnp.isfinite(target) & (jnp.sign(value) != target)


def on_branch(target, value):
    """Whether a branch indicator ``value`` has every requested sign ``target``."""
    return ~jnp.any(off_branch(target, value))


def flipped_mask(target, value):
    """int32 bit mask of the branch entries off their requested sign (``Solution.flipped``)."""
    off = jnp.atleast_1d(off_branch(target, value))
    return jnp.sum(where(off, 2 ** jnp.arange(off.shape[-1], dtype=jnp.int32), 0), axis=-1).astype(jnp.int32)
