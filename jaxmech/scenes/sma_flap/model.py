"""The SMA flap's model: parameters, hinge kinematics, wire and spring laws, the
equilibrium mechanism and the scenes (see the package docstring)."""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ...actuators import LinearSpring, SMAWire
from ...mechanism.mechanism import Mechanism, Vars
from ...solver.options import SolverOptions
from ...solver.positions import solve
from ...solver.solution import Solution
from ..base import Scene
from ..outputs import Outputs
from ...solver.xla import jit

__all__ = ["SCENE", "params", "parameters", "flap_mechanism", "residual", "drive_params", "SCENE_CHAIN", "stiffness", "equilibrium", "tensions", "rigid_wire_angle", "wire_force_for_angle", "EPS_RANGE", "output_units"]


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


def point_z(p, name):
    """Point ``name`` of the parameters (``name_x``, ``name_y``) as ``x + i y`` (m)."""
    return jax.lax.complex(jnp.asarray(p[f"{name}_x"], float), jnp.asarray(p[f"{name}_y"], float))


# --------------------------------------------------------------------------- kinematics
def _frames(theta, p, n):
    """``(o_b, rot_b, J_b)`` for bodies b = 0..n: ``z_b(x) = o_b + rot_b (x - J_b)``."""
    zero = jnp.zeros((), theta.dtype)
    fr = [(jax.lax.complex(zero, zero), jax.lax.complex(zero + 1, zero), jax.lax.complex(zero, zero))]
    phi = zero
    for b in range(1, n + 1):
        Jb = point_z(p, f"J{b}")
        o, r, Jp = fr[-1]
        phi = phi + theta[b - 1]
        fr.append((o + r * (Jb - Jp), jax.lax.complex(jnp.cos(phi), jnp.sin(phi)), Jb))
    return fr


def _at(fr, b, x):
    o, r, Jb = fr[b]
    return o + r * (x - Jb)


def _actuator_points(fr, p, kind, j):
    # F on body j-1 (ahead of hinge j), A on body j (behind it)
    return _at(fr, j - 1, point_z(p, f"{kind}{j}F")), _at(fr, j, point_z(p, f"{kind}{j}A"))


def hinge_geometry(theta, p, n):
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
    cgs = [_at(fr, b, point_z(p, f"cg{b}")) for b in range(1, n + 1)]
    ycg = jnp.stack([jnp.imag(z) for z in cgs])
    dy = jnp.stack([jnp.stack([jnp.imag(d) for d in turn(z, b)]) for b, z in enumerate(cgs, start=1)])
    stack = lambda xs: (jnp.stack([x[0] for x in xs]), jnp.stack([x[1] for x in xs]))  # noqa: E731
    (lw, dlw), (ls, dls) = stack(wires), stack(springs)
    return (lw, ls, ycg), (dlw, dls, dy)


def rest_length(p, kind, j):
    """Length (m) of element ``kind`` (``"w"`` wire, ``"s"`` spring) of hinge ``j`` as built."""
    return jnp.abs(point_z(p, f"{kind}{j}A") - point_z(p, f"{kind}{j}F"))


@functools.lru_cache(maxsize=None)
def _laws(n, law):
    wires = tuple(
        SMAWire(area="A_w", length0=lambda p, j=j: rest_length(p, "w", j), E_M="E_M", E_A="E_A",
                prestrain="eps", fraction="xi", law=law)
        for j in range(1, n + 1)
    )
    springs = tuple(
        LinearSpring(stiffness=f"k{j}", length0=lambda p, j=j: rest_length(p, "s", j), preload=f"F_pre{j}")
        for j in range(1, n + 1)
    )
    return wires, springs


def wire_tensions(theta, eps, p, n, law=None, geo=None):
    (lw, ls, _), _ = hinge_geometry(theta, p, n) if geo is None else geo
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
    geo = hinge_geometry(theta, p, n)
    dlw, dls, dy = geo[1]
    tw, ts = wire_tensions(theta, eps, p, n, law, geo)
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

        out = {"LE": mk(lambda fr, p: 0.0 * point_z(p, "J1")), "TE": mk(lambda fr, p: _at(fr, n, point_z(p, "TE")))}
        for j in range(1, n + 1):
            out[f"J{j}"] = mk(lambda fr, p, j=j: fr[j][0])
            out[f"CG{j}"] = mk(lambda fr, p, j=j: _at(fr, j, point_z(p, f"cg{j}")))
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
    return wire_tensions(jnp.asarray(theta), eps, pp, n_hinges, law)


def wire_force_for_angle(theta, p, *, n_hinges=1):
    """One hinge: the wire tension (N) that holds the flap at `theta`.  This is the document's
    force-driven formula, corrected: ``F_s = -(T_s L_s' + W y_cg') / L_w'``."""
    th = jnp.atleast_1d(jnp.asarray(theta, float))
    eps, pp = drive_params(p, jnp.zeros(n_hinges), n_hinges=n_hinges, drive="force")
    r0 = residual(th, eps, pp, n_hinges=n_hinges)
    dlw = hinge_geometry(th, p, n_hinges)[1][0]
    return -r0[0] / dlw[0, 0]


def circle_angle(L, a, g, near):
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
    J = point_z(p, f"J{j}")
    a, g = point_z(p, f"w{j}A") - J, point_z(p, f"w{j}F") - J
    return circle_angle(rest_length(p, "w", j) * (1.0 + eps), a, g, near)


# --------------------------------------------------------------------------- the scene
class HingeOutputs(NamedTuple):
    """Per sample and hinge (``_outputs_batch``): wire tensions `wire` and spring tensions
    `spring` (N), NaN where the sample failed; the least eigenvalue of the stiffness
    `stiffness_min` (N m/rad); each hinge's rigid-wire angle `rigid` (rad)."""

    wire: jax.Array
    spring: jax.Array
    stiffness_min: jax.Array
    rigid: jax.Array


@functools.partial(jit, static_argnums=(0,))
def _outputs_batch(n, p, q, eps) -> HingeOutputs:
    def one(th, e):
        tw, ts = wire_tensions(th, e, p, n)
        return tw, ts, _min_eig(stiffness(th, e, p, n_hinges=n))

    ok = jnp.all(jnp.isfinite(q), axis=-1)
    tw, ts, kmin = jax.vmap(one)(jnp.where(ok[:, None], q, 0.0), eps)
    rigid = jnp.stack([jax.vmap(lambda e, j=j: rigid_wire_angle(e, p, j))(eps) for j in range(1, n + 1)], axis=-1)
    bad = lambda x: jnp.where(ok.reshape(ok.shape + (1,) * (x.ndim - 1)), x, jnp.nan)  # noqa: E731
    return HingeOutputs(bad(tw), bad(ts), bad(kmin), rigid)


def _outputs(p, mo):
    n = mo.q.shape[-1]
    pj = {k: jnp.asarray(v, mo.q.dtype) for k, v in p.items()}
    tw, ts, kmin, rigid = _outputs_batch(n, pj, mo.q, mo.u[:, 0])
    out = {}
    for j in range(n):
        out[f"theta{j + 1}_deg"] = jnp.degrees(mo.q[:, j])
        out[f"theta{j + 1}_rigid"] = rigid[:, j]
        out[f"wire{j + 1}_tension"] = tw[:, j]
        out[f"wire{j + 1}_stress"] = tw[:, j] / p["A_w"]
        out[f"spring{j + 1}_tension"] = ts[:, j]
    out["stiffness_min"] = kmin
    return out


def output_units(n: int) -> dict[str, str]:
    """The outputs of the scene of `n` hinges: their units, in column order."""
    per_hinge = {"theta{}_deg": "deg", "theta{}_rigid": "rad", "wire{}_tension": "N", "wire{}_stress": "Pa",
                 "spring{}_tension": "N"}
    return {**{k.format(j): u for j in range(1, n + 1) for k, u in per_hinge.items()}, "stiffness_min": "N m/rad"}


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
        outputs=Outputs(_outputs, output_units(n)),
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
