"""Four-bar path synthesis: a coupler point through N target points.

The library function is ``jaxmech.design.synthesize_path`` (free or prescribed crank angles;
closed, open and partial curves; the error is the distance from each target to the coupler
curve, ``jaxmech.design.path_error``; designs that lock or change assembly mode within the
path are infeasible; batched multi-start), for example::

    from jaxmech.design import synthesize_path
    res = synthesize_path(targets, "closed")          # targets: complex (N,)
    print(res.report())

This example keeps the small, direct statement below: the same four-bar through the
engine's position solve (``jaxmech.solve_one``) with its implicit-function Jacobians, fitted
by scipy, used by ``examples/tolerance_study.py`` and ``benchmarks/design.py``.

The classic linkage design task.  Choose the crank pivot ``(x0, y0)``, the ground line's
angle ``phi``, the link lengths ``a`` (crank), ``b`` (coupler), ``c`` (rocker), ``d``
(ground), and the coupler point ``(px, py)`` in the coupler's frame, so that the coupler
point passes through the targets ``T_i``:

- with prescribed crank angles (timing): at absolute crank angle ``alpha_i`` the point
  is at ``T_i``; unknowns the 9 above;
- without: the crank angles are unknowns too (9 + N).

Error measure (both methods, ``rms_error``): the root-mean-square distance between the
coupler point and the targets, ``sqrt(mean_i |P_i - T_i|^2)`` (length units).

**Method.**  Least squares ``min sum_i |P_i - T_i|^2`` by ``scipy.optimize.least_squares``
(trust-region reflective) with the exact Jacobian of the 2N residuals from one compiled
forward-mode program: each sample is the engine's position solve (``jaxmech.solve_one``,
closed-form dyad guess), differentiated by the implicit function theorem.  A trial design
that cannot be assembled at some target gets large residuals, so the trust region shrinks
and the step shortens.  Several starts; the best wins.
"""

from __future__ import annotations

import dataclasses
import functools
import time

import jax
import jax.numpy as jnp
import numpy as np

from jaxmech.mechanism import Mechanism, cis
from jaxmech.positions import solve_one
from jaxmech.status import Status

__all__ = ["GENERAL_FOURBAR", "PARAMS", "pose", "random_starts", "Synthesis", "coupler_points", "rms_error", "synthesize", "target_curve"]

PARAMS = ("x0", "y0", "phi", "a", "b", "c", "d", "px", "py")
FAIL_RESIDUAL = 1e3  #: residual (length units) reported at a target the design cannot reach


def _coupler(q, u, p):
    return p.x0 + 1j * p.y0 + cis(p.phi) * (p.a * cis(u.theta2) + (p.px + 1j * p.py) * cis(q.theta3))


#: A four-bar anywhere in the plane: crank a at (x0, y0), ground d at angle phi, coupler
#: b, rocker c; coupler point (px, py) in the coupler's frame (x along A->B).  Angles
#: theta2..4 from the ground line; the open assembly (sin(theta4 - theta3) > 0).
GENERAL_FOURBAR = Mechanism(
    name="general_fourbar",
    coords=("theta3", "theta4"),
    inputs=("theta2",),
    params=PARAMS,
    lengths=("a", "b", "c", "d", "px", "py", "x0", "y0"),
    signed=("px", "py", "x0", "y0"),
    constraints=lambda q, u, p: [p.a * cis(u.theta2) + p.b * cis(q.theta3) - p.c * cis(q.theta4) - p.d],
    points={"P": _coupler},
    branch=lambda q, u, p: jnp.sin(q.theta4 - q.theta3),
)


def _guess(p, theta2):
    # Open assembly by circle intersection: B on circles about A (radius b) and O4 (c).
    A = p["a"] * jnp.exp(1j * theta2)
    AO = p["d"] - A
    dist = jnp.abs(AO)
    cos_ = (p["b"] ** 2 + dist**2 - p["c"] ** 2) / (2 * p["b"] * dist)
    theta3 = jnp.angle(AO) + jnp.arccos(cos_)  # NaN where the loop cannot close
    B = A + p["b"] * jnp.exp(1j * theta3)
    return jnp.stack([theta3, jnp.angle(B - p["d"])])


def pose(p, theta2):
    """``(q, P, ok)`` at ground-frame crank angle ``theta2`` (rad): ``q = (theta3,
    theta4)`` by the engine's solve (differentiable by the implicit rule), the coupler
    point ``P`` (complex, m), and whether the design assembles there (else placeholders)."""
    g = _guess(jax.lax.stop_gradient(p), theta2)
    assembled = jnp.all(jnp.isfinite(g))
    sol = solve_one(GENERAL_FOURBAR, jnp.reshape(theta2, (1,)), p, jnp.where(assembled, g, 0.0))
    ok = assembled & (sol.status == Status.CONVERGED)
    q = jnp.where(ok, sol.q, 0.0)
    P = GENERAL_FOURBAR.point("P", q, jnp.reshape(theta2, (1,)), p)
    return q, P, ok


def _point(p, theta2):
    _, P, ok = pose(p, theta2)
    return P, ok


def coupler_points(p, alpha):
    """Coupler points ``(N,)`` complex at absolute crank angles ``alpha`` (rad); NaN where
    the design cannot be assembled.  `p`: ``{name: scalar}`` over ``PARAMS``."""
    p = {k: jnp.asarray(v, float) for k, v in p.items()}
    P, ok = jax.vmap(_point, (None, 0))(p, jnp.asarray(alpha) - p["phi"])
    return jnp.where(ok, P, jnp.nan)


def rms_error(points, targets) -> float:
    """``sqrt(mean |P_i - T_i|^2)`` (length units): the error measure of both methods."""
    return float(np.sqrt(np.mean(np.abs(np.asarray(points) - np.asarray(targets)) ** 2)))


def target_curve(kind: str, n: int = 10):
    """``n`` targets (complex, m) and their crank angles (rad) on a test curve.

    - ``"coupler"``: the coupler curve of a known crank-rocker (reachable exactly, with
      timing: the synthesis should find an error near zero);
    - ``"ellipse"``: an ellipse with semi-axes 1.0 and 0.4 m centred at (2, 1), tilted
      20 deg, one turn of the crank per turn of the ellipse (not a coupler curve: the
      least error is positive).
    """
    alpha = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    if kind == "coupler":
        truth = {"x0": 0.0, "y0": 0.0, "phi": 0.1, "a": 1.0, "b": 3.0, "c": 2.5, "d": 3.5, "px": 1.5, "py": 0.8}
        return np.asarray(jax.jit(coupler_points)(truth, alpha)), alpha
    if kind == "ellipse":
        e = 1.0 * np.cos(alpha) + 0.4j * np.sin(alpha)
        return 2.0 + 1.0j + np.exp(1j * np.deg2rad(20)) * e, alpha
    raise ValueError(f"target_curve: kind must be 'coupler' or 'ellipse', got {kind!r}")


@functools.cache
def _program(n: int, timed: bool):
    """One compiled program: ``x -> (residuals (2N,), Jacobian, ok (N,))``."""

    def residual(x, targets, alpha):
        p = dict(zip(PARAMS, x[:9]))
        theta2 = (alpha if timed else x[9:]) - p["phi"]
        P, ok = jax.vmap(_point, (None, 0))(p, theta2)
        r = jnp.where(ok, P - targets, FAIL_RESIDUAL * (1 + 1j))
        return jnp.concatenate([r.real, r.imag]), ok

    def both(x, targets, alpha):
        def with_aux(x_):
            r, ok = residual(x_, targets, alpha)
            return r, (r, ok)

        jac, (r, ok) = jax.jacfwd(with_aux, has_aux=True)(x)
        return r, jnp.where(jnp.concatenate([ok, ok])[:, None], jac, 0.0), ok

    size = 9 + (0 if timed else n)
    t0 = time.perf_counter()
    compiled = jax.jit(both).lower(jnp.zeros(size), jnp.zeros(n, complex), jnp.zeros(n)).compile()
    return compiled, time.perf_counter() - t0


@dataclasses.dataclass(frozen=True)
class Synthesis:
    """Answer of ``synthesize``: `params` (``{name: float}``), `alpha` (rad, the crank angles
    used), `error` (``rms_error``, m), per-start `errors`, `wall_s` (compile included) and
    `compile_s`, `evaluations` (residual + Jacobian calls, all starts), `report`."""

    params: dict
    alpha: np.ndarray
    error: float
    errors: np.ndarray
    wall_s: float
    compile_s: float
    evaluations: int
    report: str


def random_starts(targets, n: int, seed: int = 0) -> np.ndarray:
    """``(n, 9)`` starting designs scaled to the targets' size, around their centroid."""
    rng = np.random.default_rng(seed)
    c = np.mean(targets)
    size = np.max(np.abs(targets - c))
    out = []
    for _ in range(n):
        a = size * rng.uniform(0.3, 0.8)
        b, c_, d = (size * rng.uniform(1.2, 3.0) for _ in range(3))
        out.append([c.real + size * rng.uniform(-1.5, 1.5), c.imag + size * rng.uniform(-1.5, 1.5), rng.uniform(-np.pi, np.pi),
                    a, b, c_, d, size * rng.uniform(-1, 1), size * rng.uniform(-1, 1)])
    return np.array(out)


def synthesize(targets, alpha=None, *, starts: int = 8, seed: int = 0, max_nfev: int = 200, x0=None) -> Synthesis:
    """Four-bar whose coupler point passes through `targets` (complex ``(N,)``, m).

    **Arguments**

    - `alpha`: ``(N,)`` prescribed absolute crank angles (rad), or None to let them free
      (then they start at ``2 pi i / N``).
    - `starts`, `seed`: random starting designs (``random_starts``), or `x0` ``(S, 9)``.
    - `max_nfev`: least-squares budget per start.

    **Returns** a ``Synthesis``.
    """
    from scipy.optimize import least_squares

    targets = np.asarray(targets, complex)
    n = targets.shape[0]
    if targets.ndim != 1 or n < 3:
        raise ValueError(f"synthesize: targets must be (N,) complex points with N >= 3, got shape {targets.shape}")
    timed = alpha is not None
    if timed and np.shape(alpha) != (n,):
        raise ValueError(f"synthesize: alpha must have the targets' shape ({n},), got {np.shape(alpha)}")
    t_start = time.perf_counter()
    misses = _program.cache_info().misses
    prog, compile_s = _program(n, timed)
    compile_s = compile_s if _program.cache_info().misses > misses else 0.0  # compiled by an earlier call
    alpha_j = jnp.asarray(alpha if timed else np.zeros(n))
    tj = jnp.asarray(targets)
    x0 = random_starts(targets, starts, seed) if x0 is None else np.atleast_2d(np.asarray(x0, float))
    evals = [0]
    cache = {}

    def run(x):
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            r, jac, _ = prog(jnp.asarray(x), tj, alpha_j)
            cache[key] = (np.asarray(r), np.asarray(jac))
            evals[0] += 1
        return cache[key]

    lo = np.array([-np.inf, -np.inf, -np.inf, 1e-3, 1e-3, 1e-3, 1e-3, -np.inf, -np.inf] + [-np.inf] * (0 if timed else n))
    results = []
    for s in range(x0.shape[0]):
        xs = x0[s] if timed else np.concatenate([x0[s], np.linspace(0, 2 * np.pi, n, endpoint=False)])
        res = least_squares(lambda x: run(x)[0], xs, jac=lambda x: run(x)[1], method="trf", bounds=(lo, np.inf),
                            max_nfev=max_nfev, xtol=1e-12, ftol=1e-12, gtol=1e-12)
        r = run(res.x)[0]
        err = float(np.sqrt(np.mean(r[:n] ** 2 + r[n:] ** 2)))
        results.append((err, res.x, res.message))
    errors = np.array([r[0] for r in results])
    best = int(np.argmin(errors))
    x = results[best][1]
    params = dict(zip(PARAMS, map(float, x[:9])))
    used = np.asarray(alpha) if timed else x[9:] + 0.0
    wall = time.perf_counter() - t_start
    lines = [f"path synthesis: {n} targets, {'prescribed' if timed else 'free'} crank angles; {len(errors)} starts, "
             f"best rms error {errors[best]:.3g} m (start {best}: {results[best][2]}); {wall:.2f} s ({compile_s:.2f} s compiling)",
             "  " + ", ".join(f"{k} = {v:.6g}" for k, v in params.items()),
             "  per-start rms error (m): " + ", ".join(f"{e:.3g}" for e in errors)]
    return Synthesis(params=params, alpha=used, error=float(errors[best]), errors=errors, wall_s=wall, compile_s=compile_s,
                     evaluations=evals[0], report="\n".join(lines))
