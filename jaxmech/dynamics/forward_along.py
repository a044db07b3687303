"""What a forward-dynamics run implies at each of its states: the coordinates'
accelerations, the driving effort and every joint's reaction, by inverse dynamics at the
trajectory's own states (``trajectory_dynamics``, behind ``Trajectory.dynamics``)."""

from __future__ import annotations

from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..solver.options import SolverOptions
from .friction import friction_parameters
from .inverse import InverseDynamics, inverse_dynamics_at
from .model import Model

__all__ = ["trajectory_dynamics"]

#: States per call of the compiled inverse dynamics: a trajectory of any length is cut in
#: blocks of this size (the last one padded), so a new duration compiles nothing new.
BLOCK = 128


def _block(x, start: int, size: int):
    """Rows ``start:start + size`` of `x`, the last row repeated past its end (numpy for a
    numpy `x`: no small program compiled for a new length)."""
    xp = np if isinstance(x, np.ndarray) else jnp
    rows = x[start : start + size]
    return xp.concatenate([rows, xp.repeat(rows[-1:], size - rows.shape[0], axis=0)])


def trajectory_dynamics(model: Model, tr, p: Mapping, *, options: SolverOptions = SolverOptions()) -> InverseDynamics:
    """Inverse dynamics at every state of a forward-dynamics ``Trajectory`` `tr` of `model`.

    At each state ``(t, u, u_dot, u_ddot)`` of the run (the loop closed from its ``q``) the
    result holds the coordinates' rates and accelerations ``q_dot``, ``q_ddot``, the
    driving effort ``tau`` ``(N+1, dof)``: the generalized force (N m or N, positive in the
    input's positive sense) that the run's motor, actuators and `load` exert on each input,
    since ``M u_ddot + h = tau`` there, and every joint's reaction ``joints`` (N, complex:
    the joint's first body on its second), as ``Model``'s inverse dynamics gives them.
    Rows after a stop are NaN.  A run with joint friction (``tr.friction``) has it here
    too, its sign over the run's own speed scale ``tr.friction_speed``
    (``inverse_dynamics_at(..., friction=, friction_speed=)``): ``tau`` balances the run's
    accelerations with the friction loads (``joint_friction``), the reactions include them.

    `p`: the run's parameters (the model's and friction's are read; a motor's extra names
    are ignored).
    **Returns** an ``InverseDynamics`` with leading axis ``N+1``.
    """
    fr = getattr(tr, "friction", None)
    names = model.parameters + friction_parameters(model, fr)
    missing = [k for k in names if k not in p]
    if missing:
        raise ValueError(f"{model.mechanism.name}: trajectory_dynamics needs the run's parameters p; missing {missing}")
    pm = {k: p[k] for k in names}
    friction = {} if fr is None else dict(friction=fr, friction_speed=tr.friction_speed)
    n = tr.t.shape[0]
    # cut on the host where nothing is traced: slicing a new length on the device would
    # compile small programs for each new duration
    if not any(isinstance(x, jax.core.Tracer) for x in (tr.t, tr.u, tr.u_dot, tr.u_ddot, tr.q)):
        tr = jax.tree_util.tree_map(np.asarray, tr)
    parts = []
    for start in range(0, n, BLOCK):
        blk = lambda x: _block(x, start, BLOCK)  # noqa: E731
        parts.append(inverse_dynamics_at(model, blk(tr.u), blk(tr.u_dot), blk(tr.u_ddot), pm, blk(tr.q), t=blk(tr.t),
                                         options=options, **friction))
    if isinstance(tr.u, np.ndarray):
        return jax.tree_util.tree_map(lambda *xs: jax.device_put(np.concatenate([np.asarray(x) for x in xs])[:n]), *parts)
    return jax.tree_util.tree_map(lambda *xs: jnp.concatenate(xs)[:n], *parts)
