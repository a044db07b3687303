"""User input to arrays: names to axes, broadcasting, dtypes, and the eager checks that name
the parameter at fault before anything is traced."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ..mechanism.mechanism import Mechanism
from .options import SolverOptions

__all__ = ["as_inputs", "as_coords", "prepare", "batch_shape", "own_params"]


def _stack_named(mech: Mechanism, names, values: Mapping, what: str, kind: str):
    """``{name: array}`` -> array ``(..., len(names))`` in ``names`` order, or ValueError."""
    unknown = [k for k in values if k not in names]
    if unknown:
        raise ValueError(f"{mech.name}: unknown {kind} name(s) {unknown} in {what}; {kind}s are {list(names)}")
    missing = [k for k in names if k not in values]
    if missing:
        raise ValueError(f"{mech.name}: missing {kind}(s) {missing} in {what}")
    xp = _xp(*values.values())
    return xp.stack(xp.broadcast_arrays(*[xp.asarray(values[k]) for k in names]), axis=-1)


def _xp(*values):
    """numpy for concrete values, jax.numpy inside a trace.  Input handling on the host: an
    eager jnp op on a new shape compiles a small program of its own (10-50 ms each)."""
    traced = any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves(values))
    return jnp if traced else np


def _with_last_axis(mech: Mechanism, x, names, what: str, kind: str):
    x = _xp(x).asarray(x)
    if x.ndim == 0 or x.shape[-1] != len(names):
        raise ValueError(f"{mech.name}: {what} must have a last axis of size {len(names)} ({kind}s {names}), got shape {x.shape}")
    return x


def as_inputs(mech: Mechanism, u, what="u"):
    """Inputs as an array ``(..., dof)``.  A dict maps input names to arrays; for one-input
    mechanisms a bare array is the batch of that input (a last axis of size 1 is taken as
    the input axis: ``(dof,)`` and ``(N, dof)`` arrays are accepted as documented)."""
    if isinstance(u, Mapping):
        return _stack_named(mech, mech.inputs, u, what, "input")
    if mech.dof == 1:
        # The documented shapes are (..., dof) or, for one input, the bare batch: a last
        # axis of size 1 is the input axis already.
        u = _xp(u).asarray(u)
        return u if u.ndim >= 1 and u.shape[-1] == 1 else u[..., None]
    return _with_last_axis(mech, u, mech.inputs, what, "input")


def as_coords(mech: Mechanism, q, what="guess"):
    """Coordinates as an array ``(..., m)``, from an array or ``{coord_name: array}``."""
    if isinstance(q, Mapping):
        return _stack_named(mech, mech.coords, q, what, "coordinate")
    return _with_last_axis(mech, q, mech.coords, what, "coordinate")


def _check_dtype(options: SolverOptions, named: dict[str, Any]):
    if options.dtype is None:
        return
    want = jnp.dtype(options.dtype)
    if want == jnp.float64 and not jax.config.jax_enable_x64:
        raise ValueError(
            "dtype='float64' was asked for but JAX runs in float32: call "
            "jax.config.update('jax_enable_x64', True) before creating arrays"
        )
    for name, x in named.items():
        for leaf in jax.tree_util.tree_leaves(x):
            dt = np.asarray(leaf).dtype if not isinstance(leaf, jax.Array) else leaf.dtype
            if jnp.issubdtype(dt, jnp.floating) and dt != want:
                raise ValueError(f"{name} is {dt} but dtype={want} was asked for; convert it with .astype({want.name!r})")


def own_params(mech: Mechanism, p) -> Mapping:
    """The mechanism's share of a parameter mapping: a model's (or a scene's) whole dict is
    accepted by the kinematics, which read only the mechanism's names (missing ones still
    raise, in ``check_params``)."""
    return {k: v for k, v in p.items() if k in mech.params} if isinstance(p, Mapping) else p


def prepare(mech: Mechanism, u, p, guess, options: SolverOptions, u_what="u"):
    """Checked arrays ``(u (..., dof), p, guess (..., m))`` of one dtype for a position solve:
    names, shapes, values and dtypes checked eagerly (``ValueError`` naming the argument)."""
    p = own_params(mech, p)
    mech.check_params(p)
    _check_dtype(options, {u_what: u, "p": p, "guess": guess})
    u = as_inputs(mech, u, u_what)
    guess = as_coords(mech, guess)
    dtype = jnp.result_type(u, guess, *[_xp(v).asarray(v) for v in p.values()], float)
    if options.dtype is not None:
        dtype = jnp.dtype(options.dtype)
    u = u.astype(dtype)
    guess = guess.astype(dtype)
    p = {k: _xp(p[k]).asarray(p[k], dtype) for k in mech.params}
    return u, p, guess


def batch_shape(mech, shapes: dict[str, tuple]):
    try:
        return np.broadcast_shapes(*shapes.values())
    except ValueError:
        desc = ", ".join(f"{k}: {v}" for k, v in shapes.items())
        raise ValueError(f"{mech.name}: batch shapes do not broadcast ({desc})") from None
