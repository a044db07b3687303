"""A scene over its stroke for a batch of designs: the one evaluation that ``run_scene``,
the sweeps, ``jaxmech.design`` and the live view share.

``scene_motion`` (traceable) gives every design's ``Motion`` over its own stroke under the
scene's constant-speed drive, with finite placeholders at failed samples; ``scene_outputs``
adds the scene's outputs.  For concrete parameters they run as two programs: the stroke
(``stroke_stage``: the continuation, a second of XLA compile for flap_msd) and the rest
(``outputs_stage``: kinematics of the points and the outputs).  ``evaluate`` lowers both,
compiles them one after the other (on two threads at once, XLA crashed with jaxlib 0.10.2)
and stores both as executables for the next process where the scene is one of the registry's.  The sweeps' kernels are the same two
programs, so ``run_scene`` and a one-design sweep agree bit for bit (one fused program
rounds differently: sma_flap's accelerations moved by an ulp).
"""

from __future__ import annotations

import dataclasses
import functools
import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..continuation.solve import all_converged, repair_strokes, repaired_rows, robust_size, stroke, take_rows
from .._compile.stored import cached_call, cached_chain
from ..kinematics import ConstantSpeed, Motion, sample_kinematics
from ..solver.linalg import where
from ..solver.options import SolverOptions
from ..solver.solution import Solution
from ..solver.status import Status
from ..solver.xla import jit
from .outputs import merged_status, run_outputs, sample_status
from .outputs import output_units as scene_output_units

__all__ = ["SCENE_OPTIONS", "scene_motion", "StrokePart", "scene_stroke", "scene_kinematics", "stroke_stage",
           "repair_stage", "repaired_part", "outputs_stage", "motion_and_outputs", "output_units", "evaluate"]

#: Solver options of a scene's stroke wherever it is evaluated (``run_scene``, sweeps,
#: design, the live view) unless the caller gives its own: 256 anchors.
SCENE_OPTIONS = SolverOptions(anchors=256)


def stroke_drive(scene, p, dtype):
    """One design's drive: constant speed ``scene.speed`` from the stroke start to its end;
    returns ``(drive, duration in s)``."""
    u0, u1 = (jnp.asarray(x, dtype) for x in scene.stroke(p))
    w = jnp.where(u1 >= u0, scene.speed, -scene.speed).astype(dtype)
    return ConstantSpeed(u0, w), (u1 - u0) / w


def scene_motion(scene, points: int, p, options: SolverOptions = SCENE_OPTIONS, robust: bool | None = None):
    """Every design's ``Motion`` over its stroke, traceable (``jit``/``vmap``/``grad``).

    **Arguments**

    - `scene`: the scene; `points`: samples along each stroke (both ends included).
    - `p`: ``{name: (D,)}``, every parameter of the scene for D designs (SI units).

    **Returns** ``(motion, ok)``: a ``Motion`` with ``(D, points)`` in front, and the boolean
    ``(D, points)`` mask of converged samples.  At failed samples the values are finite
    placeholders (the coordinates of ``scene.guess(p)``, zero derivatives), so that any
    function of the motion stays finite and differentiable; ``status`` says which samples are
    real.  The strokes of all designs are solved by one continuation (``per_design``
    strokes), not one per design under ``vmap``.  `robust`: as ``continuation.solve``'s.
    """
    return scene_kinematics(scene, points, p, scene_stroke(scene, points, p, options, robust))


def _as_dtype(scene, p):
    dtype = jnp.result_type(*[jnp.asarray(v) for v in p.values()], float)
    return {k: jnp.asarray(p[k], dtype) for k in scene.mechanism.params}, dtype


class StrokePart(NamedTuple):
    """``scene_stroke``'s result, ``(D, ...)`` in front of every field: each design's
    `drive` (``ConstantSpeed``), sample times `t` ``(D, N)`` in s, stroke-start `guess`
    ``(D, m)``, the stroke's ``Solution`` `solution` ``(D, N)``, and the per-unit-input
    derivatives `dq_du` ``(D, N, m, dof)`` and `d2q_du2` ``(D, N, m, dof, dof)``."""

    drive: ConstantSpeed
    t: jax.Array
    guess: jax.Array
    solution: Solution
    dq_du: jax.Array
    d2q_du2: jax.Array


def scene_stroke(scene, points: int, p, options: SolverOptions = SCENE_OPTIONS, robust: bool | None = None) -> StrokePart:
    """The first half of ``scene_motion``: every design's drive, sample times, guess and
    stroke solution with its input derivatives, a ``StrokePart`` (``scene_kinematics``
    takes it).  `robust`: as ``continuation.solve``'s."""
    mech = scene.mechanism
    p, dtype = _as_dtype(scene, p)

    def setup(p1):
        drive, duration = stroke_drive(scene, p1, dtype)
        return drive, jnp.linspace(0.0, duration, points), jnp.asarray(scene.guess(p1), dtype)

    drive, t, guess = jax.vmap(setup)(p)
    us = _stroke_inputs(mech, points, drive, t)
    # one compiled pass: positions, dq/du and d2q/du2 (differentiable by the implicit rule)
    sol, e1, e2 = stroke(mech, us, p, guess, options, derivs=True, per_design=True, robust=robust)
    return StrokePart(drive, t, guess, sol, e1, e2)


def _stroke_inputs(mech, points: int, drive, t):
    """Every design's inputs ``(D, points, dof)`` along its stroke: its drive at its times."""
    return jax.vmap(lambda d, t1: jnp.reshape(jax.vmap(d)(t1), (points, mech.dof)))(drive, t)


def scene_repair(scene, points: int, p, part: StrokePart, options: SolverOptions = SCENE_OPTIONS) -> StrokePart:
    """``part`` (``scene_stroke``'s by the walk alone, ``robust=False``) with the points the
    walk did not solve repaired (``continuation.repair_strokes``): what ``scene_stroke``
    gives with its repair, as a stage of its own that runs only for the designs that need
    it (``evaluate`` and the sweep kernels gather them)."""
    mech = scene.mechanism
    p, _ = _as_dtype(scene, p)
    us = _stroke_inputs(mech, points, part.drive, part.t)
    sol, e1, e2 = repair_strokes(mech, us, p, part.guess, options, (part.solution, part.dq_du, part.d2q_du2))
    return part._replace(solution=sol, dq_du=e1, d2q_du2=e2)


def scene_kinematics(scene, points: int, p, part: StrokePart):
    """The second half of ``scene_motion``: ``(motion, ok)`` from ``scene_stroke``'s ``part``."""
    mech = scene.mechanism
    p, _ = _as_dtype(scene, p)
    drive, t, guess, sol, e1, e2 = part.drive, part.t, part.guess, part.solution, part.dq_du, part.d2q_du2
    ok = sol.status == Status.CONVERGED
    # Mask the *inputs* of everything downstream: no NaN, not even in a branch not taken
    # (failed samples have zero derivatives).
    q = where(ok[..., None], sol.q, guess[:, None, :])
    d1 = where(ok[..., None, None], e1, 0.0)
    d2 = where(ok[..., None, None, None], e2, 0.0)
    names = tuple(mech.points)
    d = t.shape[0]
    # One vmap over designs x samples (the drive and parameters repeated per sample): JAX
    # batches the kinematics' nested jvps once instead of at two vmap levels.
    flat = lambda x: jnp.reshape(x, (d * points,) + x.shape[2:])  # noqa: E731
    rep = lambda x: jnp.repeat(x, points, axis=0)  # noqa: E731
    kin = jax.vmap(lambda dr, p1, t_, q_, a_, b_: sample_kinematics(mech, names, dr, p1, t_, q_, a_, b_))(
        jax.tree_util.tree_map(rep, drive), jax.tree_util.tree_map(rep, p), flat(t), flat(q), flat(d1), flat(d2)
    )
    u, ud, udd, qd, qdd, pts = jax.tree_util.tree_map(lambda x: jnp.reshape(x, (d, points) + x.shape[1:]), kin)
    mo = Motion(
        t=t, u=u, u_dot=ud, u_ddot=udd, q=q, q_dot=qd, q_ddot=qdd, dq_du=d1, d2q_du2=d2,
        points=pts, status=sol.status, coords=mech.coords, inputs=mech.inputs,
    )
    return mo, ok


def scene_outputs(scene, p, mo: Motion) -> dict:
    """The scene's outputs for every design of a ``scene_motion``: ``{name: (values (D, N),
    unit)}`` in the scene's column order (``scene.outputs`` is written for one design: it is
    vmapped here); ``{}`` for a scene without outputs."""
    return scene_outputs_status(scene, p, mo)[0]


def scene_outputs_status(scene, p, mo: Motion) -> tuple:
    """``(scene_outputs, status)``: the outputs and the samples' status ``(D, N)`` with the
    outputs' own where they declare one (``outputs.Outputs.status``: a sample the motion
    solved but the outputs could not evaluate), else ``mo.status`` itself."""
    if scene.outputs is None:
        return {}, mo.status
    units: dict = {}  # read from what the one-design function returns while it is traced

    def one(p1, mo1):
        outs, own = sample_status(scene, p1, mo1)
        units.update((k, unit) for k, (_, unit) in outs.items())
        return {k: jnp.broadcast_to(jnp.asarray(v), mo1.t.shape) for k, (v, _) in outs.items()}, own

    p = {k: jnp.asarray(v, mo.q.dtype) for k, v in p.items()}
    values, own = jax.vmap(one)(p, mo)
    return {k: (values[k], unit) for k, unit in units.items()}, merged_status(mo.status, own)


@functools.partial(jit, static_argnums=(0, 1, 2, 3))
def stroke_stage(scene, points: int, options: SolverOptions, robust: bool, p):
    """``scene_stroke`` as a program of its own: the first of the two a scene's evaluation
    runs (``motion_and_outputs``); ``robust``: the walk with its repair in one program, or
    the walk alone (``evaluate`` and the sweep kernels, which run ``repair_stage`` for the
    designs that need it)."""
    return scene_stroke(scene, points, p, options, robust)


@functools.partial(jit, static_argnums=(0, 1, 2))
def repair_stage(scene, points: int, options: SolverOptions, p, part):
    """``scene_repair`` as a program of its own (``p`` and ``part`` of the designs that need
    it)."""
    return scene_repair(scene, points, p, part, options)


def repaired_part(part: StrokePart, p, repair_rows, size: int | None = None) -> StrokePart:
    """``part`` with the designs where a sample failed taken from ``repair_rows(p_rows,
    part_rows)`` (the repair stage, compiled for ``size`` designs: they are gathered in
    batches of that many, ``continuation.repaired_rows``); ``part`` itself where every
    sample converged."""
    status = np.asarray(part.solution.status)
    passed = all_converged(status)
    if np.all(passed):
        return part
    # the designs with the fewest failed points first: they share the cheap calls
    work = np.sum(status != Status.CONVERGED, axis=-1)
    return repaired_rows(part, passed, lambda idx: repair_rows(*take_rows((p, part), idx)), size or robust_size(passed.size), work)


@functools.partial(jit, static_argnums=(0, 1, 2))
def outputs_stage(scene, points: int, with_outputs: bool, p, part):
    """The second program: ``(motion, {output name: values (D, N)})`` from ``stroke_stage``'s
    ``part`` (``{}`` without outputs); the motion's status takes the outputs' own where
    they declare one (``outputs.Outputs.status``)."""
    mo, _ = scene_kinematics(scene, points, p, part)
    if not with_outputs:
        return mo, {}
    outs, status = scene_outputs_status(scene, p, mo)
    if status is not mo.status:  # (outputs without a status of their own: the program is unchanged)
        mo = dataclasses.replace(mo, status=status)
    return mo, {k: v for k, (v, _) in outs.items()}


def motion_and_outputs(scene, points: int, options: SolverOptions, with_outputs: bool, p, robust: bool = True):
    """``(motion, {output name: values (D, N)})`` of ``scene_motion`` and ``scene_outputs``
    (their units: ``outputs.output_units``); ``{}`` without outputs.  Two programs, the
    stroke (``stroke_stage``) and the rest (``outputs_stage``): ``evaluate`` compiles them
    one after the other, and the sweep kernels are the same two programs, so a design's
    columns do not depend on the path.  Traceable: inside a trace the two are one program.
    ``robust``: the stroke's robust program (the default) or its straight-line one."""
    return outputs_stage(scene, points, with_outputs, p, stroke_stage(scene, points, options, robust, p))


def output_units(scene, points: int | None = None, options: SolverOptions | None = None, p=None) -> dict:
    """Deprecated: ``scenes.outputs.output_units(scene)`` (the scene's declaration; `points`,
    `options` and `p` are not needed and ignored)."""
    warnings.warn("jaxmech.scenes.evaluation.output_units is deprecated: use jaxmech.scenes.outputs.output_units(scene)",
                  DeprecationWarning, stacklevel=2)
    return scene_output_units(scene)


def evaluate(scene, points: int, p, options: SolverOptions = SCENE_OPTIONS):
    """``(motion, outputs)`` of D designs with concrete parameters ``p`` (``{name: (D,)}``):
    ``stroke_stage`` (the walk) then ``outputs_stage``, compiled where they must be
    (``stored.cached_chain``), and, for the designs where a sample failed, ``repair_stage``
    between the two (the rule of every concrete stroke, the sweep kernels' too).  Outputs
    that do not trace (``scene.outputs`` converting values to numpy;
    ``outputs.run_outputs`` tells) are evaluated design by design on the host instead:
    ``outputs`` is then ``None`` and the caller evaluates them."""
    mode = {}
    static2 = lambda traced: (scene, int(points), traced)  # noqa: E731

    def run(traced: bool):
        mode["traced"] = traced
        first = (stroke_stage, (scene, int(points), options, False), (p,))
        return cached_chain(*first, outputs_stage, static2(traced), lambda part: (p, part), with_first=True)

    part, (mo, values) = run_outputs(scene, run)
    traced = mode["traced"]
    repaired = repaired_part(part, p, lambda p_, part_: cached_call(repair_stage, (scene, int(points), options), (p_, part_)))
    if repaired is not part:
        mo, values = cached_call(outputs_stage, static2(traced), (p, repaired))
    if not traced:
        return mo, None
    return mo, {k: (values[k], unit) for k, unit in scene_output_units(scene).items()}
