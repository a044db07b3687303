"""Worked design problems (issue 5): each a function that states a design question of
one of the scenes, answers it with ``jaxmech.design`` and reports the answer in words.

- ``flap_msd``: linkage lengths of the MSD double flap for exactly 60 deg of second-flap
  travel at the least peak motor torque.
- ``landing_gear``: the nose gear's ``d`` and ``h`` from its stroke and 90 deg rotation.
- ``arc_track_flap``: the shallowest fairing for the arc-track flap under the thesis's
  validity checks and a cap on the screw torque.
- ``identify_fourbar``: link lengths and a damping coefficient of a loaded four-bar from
  noisy motion and torque records, with their Gauss-Newton standard errors.

``flap_msd`` is stated as an engineer states it (``flap_state``: the peak torque in
epigraph form at every stroke sample, the travel equalities, a transmission-angle limit at
every sample, a box) and solved by ``jaxmech.design.constrained.minimize`` (scipy SLSQP fed with
exact Jacobians from one compiled program).  ``flap_msd_objective`` keeps the older
statement (smooth peak, ``h`` and ``z`` eliminated) that ``benchmarks/design.py`` gives
Nelder-Mead.  ``landing_gear`` and ``arc_track_flap`` minimise ``scene_figure`` objectives
with ``design.fit`` (optax L-BFGS from several starts at once; the arc-track constraints by
an exterior quadratic penalty ``w * max(g, 0)^2`` whose optimum violates ``g <= 0`` by
``O(1/w)``, a back-off margin larger than that keeping the answer inside); the
identification is a least-squares problem and uses Levenberg-Marquardt on the engine's
residual Jacobian.

Each function builds its objective once per setting (``functools.cache``), so a second
call reuses the compiled program.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax

from jaxmech.design import FitResult, fit, peak, scene_figure
from jaxmech.dynamics import Body, Gravity, Model, Moment, generalized_forces
from jaxmech.scenes import Outputs, Scene
from jaxmech.sweep import design_columns

__all__ = [
    "FlapDesign",
    "GearDesign",
    "FairingDesign",
    "Identification",
    "flap_msd",
    "flap_msd_objective",
    "flap_starts",
    "flap_bounds",
    "landing_gear",
    "arc_track_flap",
    "identify_fourbar",
    "LOADED_FOURBAR",
]

_DEG = np.pi / 180.0


def _jnp(p):
    return {k: jnp.asarray(v, jnp.result_type(float)) for k, v in p.items()}


def _lean(scene: Scene, outputs) -> Scene:
    """The scene with only the outputs a problem needs and no drawing points: the same
    loops, stroke, guess and loads, but a smaller program to compile (the points' time
    derivatives and the unused outputs are not traced)."""
    mech = dataclasses.replace(scene.mechanism, points={})
    return dataclasses.replace(scene, name=f"{scene.name}_lean", mechanism=mech, outputs=outputs, drawing=None)


def _flap_torque(p, mo):
    # The energy method's closed-form torque (the document's formula with its two
    # corrections), equal to the scene's virtual-power torque (tests/seeds/test_flap_msd.py;
    # tests/test_problems.py checks the answer with run_scene) and cheaper to compile:
    # no reverse pass inside the objective's own gradient.
    from jaxmech.scenes.flap_msd import torque_document

    return {"torque": torque_document(p, mo, corrected=True)}


@functools.cache
def _flap_scene() -> Scene:
    from jaxmech.scenes.flap_msd import SCENE

    return _lean(SCENE, Outputs(_flap_torque, {"torque": "N m"}))


# =========================================================================== 1. flap_msd
#: Design variables of ``flap_msd``: loop 2 (bar BD, bar DGE, pivot B) and the E-G length.
#: Loop 1 (crank, coupler, main flap) keeps the document's values, so the main flap moves
#: exactly as designed; ``h`` (link EH) and ``z`` (arm FH) are eliminated by the two
#: equalities below.
FLAP_FREE = ("d", "p", "s", "t", "g")
FLAP_ELIMINATED = ("h", "z")
FLAP_TRAVEL = 60.0 * _DEG  #: required second-flap travel over the stroke (rad)
FLAP_TEMPERATURE = 1.0  #: N m, temperature of the smooth peak (bound T log N)


def _flap_theta_ends(p):
    """theta at alpha = 275 and 320 deg (rad), closed form (circle intersections)."""
    from jaxmech.scenes.flap_msd import ALPHA_END, ALPHA_START, closed_form_positions

    return closed_form_positions(p, ALPHA_START)[5], closed_form_positions(p, ALPHA_END)[5]


@functools.cache
def _flap_doc_theta_start() -> float:
    """The document's theta at alpha = 275 deg (rad): 0.024093 deg."""
    from jaxmech.scenes.flap_msd import DEFAULTS

    with jax.ensure_compile_time_eval():  # a constant, also when first needed under a trace
        return float(_flap_theta_ends({k: jnp.asarray(v, jnp.float64) for k, v in DEFAULTS.items()})[0])


def _flap_project(free):
    """``(h, z, ok)`` with theta(275) = the document's and theta(320) - theta(275) = 60 deg.

    Newton on the 2x2 closed-form system ``F(h, z; free) = 0`` from the document's
    ``(h, z)``, iterated without derivatives; then one Newton step with the free
    parameters traced and the Jacobian held: at a root its derivative is
    ``-F_{hz}^{-1} F_free``, the implicit function theorem's, and its value is unchanged.
    """
    from jaxmech.scenes.flap_msd import DEFAULTS

    base = _jnp(DEFAULTS)
    theta0 = _flap_doc_theta_start()

    def F(x, fr):
        p = {**base, **fr, "h": x[0], "z": x[1]}
        a, b = _flap_theta_ends(p)
        return jnp.stack([a - theta0, b - a - FLAP_TRAVEL])

    stop = jax.lax.stop_gradient
    fr0 = stop(free)
    x0 = jnp.stack([base["h"], base["z"]])
    x = jax.lax.fori_loop(0, 30, lambda _, x: x - jnp.linalg.solve(jax.jacfwd(F)(x, fr0), F(x, fr0)), x0)
    res = F(x, fr0)
    ok = jnp.all(jnp.isfinite(x)) & jnp.all(jnp.abs(res) < 1e-9) & jnp.all(x > 0)
    x = jnp.where(ok, x, x0)  # mask the inputs of what follows
    x = x - jnp.linalg.solve(stop(jax.jacfwd(F)(x, fr0)), F(x, free))
    return x[0], x[1], ok


def _flap_peak_smooth(cols, p):
    return peak(cols["torque[N m]"], "smooth", temperature=FLAP_TEMPERATURE)


@functools.cache
def flap_msd_objective(points: int = 101):
    """The objective of ``flap_msd``: ``f(free) -> (value, ok)``, ``free`` = ``{name: scalar}``
    over ``FLAP_FREE``.

    The value is the smooth peak (``design.peak(mode="smooth")``, ``T`` =
    ``FLAP_TEMPERATURE`` = 1 N m, so within ``T log N`` = 4.6 N m of the sampled maximum
    for ``N`` = 101) of the motor torque over the stroke, N m, for the design whose ``h``
    and ``z`` are solved from the two equalities (theta starts where the document's does,
    and turns through exactly 60 deg).  ``ok`` is False when the equalities cannot be met
    or a sample of the stroke does not converge.  One object per ``points``: jitted
    callers compile once.
    """
    fig = scene_figure(_flap_scene(), _flap_peak_smooth, points=points, name="peak torque (smooth)")

    def objective(free):
        h, z, ok_proj = _flap_project(dict(free))
        value, ok = fig({**free, "h": h, "z": z})
        ok = ok & ok_proj
        return jnp.where(ok, value, jnp.nan), ok

    return objective


@functools.cache
def _flap_projection_batch():
    return jax.jit(jax.vmap(_flap_project))


def flap_eliminated(free) -> dict[str, np.ndarray]:
    """``{"h", "z"}`` (m) that meet the two travel equalities for the free lengths
    ``{name: (S,)}`` over ``FLAP_FREE`` (as ``flap_msd_objective`` eliminates them); NaN
    where they cannot be met."""
    h, z, ok = _flap_projection_batch()(_jnp({k: np.atleast_1d(free[k]) for k in FLAP_FREE}))
    ok = np.asarray(ok)
    return {"h": np.where(ok, np.asarray(h), np.nan), "z": np.where(ok, np.asarray(z), np.nan)}


def flap_starts(n: int = 4, *, seed: int = 0) -> dict[str, np.ndarray]:
    """``n`` starting designs for ``flap_msd``: the document's, then random ones within
    +-10 % of it (``numpy.random.default_rng(seed)``)."""
    from jaxmech.scenes.flap_msd import DEFAULTS

    rng = np.random.default_rng(seed)
    scale = np.concatenate([[1.0], 1.0 + 0.1 * (2 * rng.random(n - 1) - 1)]) if n > 1 else np.ones(1)
    out = {}
    for k in FLAP_FREE:
        out[k] = DEFAULTS[k] * scale
        scale = np.roll(scale, 1) if n > 2 else scale  # decorrelate the parameters
        if n > 1:
            scale[0] = 1.0
    return out


def flap_bounds() -> dict[str, tuple[float, float]]:
    """Box of ``flap_msd``'s free parameters: 0.7 to 1.3 times the document's values."""
    from jaxmech.scenes.flap_msd import DEFAULTS

    return {k: (0.7 * DEFAULTS[k], 1.3 * DEFAULTS[k]) for k in FLAP_FREE}


#: Design variables of the constrained statement of ``flap_msd``: loops 2 and 3.
FLAP_VARS = FLAP_FREE + FLAP_ELIMINATED
FLAP_MIN_TRANSMISSION = 20.0 * _DEG  #: default least transmission angle of loops 2 and 3 (rad)


def flap_state_bounds() -> dict[str, tuple[float, float]]:
    """Box of the constrained ``flap_msd``: ``flap_bounds`` for the free lengths, 0.5-1.5
    times the document's for ``h`` and ``z`` (no longer eliminated)."""
    from jaxmech.scenes.flap_msd import DEFAULTS

    return {**flap_bounds(), **{k: (0.5 * DEFAULTS[k], 1.5 * DEFAULTS[k]) for k in FLAP_ELIMINATED}}


def _flap_sample(p, alpha):
    """One stroke sample by the engine's position solve from the closed-form (dyad) guess:
    ``(q, dq/dalpha, d2q/dalpha2, ok)``, differentiable in ``p`` by the implicit rule."""
    from jaxmech.kinematics import input_derivatives
    from jaxmech.scenes.flap_msd import closed_form_positions, mechanism
    from jaxmech import Status, solve

    guess = closed_form_positions(jax.lax.stop_gradient(p), alpha)
    assembled = jnp.all(jnp.isfinite(guess))  # every dyad closes at this crank angle
    guess = jnp.where(assembled, guess, 0.0)
    u = jnp.reshape(alpha, (1,))
    sol = solve(mechanism, alpha, p, guess)  # one sample (a scalar input): works inside jit, vmap and grad
    ok = assembled & (sol.status == Status.CONVERGED)
    q = jnp.where(ok, sol.q, guess)  # mask the inputs of what follows
    d1, d2 = input_derivatives(mechanism, q, u, p)
    return q, d1, d2, ok


def _flap_rows(points: int, min_transmission: float):
    """``rows(p, motion) -> Stated`` of the constrained ``flap_msd`` (see ``flap_state``)."""
    from jaxmech.design.constrained import Stated
    from jaxmech.scenes.flap_msd import torque_document

    theta0 = _flap_doc_theta_start()
    floor = float(np.sin(min_transmission))

    def rows(p, mo):
        theta = mo.q[:, 5]
        sin_mu = jnp.concatenate([-jnp.sin(mo.q[:, 2] - mo.q[:, 3]), jnp.cos(mo.q[:, 5] + mo.q[:, 4])])
        return Stated(peak=torque_document(p, mo, corrected=True),
                      eq=jnp.stack([theta[0] - theta0, theta[-1] - theta[0] - FLAP_TRAVEL]), le=floor - sin_mu)

    return rows


@functools.cache
def flap_stroke_problem(points: int = 101, min_transmission: float = FLAP_MIN_TRANSMISSION):
    """The constrained ``flap_msd`` (``flap_state``'s statement) as a
    ``jaxmech.design.stroke_problem.StrokeProblem``: the engine's position solve at each of
    ``points`` crank angles from the closed-form (dyad) guess on the scene's branch, 1 rad/s,
    and the rows of ``flap_state``; its Lagrangian's exact Hessian by the second-order
    adjoint (``jaxmech.design.minimize_second_order``)."""
    from jaxmech.design.stroke_problem import StrokeProblem
    from jaxmech.scenes.flap_msd import ALPHA_END, ALPHA_START, DEFAULTS, closed_form_positions, mechanism

    base = _jnp(DEFAULTS)
    return StrokeProblem(mechanism=mechanism, names=FLAP_VARS, params=lambda x: {**base, **x},
                         us=np.linspace(ALPHA_START, ALPHA_END, points), u_dot=np.ones(points), u_ddot=np.zeros(points),
                         guess=lambda p, u: closed_form_positions(p, u[0]), rows=_flap_rows(points, float(min_transmission)))


@functools.cache
def flap_state(points: int = 101, min_transmission: float = FLAP_MIN_TRANSMISSION):
    """``flap_msd`` as an engineer states it, for ``jaxmech.design.constrained``: ``x -> Stated``
    over ``FLAP_VARS`` (m).

    - peak: the motor torque at ``points`` crank angles, 275 -> 320 deg at 1 rad/s (N m,
      the energy method's closed form, equal to the virtual-power torque);
    - eq: ``theta(275 deg) - theta_doc`` and ``theta(320) - theta(275) - 60 deg`` (rad);
    - le: ``sin(min_transmission) - sin(mu)`` for the transmission angle ``mu`` of loops
      2 (``-sin(phi - psi)``) and 3 (``cos(theta + xi)``) at every sample: a margin from
      the toggles that bound the branch, i.e. a least normalised loop determinant
      (``min_transmission = 0``: only assemblable on the branch, the unconstrained problem);
    - ok: every sample assembled and converged on the branch.
    """
    import types

    from jaxmech.scenes.flap_msd import ALPHA_END, ALPHA_START, DEFAULTS
    from jaxmech.design.constrained import Stated

    alphas = jnp.linspace(ALPHA_START, ALPHA_END, points)
    rows = _flap_rows(points, float(min_transmission))

    def state(x):
        p = {**_jnp(DEFAULTS), **x}
        q, d1, d2, ok = jax.vmap(_flap_sample, (None, 0))(p, alphas)
        # Constant crank speed 1 rad/s: q_dot = q', q_ddot = q''.
        mo = types.SimpleNamespace(q=q, q_ddot=d2[..., 0, 0], dq_du=d1, u_dot=jnp.ones((points, 1), q.dtype))
        s = rows(p, mo)
        return Stated(peak=s.peak, eq=s.eq, le=s.le, ok=jnp.all(ok))

    return state


@dataclasses.dataclass(frozen=True)
class FlapDesign:
    """Answer of ``flap_msd``.

    - `params`: every scene parameter of the optimised design (SI), for ``run_scene``.
    - `theta_travel`, `theta_start`: second-flap travel over the stroke and its angle at
      alpha = 275 deg (rad, from the engine's solve at the stroke ends).
    - `peak_torque`, `document_peak_torque`: the largest motor torque over the ``points``
      stroke samples (N m).  `improvement`: ``1 - peak_torque / document_peak_torque``.
    - `min_transmission`: least transmission angle of loops 2 and 3 over the stroke (rad).
    - `violation`: largest constraint violation at the answer (rad, or the sine's units).
    - `result`: the ``constrained.ConstrainedResult``; `report`: the answer in words.
    """

    params: dict
    theta_travel: float
    theta_start: float
    peak_torque: float
    document_peak_torque: float
    document_theta_travel: float
    improvement: float
    min_transmission: float
    violation: float
    points: int
    result: object
    report: str


def flap_msd(*, points: int = 101, starts: int | dict = 4, min_transmission: float = FLAP_MIN_TRANSMISSION,
             method: str = "SLSQP", maxiter: int = 300) -> FlapDesign:
    """Least peak motor torque for exactly 60 deg of second-flap travel (MSD double flap).

    **Problem.**  Over the stroke alpha = 275 -> 320 deg the document's design turns the
    second flap through 60.58 deg (goal: 60) with a peak motor torque of 3230.8 N m.
    Choose the lengths of loops 2 and 3 (``FLAP_VARS``) so that theta turns through exactly
    60 deg from the same retracted start (theta(275 deg) = 0.0241 deg, the document's),
    with the least peak torque and no transmission angle of loops 2 or 3 below
    `min_transmission` (default 20 deg; 0 leaves only assemblability on the branch: the
    problem Nelder-Mead is given in ``benchmarks/design.py``, whose optimum sits within a
    degree of loop 2's toggle at the stroke start).
    Loop 1 is kept, so the main flap's motion is the document's.

    **Method.**  Stated as it reads (``flap_state``): the peak in epigraph form
    (``min t`` with ``torque_i <= t`` at every sample), the two equalities, the
    transmission limits at every sample, the box ``flap_state_bounds``; solved by
    ``jaxmech.design.constrained.minimize`` (scipy SLSQP or trust-constr) with the exact Jacobian
    of every constraint at every sample from one compiled forward-mode program, from each
    start in turn.

    **Arguments**: `points`: stroke samples; `starts`: number of starts (the document's
    design first, see ``flap_starts``; ``h`` and ``z`` start at the document's) or
    ``{name: (S,)}`` over ``FLAP_VARS``; `method`, `maxiter`: the optimiser's.

    **Returns** a ``FlapDesign``.  **Raises** ``RuntimeError`` if no start is feasible.
    """
    from jaxmech.design.constrained import minimize
    from jaxmech.scenes.flap_msd import DEFAULTS

    if isinstance(starts, int):
        p0 = flap_starts(starts)
        p0 = {**p0, **{k: np.full(starts, DEFAULTS[k]) for k in FLAP_ELIMINATED}}
    else:
        p0 = dict(starts)
    state = flap_state(points, float(min_transmission))
    doc = {k: np.asarray([DEFAULTS[k]]) for k in FLAP_VARS}
    res = minimize(state, {k: p0[k] for k in FLAP_VARS}, flap_state_bounds(), peak_scale=3000.0, method=method,
                   maxiter=maxiter, prog=_flap_program(points, float(min_transmission)))
    if res.best < 0:
        raise RuntimeError("flap_msd: no start produced a feasible design\n" + res.report())
    best = {**DEFAULTS, **res.best_params}
    doc_eval = _flap_measure(points, float(min_transmission), doc)
    new_eval = _flap_measure(points, float(min_transmission), {k: np.asarray([best[k]]) for k in FLAP_VARS})
    improvement = 1.0 - new_eval["peak"] / doc_eval["peak"]
    lines = [
        "flap_msd: least peak motor torque with exactly 60 deg of second-flap travel",
        f"  document: theta travel {np.rad2deg(doc_eval['travel']):.4f} deg, peak torque {doc_eval['peak']:.2f} N m",
        f"  design:   theta travel {np.rad2deg(new_eval['travel']):.10f} deg (from {np.rad2deg(new_eval['start']):.4f} deg), "
        f"peak torque {new_eval['peak']:.2f} N m ({100 * improvement:.1f} % lower), "
        f"least transmission angle {np.rad2deg(new_eval['mu']):.2f} deg (limit {np.rad2deg(min_transmission):g})",
        "  lengths (m): " + ", ".join(f"{k} {DEFAULTS[k]:.5f} -> {best[k]:.5f}" for k in FLAP_VARS),
        f"  peak in epigraph form over {points} samples; equalities and transmission limits as constraints; "
        f"largest violation {res.violation[res.best]:.2g}",
        res.report(),
    ]
    return FlapDesign(
        params=best, theta_travel=new_eval["travel"], theta_start=new_eval["start"], peak_torque=new_eval["peak"],
        document_peak_torque=doc_eval["peak"], document_theta_travel=doc_eval["travel"],
        improvement=float(improvement), min_transmission=new_eval["mu"], violation=float(res.violation[res.best]),
        points=points, result=res, report="\n".join(lines),
    )


def _flap_measure(points, min_transmission, design):
    """Peak torque, travel, start angle and least transmission angle of one design,
    through the same compiled program as the optimisation (values only)."""
    prog = _flap_program(points, min_transmission)
    v, _, ok = prog.evaluate(jnp.asarray([float(design[k][0]) for k in FLAP_VARS]))
    v = np.asarray(v)
    if not bool(ok):
        raise RuntimeError(f"flap_msd: design {design} cannot be assembled over the stroke")
    n = points
    return {"peak": float(np.max(v[:n])), "start": float(v[n]) + _flap_doc_theta_start(), "travel": float(v[n + 1]) + FLAP_TRAVEL,
            "mu": float(np.arcsin(np.sin(min_transmission) - np.max(v[n + 2:])))}


@functools.cache
def _flap_program(points, min_transmission):
    from jaxmech.design.constrained import program
    from jaxmech.scenes.flap_msd import DEFAULTS

    return program(flap_state(points, min_transmission), FLAP_VARS, jnp.asarray([DEFAULTS[k] for k in FLAP_VARS]))


@functools.cache
def _lbfgs():
    # One object per process: fit's compiled loop is keyed on the optimizer.
    return optax.lbfgs()


# =========================================================================== 2. landing_gear
@dataclasses.dataclass(frozen=True)
class GearDesign:
    """Answer of ``landing_gear`` (m, rad): the fitted ``d``, ``h`` and the engine's
    polished solve of the design equations (``d``, ``h``, ``theta1``)."""

    d: float
    h: float
    theta1: float
    fit_d: float
    fit_h: float
    fit: FitResult
    report: str


def _gear_misfit(cols, p):
    # Dimensionless: (rotation - 90 deg)^2 + (transmission angle at gear-down - 90 deg)^2.
    th = cols["theta[rad]"]
    rot = th[-1] - th[0]
    ta = cols["transmission_angle[rad]"][0]
    return jnp.square(rot - jnp.pi / 2) + jnp.square(ta - jnp.pi / 2)


@functools.cache
def _gear_objective():
    from jaxmech.scenes.landing_gear import SCENE

    # Only the ends of the stroke matter: two samples.
    return scene_figure(SCENE, _gear_misfit, points=2, name="gear misfit")


def landing_gear(*, steps: int = 60) -> GearDesign:
    """Recover the nose gear's ``d`` (B to rod end) and ``h`` (B to cylinder pivot).

    **Problem** (report §3.1): the cylinder runs 1.25 -> 2 ft and the gear must turn
    90 deg, with the cylinder perpendicular to BP at gear-down (the report's hidden right
    angle).

    **Method.**  (1) ``design.fit`` (L-BFGS, 4 starts between 0.5 and 2 ft) minimises
    ``(rotation - 90 deg)^2 + (transmission angle at gear-down - 90 deg)^2``, both from the
    engine's solve of the gear over its stroke (the scene, 2 samples).  (2) The fit's
    answer seeds the engine's Newton solve of the three design equations
    (``scenes.landing_gear.design``), which polishes it to machine precision.

    **Returns** a ``GearDesign`` (m, rad).
    """
    from jaxmech.scenes.landing_gear import FT, design

    starts = {"d": FT * np.array([0.5, 1.0, 0.8, 0.7]), "h": FT * np.array([1.6, 1.5, 2.0, 1.4])}
    bounds = {"d": (0.2 * FT, 1.5 * FT), "h": (0.8 * FT, 3.0 * FT)}
    res = fit(_gear_objective(), starts, bounds=bounds, optimizer=_lbfgs(), steps=steps)
    if res.best < 0:
        raise RuntimeError("landing_gear: no start produced a feasible design\n" + res.report())
    b = res.best_params
    theta1 = float(np.arctan2(1.25 * FT, b["d"]))
    sol = design(guess=(b["d"], b["h"], theta1))
    d, h, th1 = (float(sol[k]) for k in ("d", "h", "theta1"))
    lines = [
        "landing_gear: d and h from the 1.25 -> 2 ft stroke, 90 deg of rotation and the right angle at P",
        f"  fit:    d = {b['d'] / FT:.9f} ft, h = {b['h'] / FT:.9f} ft (misfit {res.value[res.best]:.3g})",
        f"  solve:  d = {d / FT:.12f} ft, h = {h / FT:.12f} ft, theta1 = {np.rad2deg(th1):.8f} deg",
        res.report(),
    ]
    return GearDesign(d=d, h=h, theta1=th1, fit_d=b["d"], fit_h=b["h"], fit=res, report="\n".join(lines))


# =========================================================================== 3. arc_track_flap
ARC_FREE = ("a1", "a2", "alpha0")
ARC_TORQUE_CAP = 1.1  #: cap on the peak raise torque, times the thesis design's


def _arc_sample(p, s34):
    """One stroke sample by the engine's solve from the cosine-rule pose (thesis eqs.
    3.1.1-3.1.2, the flap not translated): ``(q, ok)``, differentiable by the implicit rule."""
    from jaxmech.scenes.arc_track_flap import MECHANISM
    from jaxmech import Status, solve

    a1, a2 = jax.lax.stop_gradient(p["a1"]), jax.lax.stop_gradient(p["a2"])
    s = jax.lax.stop_gradient(s34)
    th12 = jnp.arccos((a1**2 + a2**2 - s**2) / (2 * a1 * a2))
    th13 = jnp.pi - jnp.arccos((a1**2 + s**2 - a2**2) / (2 * a1 * s))
    guess = jnp.stack([th12, th13, 0.0 * th12, 0.0 * th12])
    assembled = jnp.all(jnp.isfinite(guess))
    sol = solve(MECHANISM, s34, p, jnp.where(assembled, guess, 0.0))
    ok = assembled & (sol.status == Status.CONVERGED)
    return jnp.where(ok, sol.q, jnp.where(assembled, guess, 1.0)), ok


@functools.cache
def arc_state(points: int, cap: float):
    """``arc_track_flap`` as stated, for ``jaxmech.design.constrained``: ``x -> Stated`` over
    ``ARC_FREE``: the depth (m, the least ``a1 |sin theta13|`` over the stroke, a one-row
    peak: minimised) and ``le``: the raise torque over the cap at every stroke sample
    (``T_R_i / cap - 1``), the stroke within the screw (``s34_f / a3 - 1``) and
    ``a2 / a1 - 1`` (``a1 > a2``); ``ok``: every sample converged.  Each of the ``points``
    samples (nut travel ``s34_i -> s34_f``) is solved on its own, so the program is small."""
    from jaxmech.design.constrained import Stated
    from jaxmech.scenes.arc_track_flap import SCENE, geometry, quasi_static

    def state(x):
        p = {**_jnp(SCENE.defaults), **x}
        g = geometry(p)
        s34 = g["s34_i"] + (g["s34_f"] - g["s34_i"]) * jnp.linspace(0.0, 1.0, points)
        q, ok = jax.vmap(_arc_sample, (None, 0))(p, s34)
        t_r = quasi_static(q, s34[:, None], p)["T_R"]
        depth = -peak(-p["a1"] * jnp.abs(jnp.sin(q[:, 1])), "argmax")
        le = jnp.concatenate([t_r / cap - 1.0, jnp.stack([g["s34_f"] / p["a3"] - 1.0, p["a2"] / p["a1"] - 1.0])])
        return Stated(peak=jnp.reshape(depth, (1,)), le=le, ok=jnp.all(ok))

    return state


@dataclasses.dataclass(frozen=True)
class FairingDesign:
    """Answer of ``arc_track_flap`` (SI).

    - `params`: every scene parameter of the design; `depth`, `baseline_depth` (m): least
      distance from A0 to the screw line over the stroke; `peak_T_R`, `baseline_peak_T_R`,
      `cap` (N m, per jack); `s34_f` (m) stroke end (<= ``a3``); `violation`: the largest
      constraint violation (relative units).
    """

    params: dict
    depth: float
    baseline_depth: float
    peak_T_R: float
    baseline_peak_T_R: float
    cap: float
    s34_f: float
    violation: float
    result: object
    report: str


def arc_track_flap(*, points: int = 41, maxiter: int = 60, cap_factor: float = ARC_TORQUE_CAP) -> FairingDesign:
    """Shallowest fairing for the arc-track flap (Arslan 2022, cruise loads).

    **Problem.**  Minimise the fairing depth, the least distance from the remote centre A0
    to the screw line over the stroke (the thesis's ``h = a2 cos(beta3/2)`` = 228.89 mm for
    its design), over ``a1``, ``a2``, ``alpha0``, keeping the flap (``b1, c1, beta1..3``,
    rotation 35 deg), the screw (``a3``, thread) and the loads, subject to the thesis's
    validity checks (Section 5.3: ``s34_f <= a3``, ``a1 > a2``; ``c1 < b1`` holds as
    neither is a design variable; the pins stay in their slots over the stroke by
    construction of the collinear design) and ``T_R <= cap_factor x`` the thesis design's
    peak raise torque at every stroke sample.

    **Method.**  Stated as it reads (``arc_state``) and solved by
    ``jaxmech.design.constrained.minimize`` (SLSQP, exact Jacobians by one forward-mode program
    through the position solve) from 3 starts; every constraint met to 1e-8.

    **Returns** a ``FairingDesign``; check it with ``scenes.arc_track_flap.validate``.
    """
    from jaxmech.design.constrained import Program, minimize
    from jaxmech.scenes.arc_track_flap import SCENE

    p0 = dict(SCENE.defaults)
    # The thesis design's figures through the same program (cap 1: le[i] + 1 = T_R_i).
    x_doc = jnp.asarray([p0[k] for k in ARC_FREE])
    probe = _arc_program(points, 1.0)
    v, _, ok0 = probe.evaluate(x_doc)
    if not bool(ok0):
        raise RuntimeError("arc_track_flap: the thesis design does not solve over its stroke")
    v = np.asarray(v)
    depth0, tr0 = float(v[0]), float(np.max(v[1:1 + points]) + 1.0)
    cap = cap_factor * tr0
    starts = {"a1": p0["a1"] * np.array([1.0, 1.03, 0.98]), "a2": p0["a2"] * np.array([1.0, 0.95, 0.97]),
              "alpha0": p0["alpha0"] * np.array([1.0, 0.97, 1.02])}
    bounds = {"a1": (0.8 * p0["a1"], 1.2 * p0["a1"]), "a2": (0.6 * p0["a2"], 1.2 * p0["a2"]),
              "alpha0": (0.8 * p0["alpha0"], 1.2 * p0["alpha0"])}
    # The cap enters only the torque rows, T_R_i / cap - 1 = (row at cap 1 + 1) / cap - 1:
    # rescale the probe's rows instead of compiling a second program.
    scale = np.ones(sum(probe.sizes))
    scale[1:1 + points] = 1.0 / cap
    shift = np.zeros_like(scale)
    shift[1:1 + points] = 1.0 / cap - 1.0

    def evaluate(x):
        val, jac, ok = probe.evaluate(x)
        return np.asarray(val) * scale + shift, np.asarray(jac) * scale[:, None], ok

    prog = Program(probe.names, probe.sizes, evaluate, probe.compile_s)
    res = minimize(arc_state(points, cap), starts, bounds, peak_scale=depth0, maxiter=maxiter, prog=prog)
    if res.best < 0:
        raise RuntimeError("arc_track_flap: no start produced a feasible design\n" + res.report())
    best = {**p0, **res.best_params}
    v, _, _ = probe.evaluate(jnp.asarray([best[k] for k in ARC_FREE]))
    v = np.asarray(v)
    depth, tr, s34_f = float(v[0]), float(np.max(v[1:1 + points]) + 1.0), float((v[1 + points] + 1.0) * best["a3"])
    lines = [
        "arc_track_flap: least fairing depth with the validity checks and "
        f"T_R <= {cap_factor:g} x the thesis's peak",
        f"  thesis: depth {1e3 * depth0:.3f} mm, peak T_R {tr0:.4f} N m (cap {cap:.4f} N m)",
        f"  design: depth {1e3 * depth:.3f} mm ({100 * (1 - depth / depth0):.2f} % shallower), "
        f"peak T_R {tr:.4f} N m, s34_f {1e3 * s34_f:.2f} mm <= a3 {1e3 * best['a3']:.0f} mm",
        "  " + ", ".join(f"{k} {p0[k]:.6g} -> {best[k]:.6g}" for k in ARC_FREE),
        f"  constraints at every one of {points} stroke samples; largest violation {res.violation[res.best]:.2g}",
        res.report(),
    ]
    return FairingDesign(params=best, depth=depth, baseline_depth=depth0, peak_T_R=tr, baseline_peak_T_R=tr0, cap=cap,
                         s34_f=s34_f, violation=float(res.violation[res.best]), result=res, report="\n".join(lines))


@functools.cache
def _arc_program(points, cap):
    from jaxmech.design.constrained import program
    from jaxmech.scenes.arc_track_flap import SCENE

    return program(arc_state(points, cap), ARC_FREE, jnp.asarray([SCENE.defaults[k] for k in ARC_FREE]))


# =========================================================================== 4. identification
def _fourbar_loops(q, u, p):
    from jaxmech.mechanism import cis

    return [p.a * cis(u.theta2) + p.b * cis(q.theta3) - p.c * cis(q.theta4) - p.d]


def _loaded_fourbar():
    from jaxmech.mechanism import Mechanism, cis
    from jaxmech.scenes.classic import FOURBAR

    mech = Mechanism(
        name="loaded_fourbar",
        coords=("theta3", "theta4"),
        inputs=("theta2",),
        params=("a", "b", "c", "d", "m", "k_v", "g"),
        lengths=("a", "b", "c", "d"),
        constraints=_fourbar_loops,
        points={
            "B": lambda q, u, p: p.d + p.c * cis(q.theta4),
            "P": lambda q, u, p: p.a * cis(u.theta2) + 0.5 * p.b * cis(q.theta3),
        },
        branch=lambda q, u, p: jnp.sin(q.theta4 - q.theta3),
    )
    # A point mass m at the coupler's midpoint P, gravity, and a rotary damper on the
    # rocker: moment -k_v theta4_dot (N m), k_v the load coefficient (N m s/rad).
    model = Model(
        mech,
        bodies=(Body("P", mass="m", name="coupler mass"),),
        loads=(Gravity("g"), Moment("theta4", lambda q, u, p, v, t: -p.k_v * v.theta4, name="rocker damper")),
    )

    def outputs(p, mo):
        pj = dict(p)
        tau = jax.vmap(lambda q, u, ud, udd, t: generalized_forces(model, q, u, ud, udd, pj, t)[0][0])(
            mo.q, mo.u, mo.u_dot, mo.u_ddot, mo.t)
        return {"torque": tau}

    scene = Scene(
        name="loaded_fourbar",
        summary="crank-rocker four-bar with a coupler mass and a rocker damper, one turn at 1 rev/s",
        mechanism=mech,
        defaults={**FOURBAR.defaults, "m": 2.0, "k_v": 5.0, "g": 9.81},
        guess=FOURBAR.guess,
        stroke=lambda p: (0.0, 2 * jnp.pi),
        speed=2 * np.pi,
        units={"theta2": "rad", "theta3": "rad", "theta4": "rad"},
        outputs=Outputs(outputs, {"torque": "N m"}),
    )
    return scene, model


#: The identification scene: ``FOURBAR`` (a = 1, b = 3, c = 2.5, d = 3.5 m) with a 2 kg
#: point mass at the coupler midpoint, gravity, and a rocker damper ``k_v`` = 5 N m s/rad,
#: driven at 1 rev/s; output column ``torque[N m]`` (inverse dynamics by virtual power).
LOADED_FOURBAR, LOADED_FOURBAR_MODEL = _loaded_fourbar()

IDENT_UNKNOWN = ("b", "c", "k_v")


@dataclasses.dataclass(frozen=True)
class Identification:
    """Answer of ``identify_fourbar``.

    - `estimate`, `truth`, `stderr`: ``{name: float}``; ``stderr`` from the Gauss-Newton
      covariance ``(J^T J)^{-1}`` of the whitened residuals at the optimum.
    - `covariance`: ``(P, P)`` in ``IDENT_UNKNOWN`` order; `chi2`: ``sum r^2`` at the
      optimum (about ``2N - P`` when the sigmas are right); `n_data`: ``2N``.
    - `iterations`: Levenberg-Marquardt iterations of the winning start.
    """

    estimate: dict
    truth: dict
    stderr: dict
    covariance: np.ndarray
    chi2: float
    n_data: int
    iterations: int
    report: str


def _ident_residual(x, data, sig, points):
    # Whitened residuals r = (model - record) / sigma, rocker angles then crank torques.
    full = {**_jnp(LOADED_FOURBAR.defaults), **dict(zip(IDENT_UNKNOWN, x))}
    cols, status = design_columns(LOADED_FOURBAR, points, full)
    r = jnp.concatenate([(cols["theta4[rad]"] - data[0]) / sig[0], (cols["torque[N m]"] - data[1]) / sig[1]])
    return jnp.where(jnp.all(status == 0), r, jnp.nan)


@functools.partial(jax.jit, static_argnums=(3,))
def _ident_rj(x, data, sig, points):
    # J = dr/dx column by column in forward mode: the positions' tangents come from the
    # implicit function theorem (one linear solve per sample and parameter).
    return _ident_residual(x, data, sig, points), jax.jacfwd(_ident_residual)(x, data, sig, points)


def identify_fourbar(theta4, torque, *, sig_theta: float, sig_torque: float, truth: dict | None = None,
                     starts: dict | None = None, max_iter: int = 50, xtol: float = 1e-10) -> Identification:
    """Identify ``b``, ``c`` (m) and the damper coefficient ``k_v`` (N m s/rad) of
    ``LOADED_FOURBAR`` from records of the rocker angle and the crank torque.

    **Arguments**

    - `theta4`, `torque`: ``(N,)`` records at the scene's ``N`` evenly spaced stroke samples
      (rad, N m), with independent Gaussian noise of standard deviations `sig_theta`,
      `sig_torque`.
    - `truth`: for the report only.  `starts`: ``{name: (S,)}`` (default: 3 starts up to
      30 % off the scene's defaults).  `max_iter`, `xtol`: Levenberg-Marquardt budget and
      relative step tolerance.

    **Method.**  Weighted least squares, ``min sum r^2`` with ``r`` the residuals divided by
    their sigmas, by Levenberg-Marquardt (``(J^T J + mu diag J^T J) dx = -J^T r``) from every
    start; ``J = dr/dp`` by forward-mode implicit differentiation through the stroke solve
    and the virtual-power torque.  The standard errors are those of the Gauss-Newton
    covariance ``(J^T J)^{-1}`` at the optimum (the sigmas are already in ``r``).

    **Returns** an ``Identification``.  **Raises** ``ValueError`` for records of different
    shapes; ``RuntimeError`` if no start converges.
    """
    theta4 = np.asarray(theta4, float)
    torque = np.asarray(torque, float)
    n = theta4.shape[0]
    if theta4.ndim != 1 or torque.shape != (n,):
        raise ValueError(f"identify_fourbar: theta4 and torque must have the same shape (N,), got {theta4.shape}, {torque.shape}")
    if not (sig_theta > 0 and sig_torque > 0):
        raise ValueError(f"identify_fourbar: sig_theta and sig_torque must be positive, got {sig_theta}, {sig_torque}")
    d = LOADED_FOURBAR.defaults
    if starts is None:
        starts = {"b": d["b"] * np.array([1.05, 0.95, 1.08]), "c": d["c"] * np.array([0.95, 1.04, 1.08]),
                  "k_v": d["k_v"] * np.array([1.3, 0.7, 1.1])}
    data = (jnp.asarray(theta4), jnp.asarray(torque))
    sig = jnp.asarray([sig_theta, sig_torque], float)
    best = None
    for i in range(len(starts[IDENT_UNKNOWN[0]])):
        x = np.array([float(starts[k][i]) for k in IDENT_UNKNOWN])
        r, J = (np.asarray(a) for a in _ident_rj(jnp.asarray(x), data, sig, n))
        if not np.all(np.isfinite(r)):
            continue
        mu, it, converged = 1e-3, 0, False
        for it in range(1, max_iter + 1):
            A, g = J.T @ J, J.T @ r
            dx = np.linalg.solve(A + mu * np.diag(np.diag(A)), -g)
            r_new, J_new = (np.asarray(a) for a in _ident_rj(jnp.asarray(x + dx), data, sig, n))
            if np.all(np.isfinite(r_new)) and r_new @ r_new <= r @ r:
                x, r, J, mu = x + dx, r_new, J_new, mu / 3
                if np.all(np.abs(dx) <= xtol * np.abs(x)):
                    converged = True
                    break
            else:
                mu *= 10
        if converged and (best is None or r @ r < best[1] @ best[1]):
            best = (x, r, J, it)
    if best is None:
        raise RuntimeError("identify_fourbar: no start converged")
    x, r, J, it = best
    cov = np.linalg.inv(J.T @ J)
    est = dict(zip(IDENT_UNKNOWN, map(float, x)))
    se = {k: float(np.sqrt(cov[i, i])) for i, k in enumerate(IDENT_UNKNOWN)}
    chi2 = float(r @ r)
    lines = [f"identify_fourbar: {IDENT_UNKNOWN} from {n} rocker angles (sigma {sig_theta:g} rad) and "
             f"{n} crank torques (sigma {sig_torque:g} N m); chi2 = {chi2:.1f} for {2 * n - 3} degrees of freedom; "
             f"Levenberg-Marquardt, {it} iterations"]
    for k in IDENT_UNKNOWN:
        t = "" if truth is None else f"  (true {truth[k]:.6g}: {(est[k] - truth[k]) / se[k]:+.2f} sigma)"
        lines.append(f"  {k} = {est[k]:.8g} +- {se[k]:.3g}{t}")
    return Identification(estimate=est, truth=dict(truth or {}), stderr=se, covariance=cov, chi2=chi2,
                          n_data=2 * n, iterations=it, report="\n".join(lines))
