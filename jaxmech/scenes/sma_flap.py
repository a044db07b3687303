"""SMA-actuated hinged flap: quasi-static equilibrium (seed 004_52c3b6aed7b0817f).

Source: "Dynamic modelling of sma-driven flap", P. B. Camara Leal, 2016 (a short note, with no
numbers).  The analysis behind every choice below, with evidence and the chosen parameter set,
is in ``docs/seeds/sma_flap.md``.  ``tests/seeds/reference_sma_flap.py`` is an independent
numpy/scipy implementation that the tests compare against.

**Model.**  Rigid flap segments hinged at ``J1`` (wing to segment 1) and ``J2`` (segment 1 to
segment 2); one hinge locks the two segments into one flap.  Airfoil plane: x aft, y up, SI
units, complex points.  ``theta_j`` is the rotation of body j relative to body j-1,
counter-clockwise positive (theta > 0 lifts the trailing edge).  Each hinge carries an SMA wire
and a linear bias spring.  Each joins a point ``F`` on the body ahead of the hinge to a point
``A`` on the body behind it, and its tension ``T > 0`` pulls A towards F:

- SMA wire, strain-driven (``jaxmech.actuators.SMAWire``, linear branch or a user constitutive
  ``law``): ``T = A_w E (L / (L0 (1 + eps)) - 1)``.  ``E = xi E_M + (1 - xi) E_A``,
  ``eps <= 0`` is the commanded transformation strain, and the wire is slack-clamped at 0.
- SMA wire, force-driven: ``T = F_j`` prescribed.
- Bias spring (``jaxmech.actuators.LinearSpring``): ``T = F_pre + k (L - L0)``.

**Equilibrium** (virtual work, i.e. the moment balance about each hinge of everything behind it):

    R_j(theta) = sum_act T dL/dtheta_j + sum_b m_b g dy_cg,b/dtheta_j = 0,   j = 1..n.

``flap_mechanism`` makes these ``n`` equations the constraints of a ``Mechanism``.  Its
coordinates are the hinge angles and its input is the drive (``eps``, or the wire forces).  So
``jaxmech.solve`` is Newton on the equilibrium, and every derivative of the equilibrium angles
(in the drive and in every parameter) comes from the implicit function theorem.  The stiffness
``dR/dtheta`` is positive definite at a stable equilibrium (output ``stiffness_min``).
``jaxmech run sma_flap`` sweeps eps from 0 to -4 % on one hinge (``SCENE``).  ``SCENE_CHAIN`` is
the two-hinge chain.

**Parameters** (``params(n_hinges)``, from docs/seeds/sma_flap.md): a 0.40 m chord section.
Hinges at x = 0.22 and 0.31 m.  Wires run from (0.06, 0.010) to (0.22, 0.010) m and from
(0.23, 0.008) to (0.31, 0.008) m: NiTi 0.381 mm, E_M = 28 GPa, E_A = 75 GPa.  Springs run from
(0.14, -0.010) to (0.22, -0.010) m (k = 1000 N/m, preload 5 N) and from (0.27, -0.008) to
(0.31, -0.008) m (800 N/m, 3 N).  Masses are 0.06 kg at x = 0.265 m and 0.04 kg at 0.355 m;
one hinge uses 0.10 kg at 0.301 m.

**The document's fixed point** (Algorithm 1, physics corrected) is ``fixed_point``, with its
iterate history.  Its rate about the root is ``1 - V''/(k L_s'^2)`` (``fixed_point_rate``).  It
fails for any realistic wire (rate -20 for E_M, -54 for E_A).  Newton (the engine) converges in
3-5 steps.

**Corrections to the document** (12 in all, with evidence, in ``docs/seeds/sma_flap.md``):

- Eq. 1.3: a1 for a2.  Eqs. 1.1/1.4: r = x_J + T(theta) a - f (the hinge position is missing).
- §1.2, eqs. 1.5-1.9: stretching the actuator does not scale its vector.  The only condition is
  |r(theta)| = eta |r0|, a circle intersection (``rigid_wire_angle``).  Eq. 1.8 has a sign error.
- §1.3, eqs. 1.11-1.14: a tension pulls A towards F.  The weight torque has the wrong sign.
  Moments are taken about the hinge, W is the segment's weight at its CG, and a chain's hinge 1
  carries every segment behind it.
- Eq. 1.16: F = E_M A eps, not (E_M/A) eps.  The bias spring needs a preload: F = F_pre + k (L - L0).
- The strain-driven problem is over-determined as written.  The wire is treated here as elastic
  with a prescribed transformation strain; the rigid limit is ``rigid_wire_angle``.
- Algorithm 1 diverges for realistic stiffness (see above).  Its bookkeeping is incomplete, and
  the model is quasi-static, not dynamic.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ..actuators import LinearSpring, SMAWire
from ..mechanism import Mechanism, Vars
from ..options import SolverOptions
from ..positions import solve
from ..solution import Solution
from .base import Scene
from ..xla import jit

__all__ = [
    "SCENE",
    "params",
    "parameters",
    "flap_mechanism",
    "residual",
    "drive_params",
    "SCENE_CHAIN",
    "stiffness",
    "equilibrium",
    "tensions",
    "rigid_wire_angle",
    "wire_force_for_angle",
    "FixedPoint",
    "fixed_point",
    "fixed_point_rate",
    "newton_history",
    "EPS_RANGE",
]

G = 9.81
EPS_RANGE = (0.0, -0.04)  #: SMA strain sweep of the scene (recoverable strain <= 4 %)


# --------------------------------------------------------------------------- parameters
def _xy(prefix, z):
    return {f"{prefix}_x": float(np.real(z)), f"{prefix}_y": float(np.imag(z))}


def params(n_hinges: int = 2, **overrides) -> dict:
    """The chosen parameter set (SI) of docs/seeds/sma_flap.md, for 1 or 2 hinges.

    Names: hinge ``J{j}_x/_y``; wire ``w{j}F_x/_y`` (on the body ahead), ``w{j}A_x/_y`` (on
    the body behind); spring ``s{j}F_*``, ``s{j}A_*`` with ``k{j}`` (N/m) and ``F_pre{j}`` (N);
    segment mass ``m{b}`` (kg) at ``cg{b}_x/_y``; trailing edge ``TE_x/_y``; wire area ``A_w``
    (m^2), ``E_M``, ``E_A`` (Pa), martensite fraction ``xi`` (1: E = E_M); ``g`` (m/s^2);
    prescribed wire tensions ``F{j}`` (N), used where ``force_driven`` is 1 (0: strain-driven).
    With one hinge the two segments are locked together (0.10 kg at x = 0.301 m).
    """
    _check_n(n_hinges)
    p = {**_xy("J1", 0.22), **_xy("w1F", 0.06 + 0.010j), **_xy("w1A", 0.22 + 0.010j),
         **_xy("s1F", 0.14 - 0.010j), **_xy("s1A", 0.22 - 0.010j), "k1": 1000.0, "F_pre1": 5.0}
    if n_hinges == 2:
        p.update({**_xy("J2", 0.31), **_xy("w2F", 0.23 + 0.008j), **_xy("w2A", 0.31 + 0.008j),
                  **_xy("s2F", 0.27 - 0.008j), **_xy("s2A", 0.31 - 0.008j), "k2": 800.0, "F_pre2": 3.0})
        p.update({"m1": 0.06, "m2": 0.04, **_xy("cg1", 0.265), **_xy("cg2", 0.355)})
    else:
        p.update({"m1": 0.10, **_xy("cg1", (0.06 * 0.265 + 0.04 * 0.355) / 0.10)})
    p.update(_xy("TE", 0.40))
    p.update(A_w=float(np.pi * 0.381e-3**2 / 4), E_M=28e9, E_A=75e9, xi=1.0, g=G)
    p.update({f"F{j}": 0.0 for j in range(1, n_hinges + 1)}, force_driven=0.0)
    unknown = [k for k in overrides if k not in p]
    if unknown:
        raise ValueError(f"sma_flap: unknown parameter(s) {unknown}; parameters are {list(p)}")
    p.update({k: float(v) for k, v in overrides.items()})
    return p


def parameters(n_hinges: int = 2) -> dict:
    """What each parameter of ``params(n_hinges)`` is: ``{name: (SI unit, meaning)}``."""
    _check_n(n_hinges)
    out = {}

    def xy(prefix, what):
        out[f"{prefix}_x"] = ("m", f"{what}, x (chordwise, from the leading edge)")
        out[f"{prefix}_y"] = ("m", f"{what}, y")

    for j in range(1, n_hinges + 1):
        xy(f"J{j}", f"hinge {j}")
        xy(f"w{j}F", f"SMA wire {j}, end on the body ahead of hinge {j}")
        xy(f"w{j}A", f"SMA wire {j}, end on the body behind hinge {j}")
        xy(f"s{j}F", f"bias spring {j}, end on the body ahead")
        xy(f"s{j}A", f"bias spring {j}, end on the body behind")
        out[f"k{j}"] = ("N/m", f"bias spring {j} stiffness")
        out[f"F_pre{j}"] = ("N", f"bias spring {j} preload")
    for b in range(1, n_hinges + 1):
        out[f"m{b}"] = ("kg", f"mass of segment {b}")
        xy(f"cg{b}", f"centre of mass of segment {b}")
    xy("TE", "trailing edge")
    out.update(A_w=("m^2", "SMA wire cross-section"), E_M=("Pa", "martensite Young's modulus"),
               E_A=("Pa", "austenite Young's modulus"), xi=("-", "martensite fraction (1: E = E_M)"),
               g=("m/s^2", "gravity"))
    for j in range(1, n_hinges + 1):
        out[f"F{j}"] = ("N", f"prescribed tension of wire {j} (used when force_driven = 1)")
    out["force_driven"] = ("-", "1: wire tensions F_j drive; 0: the SMA strain drives (the scene)")
    return {k: out[k] for k in params(n_hinges)}


def _check_n(n):
    if n not in (1, 2):
        raise ValueError(f"n_hinges must be 1 or 2, got {n!r}")


def _geometry_names(n):
    names = []
    for j in range(1, n + 1):
        for pt in (f"J{j}", f"w{j}F", f"w{j}A", f"s{j}F", f"s{j}A", f"cg{j}"):
            names += [f"{pt}_x", f"{pt}_y"]
    return tuple(names) + ("TE_x", "TE_y")


def _param_names(n):
    phys = []
    for j in range(1, n + 1):
        phys += [f"k{j}", f"F_pre{j}", f"m{j}"]
    phys += [f"F{j}" for j in range(1, n + 1)]
    return _geometry_names(n) + tuple(phys) + ("A_w", "E_M", "E_A", "xi", "g", "force_driven")


def _z(p, name):
    return jax.lax.complex(jnp.asarray(p[f"{name}_x"], float), jnp.asarray(p[f"{name}_y"], float))


# --------------------------------------------------------------------------- kinematics
def _frames(theta, p, n):
    """``(o_b, rot_b, J_b)`` for bodies b = 0..n: ``z_b(x) = o_b + rot_b (x - J_b)``."""
    zero = jnp.zeros((), theta.dtype)
    fr = [(jax.lax.complex(zero, zero), jax.lax.complex(zero + 1, zero), jax.lax.complex(zero, zero))]
    phi = zero
    for b in range(1, n + 1):
        Jb = _z(p, f"J{b}")
        o, r, Jp = fr[-1]
        phi = phi + theta[b - 1]
        fr.append((o + r * (Jb - Jp), jax.lax.complex(jnp.cos(phi), jnp.sin(phi)), Jb))
    return fr


def _at(fr, b, x):
    o, r, Jb = fr[b]
    return o + r * (x - Jb)


def _actuator_points(fr, p, kind, j):
    # F on body j-1 (ahead of hinge j), A on body j (behind it)
    return _at(fr, j - 1, _z(p, f"{kind}{j}F")), _at(fr, j, _z(p, f"{kind}{j}A"))


def _geometry(theta, p, n):
    """Wire lengths, spring lengths and CG heights, each ``(n,)`` (m), with their gradients
    ``d/dtheta``, each ``(n, n)`` (m/rad; row = element, column = hinge).

    A point of body b turns about hinge k (k <= b): ``dz/dtheta_k = i (z - z_Jk)``.  So an
    actuator's moment arm is ``dL/dtheta_k = Re(conj(e) (dz_A - dz_F))``, with e the unit
    vector F -> A, and ``dy_cg/dtheta_k = Re(z_cg - z_Jk)``.
    """
    fr = _frames(theta, p, n)
    hinges = [fr[k][0] for k in range(1, n + 1)]

    def turn(z, b):  # dz/dtheta_k, k = 1..n, for a point of body b
        return [1j * (z - hinges[k - 1]) if b >= k else 0.0 * z for k in range(1, n + 1)]

    def actuator(kind, j):
        zF, zA = _actuator_points(fr, p, kind, j)
        L = jnp.abs(zA - zF)
        e = (zA - zF) / L
        dA, dF = turn(zA, j), turn(zF, j - 1)
        return L, jnp.stack([jnp.real(jnp.conj(e) * (a - f)) for a, f in zip(dA, dF)])

    wires = [actuator("w", j) for j in range(1, n + 1)]
    springs = [actuator("s", j) for j in range(1, n + 1)]
    cgs = [_at(fr, b, _z(p, f"cg{b}")) for b in range(1, n + 1)]
    ycg = jnp.stack([jnp.imag(z) for z in cgs])
    dy = jnp.stack([jnp.stack([jnp.imag(d) for d in turn(z, b)]) for b, z in enumerate(cgs, start=1)])
    stack = lambda xs: (jnp.stack([x[0] for x in xs]), jnp.stack([x[1] for x in xs]))  # noqa: E731
    (lw, dlw), (ls, dls) = stack(wires), stack(springs)
    return (lw, ls, ycg), (dlw, dls, dy)


def _rest_length(p, kind, j):
    return jnp.abs(_z(p, f"{kind}{j}A") - _z(p, f"{kind}{j}F"))


@functools.lru_cache(maxsize=None)
def _laws(n, law):
    wires = tuple(
        SMAWire(area="A_w", length0=lambda p, j=j: _rest_length(p, "w", j), E_M="E_M", E_A="E_A",
                prestrain="eps", fraction="xi", law=law)
        for j in range(1, n + 1)
    )
    springs = tuple(
        LinearSpring(stiffness=f"k{j}", length0=lambda p, j=j: _rest_length(p, "s", j), preload=f"F_pre{j}")
        for j in range(1, n + 1)
    )
    return wires, springs


def _tensions(theta, eps, p, n, law=None, geo=None):
    (lw, ls, _), _ = _geometry(theta, p, n) if geo is None else geo
    wires, springs = _laws(n, law)
    pe = Vars({**dict(p), "eps": eps})
    sma = jnp.stack([w.tension(lw[i], pe) for i, w in enumerate(wires)])
    given = jnp.stack([jnp.asarray(p[f"F{j}"], sma.dtype) for j in range(1, n + 1)])
    tw = jnp.where(p["force_driven"] > 0.5, given, sma)
    ts = jnp.stack([s.tension(ls[i], p) for i, s in enumerate(springs)])
    return tw, ts


def drive_params(p: Mapping, u, *, n_hinges: int = 2, drive: str = "strain"):
    """``(eps, p')``: the scene's input and parameters for a drive.

    ``drive="strain"``: `u` is the SMA strain ``eps`` (-), shared by every wire.
    ``drive="force"``: `u` holds the wire tensions ``(..., n)`` in N.  They go into ``F{j}``
    with ``force_driven = 1``, and ``eps`` is 0 (unused).
    """
    if drive == "strain":
        return jnp.asarray(u, float), {**dict(p), "force_driven": 0.0}
    if drive != "force":
        raise ValueError(f"drive must be 'strain' or 'force', got {drive!r}")
    u = jnp.asarray(u, float)
    if u.ndim == 0 or u.shape[-1] != n_hinges:
        raise ValueError(f"force-driven: u must have a last axis of {n_hinges} wire tensions (N), got shape {u.shape}")
    return jnp.zeros(u.shape[:-1]), {**dict(p), **{f"F{j}": u[..., j - 1] for j in range(1, n_hinges + 1)},
                                     "force_driven": 1.0}


def residual(theta, eps, p, *, n_hinges: int = 2, law: Callable | None = None):
    """Equilibrium residual ``R_j = dV/dtheta_j`` (N m), zero at equilibrium.

    ``R_j`` is minus the net counter-clockwise moment about hinge j of every force on the bodies
    behind it.

    **Arguments**: `theta` ``(n,)`` hinge angles (rad); `eps` the SMA strain (-); `p`
    parameters (``force_driven`` = 1 uses the wire tensions ``F{j}`` instead, see
    ``drive_params``); `law` an optional SMA constitutive law ``law(strain, p) -> stress (Pa)``.
    """
    n = n_hinges
    theta = jnp.asarray(theta)
    geo = _geometry(theta, p, n)
    dlw, dls, dy = geo[1]
    tw, ts = _tensions(theta, eps, p, n, law, geo)
    m = jnp.stack([jnp.asarray(p[f"m{b}"]) for b in range(1, n + 1)])
    # virtual work: sum of tension x moment arm, plus weight x d(height)
    return tw @ dlw + ts @ dls + (m * p["g"]) @ dy


def stiffness(theta, eps, p, **kw):
    """``dR/dtheta`` (N m/rad), the Hessian of the potential: positive definite = stable."""
    return jax.jacfwd(lambda t: residual(t, eps, p, **kw))(jnp.asarray(theta))


def _min_eig(h):
    if h.shape[0] == 1:
        return h[0, 0]
    a, b, d = h[0, 0], 0.5 * (h[0, 1] + h[1, 0]), h[1, 1]
    return 0.5 * (a + d) - jnp.sqrt(0.25 * (a - d) ** 2 + b * b)


@functools.lru_cache(maxsize=None)
def flap_mechanism(n_hinges: int = 2, law: Callable | None = None) -> Mechanism:
    """The equilibrium as a ``Mechanism``: coordinates ``theta1[, theta2]`` (rad), input ``eps``
    (SMA strain, -), constraints ``R_j = 0`` (N m).  The force-driven case is the same mechanism
    with ``force_driven = 1`` and the wire tensions in ``F{j}`` (see ``drive_params``).

    Geometry parameters are lengths in m; any sign is allowed.  Newton finds stable and
    unstable equilibria alike: check ``stiffness`` (positive definite = stable).  No branch
    indicator is set, which keeps the compiled solve small.
    """
    _check_n(n_hinges)
    n = n_hinges
    coords = tuple(f"theta{j}" for j in range(1, n + 1))
    geo = _geometry_names(n)

    def eqs(q, u, p):
        th = jnp.stack([q[c] for c in coords])
        r = residual(th, u.eps, p, n_hinges=n, law=law)
        return [r[j] for j in range(n)]

    def pts():
        def mk(fn):
            return lambda q, u, p: fn(_frames(jnp.stack([q[c] for c in coords]), p, n), p)

        out = {"LE": mk(lambda fr, p: 0.0 * _z(p, "J1")), "TE": mk(lambda fr, p: _at(fr, n, _z(p, "TE")))}
        for j in range(1, n + 1):
            out[f"J{j}"] = mk(lambda fr, p, j=j: fr[j][0])
            out[f"CG{j}"] = mk(lambda fr, p, j=j: _at(fr, j, _z(p, f"cg{j}")))
            for kind in ("w", "s"):
                out[f"{kind}{j}F"] = mk(lambda fr, p, j=j, kind=kind: _actuator_points(fr, p, kind, j)[0])
                out[f"{kind}{j}A"] = mk(lambda fr, p, j=j, kind=kind: _actuator_points(fr, p, kind, j)[1])
        return out

    return Mechanism(
        name=f"sma_flap_{n}hinge",
        coords=coords,
        inputs=("eps",),
        params=_param_names(n),
        constraints=eqs,
        lengths=geo,
        signed=geo,
        points=pts(),
    )


def equilibrium(p: Mapping, u, *, n_hinges: int = 2, drive: str = "strain", guess=None, law=None,
                options: SolverOptions = SolverOptions(), throw: bool = False) -> Solution:
    """Equilibrium hinge angles by the engine's Newton solve, batched over `u` and `p`.

    **Arguments**: `u` is the SMA strain ``eps`` (``(...)``, strain-driven) or the wire
    tensions ``(..., n)`` in N (force-driven).  `guess` is ``(..., n)`` rad (default 0, the
    undeflected flap).  **Returns** a ``Solution``.  ``sol["theta1"]`` is differentiable in
    `u` and in every parameter (implicit function theorem).  For stability, check
    ``stiffness`` at the solution.
    """
    mech = flap_mechanism(n_hinges, law)
    eps, pp = drive_params(p, u, n_hinges=n_hinges, drive=drive)
    guess = jnp.zeros(n_hinges) if guess is None else guess
    return solve(mech, eps, pp, guess, options=options, throw=throw)


def tensions(theta, u, p, *, n_hinges=2, drive="strain", law=None):
    """``(wire tensions (n,), spring tensions (n,))`` in N at the hinge angles `theta`."""
    eps, pp = drive_params(p, u, n_hinges=n_hinges, drive=drive)
    return _tensions(jnp.asarray(theta), eps, pp, n_hinges, law)


def wire_force_for_angle(theta, p, *, n_hinges=1):
    """One hinge: the wire tension (N) that holds the flap at `theta`.  This is the document's
    force-driven formula, corrected: ``F_s = -(T_s L_s' + W y_cg') / L_w'``."""
    th = jnp.atleast_1d(jnp.asarray(theta, float))
    eps, pp = drive_params(p, jnp.zeros(n_hinges), n_hinges=n_hinges, drive="force")
    r0 = residual(th, eps, pp, n_hinges=n_hinges)
    dlw = _geometry(th, p, n_hinges)[1][0]
    return -r0[0] / dlw[0, 0]


def _circle_angle(L, a, g, near):
    """Angle t with ``|a e^{it} - g| = L`` nearest `near`, or NaN if out of reach (eq. 1.7, corrected)."""
    w = a * jnp.conj(g)
    C = (jnp.abs(a) ** 2 + jnp.abs(g) ** 2 - L**2) / 2
    reach = jnp.abs(C) <= jnp.abs(w)
    half = jnp.arccos(jnp.clip(C / jnp.abs(w), -1.0, 1.0))
    cands = jnp.stack([-jnp.angle(w) + half, -jnp.angle(w) - half])
    cands = jnp.mod(cands + jnp.pi, 2 * jnp.pi) - jnp.pi
    best = cands[jnp.argmin(jnp.abs(cands - near))]
    return jnp.where(reach, best, jnp.nan)


def rigid_wire_angle(eps, p, j: int = 1, near=0.0):
    """Rigid-wire limit (E -> inf) of the strain-driven case: the hinge angle at which wire j has
    length ``L0 (1 + eps)``.  This is the corrected §1.2 inverse solution (a circle intersection
    in the hinge frame; the branch nearest `near`).  NaN when that length is out of reach."""
    J = _z(p, f"J{j}")
    a, g = _z(p, f"w{j}A") - J, _z(p, f"w{j}F") - J
    return _circle_angle(_rest_length(p, "w", j) * (1.0 + eps), a, g, near)


# --------------------------------------------------------------------------- the document's fixed point
@dataclasses.dataclass(frozen=True)
class FixedPoint:
    """Result of ``fixed_point``: `theta` (rad), `iterations`, `status` (``"converged"``,
    ``"diverged"``, ``"unreachable"``, ``"2-cycle"`` or ``"maxit"``), `history` (iterates,
    ``(k+1, n)`` rad) and `amplitude` (half the 2-cycle swing, rad; NaN otherwise)."""

    theta: np.ndarray
    iterations: int
    status: str
    history: np.ndarray
    amplitude: np.ndarray


@functools.partial(jit, static_argnums=(3, 4))
def _fp_step(theta, eps, p, n, law):
    # Algorithm 1 (corrected physics), Jacobi sweep over the hinges: the spring tension that
    # balances hinge j at theta^k (eq. 1.15) -> spring length -> theta_j^{k+1} from the spring's
    # inverse kinematics (eq. 1.7 as a circle intersection).
    R = residual(theta, eps, p, n_hinges=n, law=law)
    _, ts = _tensions(theta, eps, p, n, law)
    dls = _geometry(theta, p, n)[1][1]
    new = []
    for j in range(1, n + 1):
        d = dls[j - 1, j - 1]
        t_need = -(R[j - 1] - ts[j - 1] * d) / d
        L_need = _rest_length(p, "s", j) + (t_need - p[f"F_pre{j}"]) / p[f"k{j}"]
        J = _z(p, f"J{j}")
        new.append(_circle_angle(L_need, _z(p, f"s{j}A") - J, _z(p, f"s{j}F") - J, theta[j - 1]))
    return jnp.stack(new)


def fixed_point(p: Mapping, u, *, n_hinges: int = 2, drive: str = "strain", theta0=None, tol: float = 1e-10,
                maxit: int = 200, blowup: float = np.pi, law=None) -> FixedPoint:
    """The document's Algorithm 1 (with its physics corrected), with its iterate history.

    Each iteration takes, for every hinge, the spring tension that balances the moment at the
    current angles (eq. 1.15).  That gives a spring length, and eq. 1.7 (a circle
    intersection) gives the new angle.  The iteration stops when the step is below `tol` (rad),
    an angle exceeds `blowup`, or the spring length asked for is out of the linkage's reach.
    """
    th = np.zeros(n_hinges) if theta0 is None else np.asarray(theta0, float)
    eps, pp = drive_params(p, u, n_hinges=n_hinges, drive=drive)
    pj = {k: jnp.asarray(v, float) for k, v in pp.items()}
    hist = [th.copy()]
    nan = np.full(n_hinges, np.nan)
    for it in range(1, maxit + 1):
        new = np.asarray(_fp_step(jnp.asarray(th), eps, pj, n_hinges, law))
        hist.append(new.copy())
        if np.any(np.isnan(new)):
            return FixedPoint(new, it, "unreachable", np.array(hist), nan)
        if np.any(np.abs(new) > blowup):
            return FixedPoint(new, it, "diverged", np.array(hist), nan)
        if np.max(np.abs(new - th)) < tol:
            return FixedPoint(new, it, "converged", np.array(hist), nan)
        th = new
    H = np.array(hist)
    if np.max(np.abs(H[-1] - H[-3])) < 1e-8 and np.max(np.abs(H[-1] - H[-2])) > 1e-6:
        return FixedPoint(th, maxit, "2-cycle", H, np.abs(H[-1] - H[-2]) / 2)
    return FixedPoint(th, maxit, "maxit", H, nan)


@functools.partial(jit, static_argnums=(3, 4))
def _rate_parts(th, eps, p, n, law):
    return stiffness(th, eps, p, n_hinges=n, law=law), _geometry(th, p, n)[1][1]


def fixed_point_rate(p: Mapping, u, theta_star, *, n_hinges=2, drive="strain", law=None):
    """Linear rate of Algorithm 1 about the root: eigenvalues of ``I - D^-1 H`` with
    ``D = diag(k_j (dL_spring,j/dtheta_j)^2)`` and H the stiffness.  Returns
    ``(eigenvalues, spectral radius)``; the scheme converges only if the radius is below 1.
    For one hinge the eigenvalue is ``1 - V''/(k L_s'^2)``."""
    th = jnp.atleast_1d(jnp.asarray(theta_star, float))
    eps, pp = drive_params(p, u, n_hinges=n_hinges, drive=drive)
    H, dls = (np.asarray(x) for x in _rate_parts(th, eps, {k: jnp.asarray(v, float) for k, v in pp.items()}, n_hinges, law))
    D = np.diag([float(p[f"k{j}"]) * dls[j - 1, j - 1] ** 2 for j in range(1, n_hinges + 1)])
    ev = np.linalg.eigvals(np.eye(n_hinges) - np.linalg.solve(D, 0.5 * (H + H.T)))
    return ev, float(np.max(np.abs(ev)))


def newton_history(p: Mapping, u, *, n_hinges=2, drive="strain", theta0=None, tol=1e-13, maxit=20, law=None):
    """Plain Newton on the same residual (the engine's ``solve`` adds damping and statuses).
    Returns ``(theta, max |R| per iterate (N m))``: quadratic convergence, for comparison with
    ``fixed_point``."""
    th = jnp.zeros(n_hinges) if theta0 is None else jnp.asarray(theta0, float)
    eps, pp = drive_params(p, u, n_hinges=n_hinges, drive=drive)
    f = jit(lambda t, e, q: (residual(t, e, q, n_hinges=n_hinges, law=law), stiffness(t, e, q, n_hinges=n_hinges, law=law)))
    hist = []
    for _ in range(maxit + 1):
        R, H = f(th, eps, pp)
        hist.append(float(jnp.max(jnp.abs(R))))
        if hist[-1] < tol:
            break
        th = th - jnp.linalg.solve(H, R)
    return np.asarray(th), hist


# --------------------------------------------------------------------------- the scene
@functools.partial(jit, static_argnums=(0,))
def _outputs_batch(n, p, q, eps):
    def one(th, e):
        tw, ts = _tensions(th, e, p, n)
        return tw, ts, _min_eig(stiffness(th, e, p, n_hinges=n))

    ok = jnp.all(jnp.isfinite(q), axis=-1)
    tw, ts, kmin = jax.vmap(one)(jnp.where(ok[:, None], q, 0.0), eps)
    rigid = jnp.stack([jax.vmap(lambda e, j=j: rigid_wire_angle(e, p, j))(eps) for j in range(1, n + 1)], axis=-1)
    bad = lambda x: jnp.where(ok.reshape(ok.shape + (1,) * (x.ndim - 1)), x, jnp.nan)  # noqa: E731
    return bad(tw), bad(ts), bad(kmin), rigid


def _outputs(p, mo):
    n = mo.q.shape[-1]
    pj = {k: jnp.asarray(v, mo.q.dtype) for k, v in p.items()}
    tw, ts, kmin, rigid = _outputs_batch(n, pj, mo.q, mo.u[:, 0])
    out = {}
    for j in range(n):
        out[f"theta{j + 1}_deg"] = (jnp.degrees(mo.q[:, j]), "deg")
        out[f"theta{j + 1}_rigid"] = (rigid[:, j], "rad")
        out[f"wire{j + 1}_tension"] = (tw[:, j], "N")
        out[f"wire{j + 1}_stress"] = (tw[:, j] / p["A_w"], "Pa")
        out[f"spring{j + 1}_tension"] = (ts[:, j], "N")
    out["stiffness_min"] = (kmin, "N m/rad")
    return out


def _drawing(p):
    n = 2 if "J2_x" in p else 1
    chords = [("LE", "J1"), ("J1", "J2"), ("J2", "TE")] if n == 2 else [("LE", "J1"), ("J1", "TE")]
    links = []
    for j in range(1, n + 1):
        links += [(f"w{j}F", f"w{j}A"), (f"s{j}F", f"s{j}A"), (f"J{j}", f"w{j}A"), (f"J{j}", f"s{j}A")]
    return {"chords": chords, "links": links, "ground": ["J1", "w1F", "s1F"], "slots": [], "trace": ["TE"],
            "output": f"theta{n}"}


def _validate(p):
    n = 2 if "J2_x" in p else 1
    for j in range(1, n + 1):
        if p[f"k{j}"] < 0:
            raise ValueError(f"spring stiffness k{j} must be >= 0 N/m, got {p[f'k{j}']}")
        if p[f"m{j}"] < 0:
            raise ValueError(f"segment mass m{j} must be >= 0 kg, got {p[f'm{j}']}")
    for name in ("A_w", "E_M", "E_A"):
        if p[name] <= 0:
            raise ValueError(f"{name} must be positive, got {p[name]}")
    if not 0.0 <= p["xi"] <= 1.0:
        raise ValueError(f"martensite fraction xi must lie in [0, 1], got {p['xi']}")
    if p["force_driven"] != 0.0:
        raise ValueError("the sma_flap scene sweeps the SMA strain: keep force_driven = 0 "
                         "(use equilibrium(..., drive='force') for the force-driven case)")


def _scene(n, name, summary):
    return Scene(
        name=name,
        summary=summary,
        mechanism=flap_mechanism(n),
        defaults=params(n),
        parameters=parameters(n),
        guess=lambda p: jnp.zeros(n),
        stroke=lambda p: EPS_RANGE,
        speed=0.01,
        units={"eps": "-", **{f"theta{j}": "rad" for j in range(1, n + 1)}},
        outputs=_outputs,
        validate=_validate,
        drawing=_drawing,
        document="P. B. Camara Leal, 'Dynamic modelling of sma-driven flap', note, February 19, 2016; corrections in docs/seeds/sma_flap.md",
    )


#: ``jaxmech run sma_flap``: one hinge (the two segments locked), the SMA strain swept from 0 to
#: -4 % at 1 %/s.  The coordinate is the equilibrium angle ``theta1``; ``theta1_dot`` is
#: ``d theta1/d eps`` times the sweep rate (implicit function theorem).
SCENE = _scene(1, "sma_flap", "SMA-wire flap (one hinge) against a bias spring and weight: equilibrium over SMA strain 0 -> -4 %")

#: The chain of two hinges, the same sweep (same eps on both wires).  It is not registered: its
#: compiled stroke takes about 30 s, against about 10 s for one hinge.
SCENE_CHAIN = _scene(2, "sma_flap_chain", "SMA-wire flap, chain of two hinges: equilibrium over SMA strain 0 -> -4 %")
