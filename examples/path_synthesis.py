"""Four-bar path synthesis with the library's ``jaxmech.design.synthesize_path``: a coupler
point through (or nearest to) N target points.  ``docs/path_synthesis.md`` explains it.

- ``target_curve``: two test sets (a known crank-rocker's coupler curve, an ellipse), each
  with the crank angles that trace it.
- ``BULATOVIC_TARGETS``: the 12 closed-path targets of Bulatovic et al. (2016); their own
  linkage (``BULATOVIC_SOLUTION``) scores 0.00352 by ``path_error``, the synthesis 0.00252.
- ``draw``: the found linkage drawn over its targets (Matplotlib, no pyplot).
- ``CRUNODE``, ``TOGGLE_ARC`` and ``noisy_targets``: two curves with an exact answer, a
  figure-eight closed curve and a toggle-to-toggle open arc, sampled from their generating
  four-bars with small known noise (the generator's own error is then the noise floor).

Run ``python -m examples.path_synthesis`` for the reports, ``--figure PATH.png`` to draw them
(the docs page's figure is ``--figure docs/img/path_synthesis.png``).
"""

from __future__ import annotations

import argparse
from typing import NamedTuple

import numpy as np
from matplotlib.figure import Figure

from jaxmech.design import PathSynthesis, coupler_curve, crank_intervals, path_error, synthesize_path

__all__ = ["BULATOVIC_SOLUTION", "BULATOVIC_TARGETS", "CRANK_ROCKER", "CRUNODE", "STRAIGHT_LINE", "TOGGLE_ARC", "draw", "main",
           "noisy_targets", "Pins", "pins", "synthesize", "target_curve"]

#: A crank-rocker (m, rad): crank a about (x0, y0), ground d at angle phi, coupler b, rocker c,
#: coupler point (px, py) in the coupler's frame; mode +1 (jaxmech.design.coupler_path).
CRANK_ROCKER = {"x0": 0.0, "y0": 0.0, "phi": 0.1, "a": 1.0, "b": 3.0, "c": 2.5, "d": 3.5, "px": 1.5, "py": 0.8, "mode": 1.0}
#: Bulatovic, Miodragovic, Boskovic (2016), Mechanism and Machine Theory 95, 1-21: a 12-point
#: closed path and the paper's linkage (as transcribed by four-bar-rs; circuit 1 is mode +1).
BULATOVIC_TARGETS = np.array([4.15 + 2.21j, 4.5 + 2.18j, 4.53 + 1.83j, 4.13 + 1.68j, 3.67 + 1.58j, 2.96 + 1.33j, 2.67 + 1.06j,
                              2.63 + 0.82j, 2.92 + 0.81j, 3.23 + 1.07j, 3.49 + 1.45j, 3.76 + 1.87j])
BULATOVIC_SOLUTION = {"x0": 1.14265, "y0": 0.48237, "phi": 0.16502, "a": 1.14644, "b": 4.40713, "c": 4.75773, "d": 2.87645,
                      "px": 2.6666 * np.cos(-1.1364), "py": 2.6666 * np.sin(-1.1364), "mode": 1.0}
#: Nine points on a straight segment, (x, y) rows: an open path (a straight-line mechanism).
STRAIGHT_LINE = np.stack([np.linspace(0.0, 1.0, 9), np.zeros(9)], axis=1)
#: A Grashof crank-rocker (crank 1, coupler 2, rocker 2.5, ground 2.5) with its coupler point
#: far off the coupler line: its coupler curve crosses itself once (a crunode, a figure eight).
CRUNODE = {"x0": 0.4, "y0": -0.3, "phi": 0.35, "a": 1.0, "b": 2.0, "c": 2.5, "d": 2.5, "px": 3.0, "py": 2.5, "mode": 1.0}
#: Hsieh (2017)'s open-curve linkage ("sharp", as transcribed by four-bar-rs, test-fb): a
#: non-Grashof triple rocker (crank 10, coupler 3, rocker 3, ground 7) whose crank swings
#: between its two toggles; its coupler point 20 from the crank pin.
TOGGLE_ARC = {"x0": -2.0, "y0": -3.0, "phi": 0.2, "a": 10.0, "b": 3.0, "c": 3.0, "d": 7.0, "px": 20.0 * np.cos(1.5),
              "py": 20.0 * np.sin(1.5), "mode": -1.0}


def noisy_targets(generator: dict, curve: str, n: int = 30, noise: float = 1e-3, seed: int = 0):
    """`n` points of `generator`'s coupler curve, complex ``(n,)``: once round at even crank
    angles for a closed curve, across its toggle-free crank interval (transmission angle >= 5
    deg; toggle to toggle for a triple rocker) for an open one; each coordinate moved by
    normal noise of `noise` times the points' rms radius (numpy's generator, `seed`)."""
    if curve == "closed":
        alpha = 0.1 + np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    else:
        (lo, hi), *_ = crank_intervals(generator, 5.0)
        alpha = lo + (hi - lo) * (np.arange(n) + 0.5) / n
    T = coupler_curve(generator, alpha)
    size = np.sqrt(np.mean(np.abs(T - T.mean()) ** 2))
    rng = np.random.default_rng(seed)
    return T + noise * size * (rng.normal(size=n) + 1j * rng.normal(size=n))


def target_curve(kind: str, n: int = 10):
    """``(targets complex (n,), alpha (n,))``: points (m) at absolute crank angles (rad).

    - ``"coupler"``: ``CRANK_ROCKER``'s coupler curve (reachable exactly, with timing);
    - ``"ellipse"``: semi-axes 1.0 and 0.4 m centred at (2, 1), tilted 20 deg, one crank turn
      per turn of the ellipse (not a coupler curve: the least error is positive).
    """
    alpha = np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    if kind == "coupler":
        return coupler_curve(CRANK_ROCKER, alpha), alpha
    if kind == "ellipse":
        return 2.0 + 1.0j + np.exp(1j * np.deg2rad(20)) * (np.cos(alpha) + 0.4j * np.sin(alpha)), alpha
    raise ValueError(f"target_curve: kind must be 'coupler' or 'ellipse', got {kind!r}")


def synthesize(targets, alpha=None, **options) -> PathSynthesis:
    """``synthesize_path(targets, "closed", alpha, **options)``: the name
    ``notebooks/design_studies.ipynb`` calls (its cell prints ``report``, a method now); to
    be removed once that notebook calls ``synthesize_path`` itself."""
    return synthesize_path(targets, "closed", alpha, **options)


class Pins(NamedTuple):
    """Ground pivots and moving pins of a four-bar (complex, length units)."""

    O2: np.ndarray  # crank pivot
    O4: np.ndarray  # rocker pivot
    A: np.ndarray  # crank-coupler pin
    B: np.ndarray  # coupler-rocker pin


def pins(design, alpha) -> Pins:
    """The pivots and pins at absolute crank angles `alpha` (rad); B from the coupler point
    (the coupler frame's x axis runs from A to B), so the drawing is the curve's own."""
    O2 = design["x0"] + 1j * design["y0"]
    O4 = O2 + design["d"] * np.exp(1j * design["phi"])
    A = O2 + design["a"] * np.exp(1j * alpha)
    P = coupler_curve(design, alpha)
    B = A + design["b"] * (P - A) / (design["px"] + 1j * design["py"])  # the coupler frame: x along A -> B
    return Pins(O2, O4, A, B)


def draw(ax, res: PathSynthesis, targets, title: str = "") -> None:
    """The found linkage over its targets on Matplotlib axes `ax`: the targets, the feasible
    coupler curve (the arc used for an open path), each target's closest point on it, and
    the linkage at the first target's crank angle."""
    T = np.asarray(targets)
    T = T[:, 0] + 1j * T[:, 1] if T.ndim == 2 else T
    d, pe = res.design, res.path
    lo, hi = pe.interval if res.curve == "open" else (d["phi"] - np.pi, d["phi"] + np.pi)
    curve = coupler_curve(d, np.linspace(lo, hi, 721))
    closest = coupler_curve(d, pe.alpha)
    O2, O4, A, B = pins(d, pe.alpha[0])
    ax.plot(curve.real, curve.imag, "-", color="tab:blue", lw=1.2, label="coupler curve")
    for t, c in zip(T, closest):
        ax.plot([t.real, c.real], [t.imag, c.imag], "-", color="tab:red", lw=0.8)
    ax.plot(T.real, T.imag, "o", ms=5, mfc="none", color="tab:red", label="targets")
    ax.plot([O2.real, A.real, B.real, O4.real], [O2.imag, A.imag, B.imag, O4.imag], "-o", color="k", lw=1.5, ms=4,
            label="linkage")
    ax.fill([A.real, B.real, closest[0].real], [A.imag, B.imag, closest[0].imag], color="0.6", alpha=0.5)
    ax.plot([O2.real, O4.real], [O2.imag, O4.imag], "^", color="k", ms=9)
    ax.set_aspect("equal")
    ax.set_title(f"{title}\nrms distance {res.error:.3g}; {res.reached_best} of {res.starts} starts at the best",
                 fontsize=9)
    ax.legend(fontsize=7, loc="best")


def main(argv=None) -> list[PathSynthesis]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--figure", help="draw the linkages over their targets into this PNG")
    args = ap.parse_args(argv)
    published = path_error(BULATOVIC_SOLUTION, BULATOVIC_TARGETS, "closed")
    closed = synthesize_path(BULATOVIC_TARGETS, "closed")
    print(f"Bulatovic et al. (2016), 12 targets: the paper's linkage {published.error:.4g}\n{closed.report()}")
    line = synthesize_path(STRAIGHT_LINE, "open")
    print(f"a straight segment, 9 targets (open)\n{line.report()}")
    targets, alpha = target_curve("coupler", 10)
    timed = synthesize_path(targets, "closed", alpha=alpha)
    print(f"10 points of a known crank-rocker at their crank angles (prescribed)\n{timed.report()}")
    if args.figure:
        fig = Figure(figsize=(11, 3.9), layout="constrained")
        axes = fig.subplots(1, 3)
        draw(axes[0], closed, BULATOVIC_TARGETS, "closed: Bulatovic et al. (2016)")
        draw(axes[1], line, STRAIGHT_LINE, "open: a straight segment")
        draw(axes[2], timed, targets, "closed, crank angles prescribed")
        fig.savefig(args.figure, dpi=110)
        print(f"wrote {args.figure}")
    return [closed, line, timed]


if __name__ == "__main__":
    main()
