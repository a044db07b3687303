"""The thesis's case-study figures from the arc-track flap's model: forces over the stroke,
accelerations, the fairing depth and Tables 2 and 3 (see the package docstring)."""

from __future__ import annotations

import math
from collections.abc import Mapping

import jax
import jax.numpy as jnp
import numpy as np

from ...solver.positions import solve_one
from ...solver.status import Status, status_message
from ..base import run_scene
from ...solver.xla import jit
from .model import DEG, MECHANISM, MM, PARAM_NAMES, SCENARIOS, SCENE, initial_pose, quasi_static_one, scene_for, stroke_ends, validate

__all__ = ["params", "forces", "accelerations", "fairing_depth", "table2", "table3"]


# --------------------------------------------------------------------------- user functions
def params(scenario: str = "cruise", **overrides) -> dict:
    """The case study's parameters for ``scenario`` ("cruise" or "landing"), with overrides."""
    return scene_for(scenario).params(**overrides)


_SOLVED_POINTS = ("A", "B", "D", "G", "F")
_CHUNK = 32  # one compiled solve serves every batch size (inputs are padded to chunks)


@jit
def _solve_chunk(s, p):
    """Engine solve (from the closed pose) and quasi-static forces for a chunk of travels."""
    guess = initial_pose(p)

    def one(s_):
        sol = solve_one(MECHANISM, s_[None], p, guess)
        pts = {k: MECHANISM.point(k, sol.q, s_[None], p) for k in _SOLVED_POINTS}
        return sol.q, sol.status, {**quasi_static_one(sol.q, s_[None], p), "points": pts}

    return jax.vmap(one)(s)


def _solve_at(p, s):
    """``(q (N, 4), status (N,), forces)`` at nut travels ``s`` (N,); raises if any fails."""
    MECHANISM.check_params(p)
    pj = {k: jnp.asarray(p[k], float) for k in PARAM_NAMES}
    s = np.atleast_1d(np.asarray(s, float))
    n = s.shape[0]
    pad = np.concatenate([s, np.full((-n % _CHUNK,), s[-1])])
    parts = [_solve_chunk(jnp.asarray(pad[i:i + _CHUNK]), pj) for i in range(0, pad.shape[0], _CHUNK)]
    q, status, out = jax.tree_util.tree_map(lambda *x: np.concatenate([np.asarray(a) for a in x])[:n], *parts)
    bad = np.flatnonzero(np.asarray(status) != Status.CONVERGED)
    if bad.size:
        raise RuntimeError(
            f"arc_track_flap: {bad.size} of {n} poses failed, first at s34 = {float(s[bad[0]]):.6g} m: "
            f"{status_message(status[bad[0]])}"
        )
    return q, status, out


def forces(p: Mapping, s34=None, *, n: int = 101) -> dict:
    """Positions and per-jack forces solved by the engine at nut travels ``s34`` (m).

    ``s34`` defaults to ``n`` points over the stroke.  **Returns** ``s34``, ``theta12``,
    ``theta13``, ``status`` and everything of ``quasi_static`` (arrays ``(N,)``).
    **Raises** ``ValueError`` (``validate``) for a bad design or a travel outside the slots.
    """
    validate(p, s34)
    s = np.linspace(*stroke_ends(p, np)[:2], n) if s34 is None else s34
    s = np.atleast_1d(np.asarray(s, float))
    q, status, out = _solve_at(p, s)
    return dict(s34=s, theta12=q[:, 0], theta13=q[:, 1], status=status, **out)


def accelerations(p: Mapping, *, n: int = 101) -> dict:
    """|a_A|/g and |a_D|/g (fractions) over the stroke at the scene's 35 mm/s nut speed
    (``s34_ddot = 0``), from the engine's implicit second derivatives (``run_scene``).

    **Returns** ``s34`` (m), ``aA_over_g``, ``aD_over_g`` and the ``motion``."""
    res = run_scene(SCENE, n, **p)
    return dict(s34=res.motion.u[:, 0], aA_over_g=res.outputs["aA_over_g"][0],
                aD_over_g=res.outputs["aD_over_g"][0], motion=res.motion)


def fairing_depth(p: Mapping, *, n: int = 201) -> dict:
    """Fairing-depth measures (m).

    - ``h = a2 cos(beta3/2)``: the thesis's saving against a dropped-hinge fairing (which
      reaches A0); it is also the least distance from A0 to the screw line over the stroke
      (``screw_line_distance``, from the engine's poses; reached at both stroke ends).
    - ``y_min``: lowest local y of the mechanism over the stroke (screw tip B, nut A,
      pivot B0, both slot arcs), and ``lowest_part``.
    """
    f = forces(p, n=n)
    pts = f["points"]
    a1, al0 = p["a1"], p["alpha0"]
    B0 = a1 * np.exp(1j * al0)
    e_s = np.exp(1j * (al0 + np.asarray(f["theta13"])))
    ang = np.linspace(0.0, p["beta3"], n)
    parts = {
        "screw tip B": np.min(np.imag(pts["B"])),
        "screw pivot B0": B0.imag,
        "nut A": np.min(np.imag(pts["A"])),
        "b1-slot": np.min(p["b1"] * np.sin(p["beta1"] + ang)),
        "c1-slot": np.min(p["c1"] * np.sin(p["beta1"] + p["beta2"] + ang)),
    }
    parts = {k: float(v) for k, v in parts.items()}
    low = min(parts, key=parts.get)
    return dict(h=p["a2"] * math.cos(p["beta3"] / 2),
                screw_line_distance=float(np.min(np.abs(np.imag(np.conj(e_s) * -B0)))),
                y_min=parts[low], lowest_part=low, parts=parts)


def table2(p: Mapping | None = None) -> dict:
    """Table 2's computed entries in the thesis's units (mm, deg), from the engine's
    closed pose: a3, s34_i, delta_s, g2 = |AD|, p2 = |DG|, q2 = |DF|, alpha2 = angle D A0 A."""
    p = params() if p is None else p
    s34_i, s34_f, _ = (float(x) for x in stroke_ends(p, np))
    pt = {k: complex(v[0]) for k, v in forces(p, s34_i)["points"].items()}
    return dict(a3=p["a3"] / MM, s34_i=s34_i / MM, delta_s=(s34_f - s34_i) / MM,
                g2=abs(pt["D"] - pt["A"]) / MM, p2=abs(pt["D"] - pt["G"]) / MM,
                q2=abs(pt["D"] - pt["F"]) / MM, alpha2=abs(np.angle(pt["D"] / pt["A"])) / DEG)


def table3(p: Mapping | None = None) -> dict:
    """Table 3 from the engine, in the thesis's units (N, N mm), per jack.

    ``{"cruise": {entry: value}, "landing": {entry: (closed, deployed)}}``: cruise at the
    closed flap with ``SCENARIOS["cruise"]``; landing closed with M12_i and deployed with
    M12_f of ``SCENARIOS["landing"]``.  Entries F_input, G12G, G12F, F34y, T_R, T_L.
    NB the thesis prints landing G12G in algebraic min/max order, i.e. (deployed, closed).
    """
    p = params() if p is None else dict(p)
    ends = [float(x) for x in stroke_ends(p, np)[:2]]

    def at(scenario):
        f = forces({**p, **SCENARIOS[scenario]}, jnp.asarray(ends))
        return {k: np.asarray(f[k]) * (1 / MM if k in ("T_R", "T_L") else 1.0)
                for k in ("F_input", "G12G", "G12F", "F34y", "T_R", "T_L")}

    cr, la = at("cruise"), at("landing")
    return {"cruise": {k: float(v[0]) for k, v in cr.items()},
            "landing": {k: (float(v[0]), float(v[1])) for k, v in la.items()}}
