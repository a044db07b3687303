"""Starting designs for four-bar path synthesis, in numpy: random four-bar shapes placed
on the targets by the best similarity (rotation, scale, translation; closed form), crank
angles spread by arc length, then refined by closest-point iterations
(``placed_starts``; the method is described in ``jaxmech.design.synthesis``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .coupler_path import TAU, crank_interval, local_point

__all__ = ["placed_starts", "Starts", "GRID", "arc_indices"]


# =========================================================================== starts (numpy)
def _arc_fractions(targets, closed: bool):
    seg = np.abs(np.diff(targets))
    if closed:
        seg = np.append(seg, np.abs(targets[0] - targets[-1]))
        total = np.sum(seg)
        return np.concatenate([[0.0], np.cumsum(seg[:-1])]) / max(total, 1e-300)
    total = np.sum(seg)
    return np.concatenate([[0.0], np.cumsum(seg)]) / max(total, 1e-300)


def _random_shapes(rng, m, rotatable_fraction, cmu):
    """``m`` random four-bar shapes with ground ``d = 1``: ``(a, b, c, px, py)``; a fraction
    with a crank that turns fully (with the transmission margin `cmu`), the rest with some
    usable crank interval."""
    out = []
    need_rot = int(round(m * rotatable_fraction))
    got_rot, got_any = 0, 0
    for _ in range(200):
        if got_rot >= need_rot and got_any >= m - need_rot:
            break
        k = 4 * m
        a = np.exp(rng.uniform(np.log(0.08), np.log(2.5), k))
        b = np.exp(rng.uniform(np.log(0.2), np.log(4.0), k))
        c = np.exp(rng.uniform(np.log(0.2), np.log(4.0), k))
        rho = np.exp(rng.uniform(np.log(0.05), np.log(4.0), k)) * np.maximum(b, 1.0)
        ang = rng.uniform(-np.pi, np.pi, k)
        px, py = rho * np.cos(ang), rho * np.sin(ang)
        full, _, half, _, closes = crank_interval(a, b, c, 1.0, cmu)
        rot = np.flatnonzero(full)[: need_rot - got_rot]
        other = np.flatnonzero(~full & closes & (half > 0.05))[: m - need_rot - got_any]
        for idx in (rot, other):
            out.extend(zip(a[idx], b[idx], c[idx], px[idx], py[idx]))
        got_rot, got_any = got_rot + rot.size, got_any + other.size
    return np.array(out).reshape(-1, 5)


GRID = 128  #: samples per random shape's coupler curve when placing it on the targets
ARC_TARGETS = 12  #: targets (evenly spread along the list) an arc-length placement is scored on
ARC_LEVELS = 1024  #: steps of arc length (a curve's whole) at which ``arc_indices`` tabulates its nearest sample


class Starts(NamedTuple):
    """Best-placed starts (``placed_starts``), in the normalised frame; unpacks like the
    4-tuple it replaces."""

    x: np.ndarray  # (keep, 9) designs (x0, y0, phi, log a, log b, log c, log d, px, py)
    theta: np.ndarray  # (keep, n) each target's crank angle (rad, from the ground line)
    mode: np.ndarray  # (keep,) assembly modes
    cost: np.ndarray  # (keep,) placement's sum of squared distances


class ShapeGrid(NamedTuple):
    """Random four-bar shapes (ground ``d = 1``) and each one's sampled crank interval
    ``[lo, lo + width)``: ``grid`` ``(m, GRID)`` crank angles (rad); `full`: the crank
    turns fully."""

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    px: np.ndarray
    py: np.ndarray
    full: np.ndarray
    lo: np.ndarray
    width: np.ndarray
    grid: np.ndarray


class Placement(NamedTuple):
    """One assembly mode's placements of every shape (``placement_costs``): `cost`
    ``(m, P)`` of the best similarity ``T ~ z C + w`` (inf where a placement leaves the
    interval or degenerates), `z`, `w` ``(m, P)`` complex, the `mode`, and the shapes'
    sampled coupler curves `curve` ``(m, GRID)`` (NaN where the loop does not close)."""

    cost: np.ndarray
    z: np.ndarray
    w: np.ndarray
    mode: float
    curve: np.ndarray


def shape_grid(rng, n_shapes, rotatable_fraction, cmu) -> ShapeGrid:
    """`n_shapes` random shapes (``_random_shapes``), each with its crank interval sampled at
    ``GRID`` angles (a whole turn, or one of its usable intervals, the mirror one chosen at
    random half the time)."""
    shapes = _random_shapes(rng, n_shapes, rotatable_fraction, cmu)
    a, b, c, px, py = (shapes[:, i] for i in range(5))
    m = a.size
    full, center, half, two, _ = crank_interval(a, b, c, 1.0, cmu)
    mirror = two & (rng.uniform(size=m) < 0.5)
    lo = np.where(full, -np.pi, np.where(mirror, -center, center) - half)
    width = np.where(full, TAU, 2 * half)
    g = np.arange(GRID)
    grid = lo[:, None] + width[:, None] * np.where(full[:, None], g / GRID, (g + 0.5) / GRID)  # (m, GRID)
    return ShapeGrid(a, b, c, px, py, full, lo, width, grid)


def placement_positions(sg: ShapeGrid, targets_n, alpha, closed: bool, rng):
    """``(U, phis)``: the targets' positions ``U (m, P, n)`` in ``[0, 1)`` along each shape's
    interval, for P placements: with prescribed crank angles, 8 random ground angles `phis`
    ``(m, 8)``; for a closed curve, 12 phases in both directions spread by arc length;
    otherwise 3 spans at 3 offsets in both directions (`phis` None)."""
    n, m = targets_n.size, sg.a.size
    frac = _arc_fractions(targets_n, closed)
    us, phis = [], None
    if alpha is not None:
        phis = rng.uniform(-np.pi, np.pi, (m, 8))
        u = (alpha[None, None, :] - phis[:, :, None] - sg.lo[:, None, None]) / sg.width[:, None, None]
        u = np.where(sg.full[:, None, None], np.mod(u, 1.0), u)
        return u, phis
    if closed:
        for ph in np.linspace(0, 1, 12, endpoint=False):
            for sgn in (1.0, -1.0):
                us.append(np.broadcast_to(np.mod(ph + sgn * frac, 1.0), (m, n)))
    else:
        for span in (0.35, 0.65, 0.95):
            for off in (0.0, 0.5, 1.0):
                for sgn in (1.0, -1.0):
                    v = off * (1 - span) + span * (frac if sgn > 0 else 1 - frac)
                    us.append(np.broadcast_to(v * 0.999 + 0.0005, (m, n)))
    return np.stack(us, axis=1), phis


def arc_indices(C, full, V):
    """Grid indices ``(m, P, k)`` of the points at arc-length fractions `V` ``(m, P, k)`` along
    each sampled curve `C` ``(m, GRID)`` (once round, the closing chord included, where the
    crank turns `full`y; its interval's end to end otherwise): a curve's points are spaced
    by its speed along the crank, which varies most on the curves a far coupler point draws
    (loops, cusps, crossings), so a target's arc-length fraction places it better than the
    same fraction of crank angle."""
    m = C.shape[0]
    seg = np.nan_to_num(np.abs(np.diff(C, axis=1, append=C[:, :1])))  # (m, GRID): chord g -> g + 1
    seg[:, -1] = np.where(full, seg[:, -1], 0.0)
    cum = np.cumsum(seg, axis=1)
    cum = np.concatenate([np.zeros((m, 1)), cum / np.maximum(cum[:, -1:], 1e-300)], axis=1)  # (m, GRID + 1) in [0, 1]
    # a table of the nearest sample at 1/ARC_LEVELS steps of arc: each sample marks the level
    # nearest it, the levels between take the last sample marked (its sample or the one before)
    table = np.full((m, ARC_LEVELS + 1), -1)
    rows = np.repeat(np.arange(m), GRID + 1)
    table[rows, np.rint(cum * ARC_LEVELS).astype(int).reshape(-1)] = np.tile(np.arange(GRID + 1), m)
    table = np.maximum.accumulate(table, axis=1)
    lv = np.rint(np.clip(V, 0.0, 1.0) * ARC_LEVELS).astype(int).reshape(m, -1)
    return np.mod(np.take_along_axis(table, lv, axis=1), GRID).reshape(V.shape)


def placement_costs(sg: ShapeGrid, U, phis, sub, Ts, mode_choices, arc: bool = False) -> list:
    """A ``Placement`` per assembly mode: the sampled curve points at the placements'
    positions of the targets `sub` (``Ts``), taken to them by the best similarity (rotation
    fixed by `phis` when crank angles are prescribed): closed form.  With `arc`, `U` are
    fractions of each curve's arc length (``arc_indices``), not of its crank interval."""
    m = sg.a.size
    Tc = Ts - Ts.mean()
    inside = np.all((U >= 0) & (U < 1), axis=-1)
    idx = np.clip(np.floor(U[..., sub] * GRID).astype(int), 0, GRID - 1)
    cands = []
    for mode in mode_choices:
        C, s2 = local_point(np, sg.a[:, None], sg.b[:, None], sg.c[:, None], 1.0, sg.px[:, None], sg.py[:, None], mode, sg.grid)
        C = np.where(s2 >= 0, C, np.nan)
        if arc:
            idx = arc_indices(C, sg.full, np.clip(U[..., sub], 0.0, 1.0))
        P = np.take_along_axis(C[:, None, :], idx.reshape(m, -1, sub.size), axis=2) if U.ndim == 3 else None
        if phis is not None:
            rot = np.exp(1j * phis)[:, :, None]
            Q = rot * P
            Qc = Q - Q.mean(-1, keepdims=True)
            k = np.maximum(np.sum((np.conj(Qc) * Tc).real, -1) / np.maximum(np.sum(np.abs(Qc) ** 2, -1), 1e-300), 1e-3)
            z = k * rot[..., 0]
            w = Ts.mean() - k * Q.mean(-1)
            cost = np.sum(np.abs(k[..., None] * Qc - Tc) ** 2, -1)
        else:
            Pc = P - P.mean(-1, keepdims=True)
            z = np.sum(np.conj(Pc) * Tc, -1) / np.maximum(np.sum(np.abs(Pc) ** 2, -1), 1e-300)
            w = Ts.mean() - z * P.mean(-1)
            cost = np.sum(np.abs(z[..., None] * Pc - Tc) ** 2, -1)
        cost = np.where(inside & np.isfinite(cost) & (np.abs(z) > 1e-6), cost, np.inf)
        cands.append(Placement(cost, z, w, mode, C))
    return cands


class ClosestPointFit(NamedTuple):
    """The placements after closest-point iterations (``closest_point_fit``): the similarity
    `z`, `w` of every row, the kept rows `sel`, their targets' crank angles `theta` and
    their costs `cost`."""

    z: np.ndarray
    w: np.ndarray
    sel: np.ndarray
    theta: np.ndarray
    cost: np.ndarray


def closest_point_fit(curves, z, w, Ts, targets_n, grid_rows, keep: int) -> ClosestPointFit:
    """Closest-point iterations on placed curves ``z C + w`` (`curves` ``(K, GRID)``): each
    target of `Ts` to its nearest point of the placed curve, then the best similarity again
    (the distance to the curve, not to a timing guess); the best `keep` kept, every
    target's crank angle on them from the rows' `grid_rows`."""
    Tc = Ts - Ts.mean()
    for _ in range(2):
        jj = _nearest(curves, z, w, Ts)
        P = np.take_along_axis(curves, jj, axis=1)
        Pc = P - P.mean(-1, keepdims=True)
        z = np.sum(np.conj(Pc) * Tc, -1) / np.maximum(np.sum(np.abs(Pc) ** 2, -1), 1e-300)
        w = Ts.mean() - z * P.mean(-1)
    jj = _nearest(curves, z, w, Ts)
    P = np.take_along_axis(curves, jj, axis=1)
    cost = np.sum(np.abs(z[:, None] * P + w[:, None] - Ts) ** 2, -1)
    cost = np.where(np.isfinite(cost) & (np.abs(z) > 1e-6), cost, np.inf)
    sel = np.argsort(cost)[:keep]
    sel = sel[np.isfinite(cost[sel])]
    jj = _nearest(curves[sel], z[sel], w[sel], targets_n)
    theta = np.take_along_axis(grid_rows[sel], jj, axis=1)
    return ClosestPointFit(z, w, sel, theta, cost[sel])


def placed_starts(targets_n, curve, alpha, mode_choices, n_shapes, keep, rng, ordered, cmu, arc: bool = True) -> Starts:
    """Best-placed random shapes: ``Starts(x (keep, 9), theta (keep, n), mode (keep,), cost
    (keep,))`` in the normalised frame.

    Each shape's coupler curve is sampled once (``GRID`` points over its crank interval);
    a placement puts the targets at positions along it spread as they are along the targets
    by arc length (a phase, a span, a direction), and is scored by the best similarity (or,
    with prescribed crank angles, scale and translation) taking the curve points to the
    targets: closed form.  The positions are fractions of the curve's arc length
    (``arc_indices``, `arc`, on ``ARC_TARGETS`` of the targets) when the crank angles are free
    and unordered, else of the crank's interval.  Stages: ``shape_grid``,
    ``placement_positions``, ``placement_costs``, ``closest_point_fit``."""
    n = targets_n.size
    closed = curve == "closed"
    timed = alpha is not None
    sg = shape_grid(rng, n_shapes, 0.5 if curve == "open" and not timed else 1.0, cmu)
    sub = np.unique(np.round(np.linspace(0, n - 1, min(n, 32))).astype(int))
    U, phis = placement_positions(sg, targets_n, alpha, closed, rng)
    Ts = targets_n[sub]
    icp = not (timed or ordered)
    arc = icp and arc  # arc-length placements, then closest-point iterations (which take the crank angles from the curve)
    coarse = np.unique(np.round(np.linspace(0, n - 1, min(n, ARC_TARGETS))).astype(int)) if arc else sub
    cands = placement_costs(sg, U, phis, coarse, targets_n[coarse], mode_choices, arc)
    costs = np.stack([cd.cost for cd in cands])  # (modes, m, P)
    flat = np.argsort(costs, axis=None)[: (2 * keep if icp else keep)]
    flat = flat[np.isfinite(costs.reshape(-1)[flat])]
    gi, i, j = np.unravel_index(flat, costs.shape)
    z = np.array([cands[g].z[ii, jj] for g, ii, jj in zip(gi, i, j)])
    w = np.array([cands[g].w[ii, jj] for g, ii, jj in zip(gi, i, j)])
    mode = np.array([cands[g].mode for g in gi], float)
    curves = np.stack([cands[g].curve[ii] for g, ii in zip(gi, i)]) if flat.size else np.zeros((0, GRID), complex)
    if icp and flat.size:
        z, w, sel, theta, cost = closest_point_fit(curves, z, w, Ts, targets_n, sg.grid[i], keep)
    else:
        sel = np.arange(flat.size)
        cost = costs.reshape(-1)[flat]
        theta = sg.lo[i, None] + sg.width[i, None] * U[i, j]
        theta = np.unwrap(theta, axis=1) if (timed or closed) else theta  # ordered crank angles, unwrapped
    ii, s_ = i[sel], np.abs(z[sel])
    lens = np.log(np.stack([sg.a[ii], sg.b[ii], sg.c[ii], np.ones(ii.size)], axis=1) * s_[:, None])
    x = np.concatenate([np.stack([w[sel].real, w[sel].imag, np.angle(z[sel])], axis=1), lens,
                        np.stack([sg.px[ii] * s_, sg.py[ii] * s_], axis=1)], axis=1)
    return Starts(x, theta.reshape(-1, n), mode[sel], cost)


def _nearest(curves, z, w, targets, block=64):
    """Index of each target's nearest sample on each placed curve ``z C + w``: ``(K, n)``."""
    out = np.empty((curves.shape[0], targets.size), int)
    for s0 in range(0, curves.shape[0], block):
        sl = slice(s0, s0 + block)
        placed = z[sl, None] * curves[sl] + w[sl, None]  # (k, GRID)
        d = np.abs(targets[None, :, None] - placed[:, None, :])
        out[sl] = np.argmin(np.where(np.isfinite(d), d, np.inf), axis=2)
    return out


