"""Plots and animations of a scene run (``SceneResult``): curves, transmission, drawings.

Every function builds a Matplotlib ``Figure`` with an Agg canvas (no ``pyplot``, no
global figure list, no display needed) and returns it, or the ``Axes`` it drew on, so
that tests and notebooks can inspect what was drawn.  In Jupyter a returned ``Figure``
displays inline; ``animate(result).to_jshtml()`` gives an HTML animation.

Units are SI throughout (rad, m, s), as in ``SceneResult.table()``; the one exception is
the transmission angle, plotted in degrees because that is how it is read.

## Drawing spec

A scene draws itself from a *drawing spec*: the dict returned by ``scene.drawing(p)``
(``p`` the parameters of the run).  A **point** in the spec is either the name of one of
``scene.mechanism.points`` (a function of the pose) or a complex number ``x + i y`` in m
(fixed in the ground frame).  Every key is optional:

| key | value | drawn as |
|---|---|---|
| `links` | `[(a, b), ...]` | a bar from point `a` to point `b`, joints as circles |
| `ground` | `[a, ...]` | ground pivots (triangles); points that do not move |
| `slots` | `[{"centre": c, "radius": r}, {"line": (a, b)}, ...]` | a circular arc slot of radius `r` (m) about `c`, or a straight slot from `a` to `b` (both as a wide pale band) |
| `chords` | `[(le, te), ...]` | flap or aerofoil chords, leading edge to trailing edge (thick) |
| `polygons` | `[(a, b, c, ...), ...]` | rigid plates (ternary links, bell cranks), filled |
| `points` | `[a, ...]` | extra points, marked and labelled |
| `trace` | `[a, ...]` | points whose paths over the stroke are drawn (dashed) |
| `transmission` | `(a, joint, b)` | the transmission angle: the angle at `joint` between the links to `a` and to `b` |
| `output` | coordinate or point name | the output of the mechanical advantage (default: the last coordinate) |

A circular slot may also say which arc to draw: `"angles": (start, end)` (rad, CCW from
+x), or `"pin": name` (the arc the pin sweeps over the stroke, plus a margin); otherwise
the whole circle is drawn.  A scene without a drawing spec is drawn as its named points,
with their paths traced.

Example (the classic four-bar)::

    {"links": [("O2", "A"), ("A", "B"), ("O4", "B")], "ground": ["O2", "O4"],
     "trace": ["P"], "transmission": ("A", "B", "O4")}

## Toggle positions

``find_toggles`` marks where a one-dof mechanism loses (or gains without bound) its
mechanical advantage ``MA = |dq_out/du|^-1``: the solver's ``SINGULAR`` status, a blow-up
of ``|dq_out/du|`` (``MA -> 0``: the input can no longer drive the output), a zero of
``dq_out/du`` (``MA -> inf``: the output at a limit, dead-centre position), and a
transmission angle within a tolerance of 0 or 180 deg.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from .status import Status

__all__ = [
    "Toggle",
    "animate",
    "draw_mechanism",
    "drawing_spec",
    "find_toggles",
    "mechanical_advantage",
    "plot_accelerations",
    "plot_coordinates",
    "plot_outputs",
    "plot_poses",
    "plot_transmission",
    "plot_velocities",
    "save_default_plots",
    "transmission_angle",
]

_SPEC_KEYS = ("links", "ground", "slots", "chords", "polygons", "points", "trace", "transmission", "output")
_QUANTITY = {0: "position", 1: "velocity", 2: "acceleration"}
_SUFFIX = {0: "", 1: "_dot", 2: "_ddot"}


# --------------------------------------------------------------------------- helpers
def _figure(nrows: int = 1, ncols: int = 1, *, width: float = 6.4, height: float = 2.6, sharex: bool = True, layout="constrained", dpi=100):
    """A pyplot-free figure with an Agg canvas and a flat array of axes."""
    fig = Figure(figsize=(width * ncols, height * nrows), layout=layout, dpi=dpi)
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, sharex=sharex, squeeze=False)
    return fig, list(axes.ravel())


def _per(unit: str, order: int) -> str:
    """Unit of the ``order``-th time derivative: ``rad`` -> ``rad/s`` -> ``rad/s^2``."""
    return unit if order == 0 else f"{unit}/s" if order == 1 else f"{unit}/s^2"


def _abscissa(result, against: str):
    """``(values, label)`` of the x axis: the input (its unit) or the time (s)."""
    if against == "input":
        name = result.input_name
        return np.asarray(result.motion.u[:, 0], float), f"{name} [{result.scene.units[name]}]"
    if against == "time":
        return np.asarray(result.motion.t, float), "t [s]"
    raise ValueError(f"against must be 'input' or 'time', got {against!r}")


def _input_unit(result) -> str:
    return result.scene.units[result.input_name]


# --------------------------------------------------------------------------- curves
def plot_coordinates(result, *, order: int = 0, against: str = "input", names: Sequence[str] | None = None) -> Figure:
    """Coordinates (``order=0``), velocities (1) or accelerations (2) against the input or time.

    One axes per unit (angles and lengths are not mixed on one scale), each curve labelled
    with its name; y labels read ``position [rad]``, ``velocity [m/s]``,
    ``acceleration [rad/s^2]``.  Time derivatives are under the scene's constant drive.

    **Arguments**

    - `result`: a ``SceneResult``.
    - `order`: 0, 1 or 2.
    - `against`: ``"input"`` (the driven coordinate) or ``"time"`` (s).
    - `names`: coordinates to plot (default: all).

    **Returns** the ``Figure``.  **Raises** ``ValueError`` for an unknown name or order.
    """
    if order not in _QUANTITY:
        raise ValueError(f"order must be 0, 1 or 2, got {order!r}")
    mech, mo = result.scene.mechanism, result.motion
    names = list(mech.coords if names is None else names)
    for n in names:
        if n not in mech.coords:
            raise ValueError(f"unknown coordinate {n!r}; coordinates: {list(mech.coords)}")
    data = (mo.q, mo.q_dot, mo.q_ddot)[order]
    x, xlabel = _abscissa(result, against)
    units = list(dict.fromkeys(result.scene.units[n] for n in names))
    fig, axes = _figure(len(units))
    for ax, unit in zip(axes, units):
        for n in names:
            if result.scene.units[n] == unit:
                ax.plot(x, np.asarray(data[:, mech.coords.index(n)], float), label=f"{n}{_SUFFIX[order]}")
        ax.set_ylabel(f"{_QUANTITY[order]} [{_per(unit, order)}]")
        ax.legend(loc="best", fontsize="small")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel(xlabel)
    fig.suptitle(f"{result.scene.name}: {_QUANTITY[order]}s")
    return fig


def plot_velocities(result, *, against: str = "input", names: Sequence[str] | None = None) -> Figure:
    """``plot_coordinates(result, order=1, ...)``: velocities (rad/s, m/s)."""
    return plot_coordinates(result, order=1, against=against, names=names)


def plot_accelerations(result, *, against: str = "input", names: Sequence[str] | None = None) -> Figure:
    """``plot_coordinates(result, order=2, ...)``: accelerations (rad/s^2, m/s^2)."""
    return plot_coordinates(result, order=2, against=against, names=names)


def plot_outputs(result, *, names: Sequence[str] | None = None, against: str = "input") -> Figure:
    """The scene's outputs (torque, force, voltage...), one axes each, y label ``NAME [UNIT]``.

    **Raises** ``ValueError`` if the scene has no outputs or a name is unknown.
    """
    outs = result.outputs
    names = list(outs if names is None else names)
    if not names:
        raise ValueError(f"scene {result.scene.name!r} has no outputs to plot")
    for n in names:
        if n not in outs:
            raise ValueError(f"unknown output {n!r}; outputs: {list(outs)}")
    x, xlabel = _abscissa(result, against)
    fig, axes = _figure(len(names))
    for ax, n in zip(axes, names):
        values, unit = outs[n]
        values = np.asarray(values, float)
        ax.plot(x, values if values.ndim else np.full_like(x, values), label=n)
        ax.set_ylabel(f"{n} [{unit}]")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel(xlabel)
    fig.suptitle(f"{result.scene.name}: outputs")
    return fig


# --------------------------------------------------------------------------- drawing spec and positions
def drawing_spec(result) -> dict:
    """The checked drawing spec of a result: ``scene.drawing(params)``, or the fallback
    (every named point, traced) when the scene has none.

    **Raises** ``ValueError`` naming an unknown key or point.
    """
    scene = result.scene
    if scene.drawing is None:
        names = list(scene.mechanism.points)
        return {"points": names, "trace": names}
    spec = scene.drawing(result.params)
    return _check_spec(scene, spec)


def _check_spec(scene, spec) -> dict:
    if not isinstance(spec, Mapping):
        raise ValueError(f"scene {scene.name!r}: drawing must return a dict, got {type(spec).__name__}")
    unknown = [k for k in spec if k not in _SPEC_KEYS]
    if unknown:
        raise ValueError(f"scene {scene.name!r}: unknown drawing key(s) {unknown}; known keys: {list(_SPEC_KEYS)}")
    spec = dict(spec)
    for name in _spec_points(spec):
        _check_point(scene, name)
    out = spec.get("output")
    if out is not None and out not in scene.mechanism.coords and out not in scene.mechanism.points:
        raise ValueError(f"scene {scene.name!r}: drawing output {out!r} is neither a coordinate nor a point")
    return spec


def _check_point(scene, name):
    if isinstance(name, str):
        if name not in scene.mechanism.points:
            raise ValueError(
                f"scene {scene.name!r}: drawing names unknown point {name!r}; "
                f"points: {list(scene.mechanism.points)} (or give a complex number in m)"
            )
    elif not isinstance(name, (int, float, complex, np.number)):
        raise ValueError(f"scene {scene.name!r}: a drawing point must be a point name or a complex number, got {name!r}")


def _spec_points(spec) -> list:
    """Every point the spec refers to (names and numbers), in order of appearance."""
    pts: list = []
    for a, b in spec.get("links", ()):
        pts += [a, b]
    pts += list(spec.get("ground", ()))
    for s in spec.get("slots", ()):
        if "centre" in s:
            pts.append(s["centre"])
            if "pin" in s:
                pts.append(s["pin"])
        elif "line" in s:
            pts += list(s["line"])
        else:
            raise ValueError(f"a slot needs 'centre' and 'radius', or 'line'; got {s!r}")
    for a, b in spec.get("chords", ()):
        pts += [a, b]
    for poly in spec.get("polygons", ()):
        pts += list(poly)
    pts += list(spec.get("points", ()))
    pts += list(spec.get("trace", ()))
    if "transmission" in spec:
        pts += list(spec["transmission"])
    return pts


def _positions(result, names) -> dict:
    """``{point: (N,) complex}`` over the stroke, in m (NaN where a sample failed)."""
    mo, mech = result.motion, result.scene.mechanism
    n = mo.q.shape[0]
    out, missing = {}, []
    for name in dict.fromkeys(names if not isinstance(names, str) else [names]):
        if not isinstance(name, str):
            out[name] = np.full(n, complex(name))
        elif name in mo.points:
            out[name] = np.asarray(mo.points[name][0], complex)
        else:
            missing.append(name)
    if missing:
        import jax
        import jax.numpy as jnp

        p = {k: jnp.asarray(v, mo.q.dtype) for k, v in result.params.items()}
        for name in missing:
            _check_point(result.scene, name)
            f = jax.vmap(lambda q, u, name=name: mech.point(name, q, u, p))
            out[name] = np.broadcast_to(np.asarray(f(mo.q, mo.u), complex), (n,)).copy()
    return out


# --------------------------------------------------------------------------- transmission, MA, toggles
def transmission_angle(result, transmission: tuple | None = None) -> np.ndarray:
    """Transmission angle (rad, in ``[0, pi]``) over the stroke.

    The angle at `joint` between the links ``joint -> a`` and ``joint -> b``, for
    ``transmission = (a, joint, b)`` (default: the drawing spec's ``transmission``); for
    a four-bar ``("A", "B", "O4")``: coupler against rocker.  At 0 or pi the two links are
    in line and the output joint cannot be driven (a toggle).

    **Raises** ``ValueError`` if no transmission is given or defined by the scene.
    """
    if transmission is None:
        transmission = drawing_spec(result).get("transmission")
    if transmission is None:
        raise ValueError(
            f"scene {result.scene.name!r} defines no transmission angle; pass transmission=(a, joint, b)"
        )
    a, j, b = transmission
    pos = _positions(result, [a, j, b])
    ra, rb = pos[a] - pos[j], pos[b] - pos[j]
    return np.abs(np.angle(rb * np.conj(ra)))


def _output_derivative(result, output: str | None):
    """``(dq_out/du (N,), output name, output unit)``; a point output gives ``|dP/du|``."""
    mech, mo = result.scene.mechanism, result.motion
    if output is None:
        output = drawing_spec(result).get("output") or mech.coords[-1]
    if output in mech.coords:
        d = np.asarray(mo.dq_du[:, mech.coords.index(output), 0], float)
        return d, output, result.scene.units[output]
    if output in mech.points:
        vel = _point_velocity(result, output)
        udot = np.asarray(mo.u_dot[:, 0], float)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.abs(vel) / np.abs(udot), output, "m"
    raise ValueError(
        f"unknown output {output!r}; give a coordinate {list(mech.coords)} or a point {list(mech.points)}"
    )


def _point_velocity(result, name):
    mo = result.motion
    if name in mo.points:
        return np.asarray(mo.points[name][1], complex)
    import jax
    import jax.numpy as jnp

    mech = result.scene.mechanism
    p = {k: jnp.asarray(v, mo.q.dtype) for k, v in result.params.items()}

    def vel(q, qd, u, ud):
        return jax.jvp(lambda q_, u_: mech.point(name, q_, u_, p), (q, u), (qd, ud))[1]

    return np.asarray(jax.vmap(vel)(mo.q, mo.q_dot, mo.u, mo.u_dot), complex)


def mechanical_advantage(result, output: str | None = None):
    """Mechanical advantage ``|dq_out/du|^-1`` of a one-dof scene over its stroke.

    The ideal (frictionless) ratio of output to input effort: output torque per input
    torque for rotations, force per torque (``rad/m``) for a slider driven by a crank.

    **Arguments**

    - `output`: a coordinate name, or a point name (then ``|dP/du|`` is used); default the
      drawing spec's ``output``, else the last coordinate.

    **Returns** ``(ma (N,), unit)``; ``inf`` where the output is at rest (a limit position),
    NaN where the sample failed.
    """
    d, _, unit = _output_derivative(result, output)
    uu = _input_unit(result)
    with np.errstate(divide="ignore", invalid="ignore"):
        ma = 1.0 / np.abs(d)
    return ma, ("-" if uu == unit else f"{uu}/{unit}")


class Toggle(NamedTuple):
    """A toggle (dead-centre) position found along a stroke.

    - `kind`: ``"singular"`` (solver status ``SINGULAR``), ``"blowup"`` (``|dq_out/du|``
      unbounded, ``MA -> 0``), ``"limit"`` (``dq_out/du = 0``, ``MA -> inf``: the output
      at an extreme), ``"transmission"`` (transmission angle at 0 or 180 deg).
    - `index`: the nearest sample.
    - `u`: the input there (interpolated for ``"limit"``), in the input's unit.
    """

    kind: str
    index: int
    u: float


def _groups(mask: np.ndarray) -> list[np.ndarray]:
    """Runs of consecutive True samples, as index arrays."""
    idx = np.flatnonzero(mask)
    if idx.size == 0:
        return []
    return np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)


def find_toggles(
    result,
    *,
    output: str | None = None,
    transmission: tuple | None = None,
    angle_tol: float = math.radians(2.0),
    blowup: float = 100.0,
) -> list[Toggle]:
    """Toggle positions along a one-dof stroke, sorted by sample.

    **Arguments**

    - `output`: the output coordinate or point (see ``mechanical_advantage``).  For a
      point only ``|dP/du|`` is known, which does not change sign: its limit positions
      are found only where a sample hits zero exactly; prefer a coordinate.
    - `transmission`: ``(a, joint, b)``; default the drawing spec's (none: not checked).
    - `angle_tol`: a transmission angle within this of 0 or pi counts (rad).
    - `blowup`: ``|dq_out/du|`` above this many times its median counts as unbounded.

    **Returns** a list of ``Toggle``.
    """
    mo = result.motion
    u = np.asarray(mo.u[:, 0], float)
    status = np.asarray(mo.status)
    found: list[Toggle] = []
    for g in _groups(status == Status.SINGULAR):
        found.append(Toggle("singular", int(g[len(g) // 2]), float(u[g[len(g) // 2]])))
    d, _, _ = _output_derivative(result, output)
    ad = np.abs(d)
    finite = np.isfinite(d)
    if np.any(finite):
        med = np.median(ad[finite])
        if med > 0:
            for g in _groups(finite & (ad > blowup * med)):
                i = int(g[np.argmax(ad[g])])
                found.append(Toggle("blowup", i, float(u[i])))
    # Sign changes (or exact zeros) of dq_out/du between consecutive converged samples.
    for i in range(len(d) - 1):
        d0, d1 = d[i], d[i + 1]
        if not (np.isfinite(d0) and np.isfinite(d1)):
            continue
        if d0 == 0.0:
            found.append(Toggle("limit", i, float(u[i])))
        elif d0 * d1 < 0:
            s = d0 / (d0 - d1)
            found.append(Toggle("limit", i if s < 0.5 else i + 1, float(u[i] + s * (u[i + 1] - u[i]))))
    if transmission is None:
        transmission = drawing_spec(result).get("transmission")
    if transmission is not None:
        mu = transmission_angle(result, transmission)
        gap = np.minimum(mu, np.pi - mu)
        for g in _groups(np.isfinite(gap) & (gap <= angle_tol)):
            i = int(g[np.argmin(gap[g])])
            found.append(Toggle("transmission", i, float(u[i])))
    return sorted(found, key=lambda t: (t.index, t.kind))


_TOGGLE_STYLE = {"singular": ("red", "-"), "blowup": ("red", "--"), "limit": ("tab:green", ":"), "transmission": ("purple", "-.")}


def plot_transmission(
    result,
    *,
    output: str | None = None,
    transmission: tuple | None = None,
    against: str = "input",
    **toggle_options,
) -> Figure:
    """Transmission angle (deg; when the scene defines one) and mechanical advantage, with
    the toggle positions from ``find_toggles`` marked as vertical lines (gid ``"toggle"``,
    labelled by kind).

    The mechanical advantage is drawn on a log scale (it spans decades near toggles).

    **Returns** the ``Figure`` (axes: transmission angle if defined, then MA).
    """
    if transmission is None:
        transmission = drawing_spec(result).get("transmission")
    toggles = find_toggles(result, output=output, transmission=transmission, **toggle_options)
    x, xlabel = _abscissa(result, against)
    xt = np.asarray(result.motion.t if against == "time" else result.motion.u[:, 0], float)
    fig, axes = _figure(2 if transmission is not None else 1)
    if transmission is not None:
        ax = axes[0]
        ax.plot(x, np.degrees(transmission_angle(result, transmission)), label="transmission angle")
        ax.axhspan(0, 40, color="red", alpha=0.06)
        ax.axhspan(140, 180, color="red", alpha=0.06)
        ax.set_ylim(0, 180)
        ax.set_yticks([0, 45, 90, 135, 180])
        ax.set_ylabel("transmission angle [deg]")
    ma, unit = mechanical_advantage(result, output)
    ax = axes[-1]
    _, out_name, _ = _output_derivative(result, output)
    shown = np.where(np.isfinite(ma) & (ma > 0), ma, np.nan)
    ax.plot(x, shown, label=f"MA ({out_name})")
    if np.any(np.isfinite(shown)):
        ax.set_yscale("log")
    ax.set_ylabel(f"mechanical advantage [{unit}]")
    for ax in axes:
        seen = set()
        for t in toggles:
            # Place the mark at the toggle's input value (or its time, when plotting against t).
            pos = t.u if against == "input" else float(np.interp(t.u, xt[[0, -1]], x[[0, -1]]))
            colour, style = _TOGGLE_STYLE[t.kind]
            line = ax.axvline(pos, color=colour, linestyle=style, lw=1.2, label=None if t.kind in seen else f"toggle: {t.kind}")
            line.set_gid("toggle")
            seen.add(t.kind)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize="small")
    axes[-1].set_xlabel(xlabel)
    fig.suptitle(f"{result.scene.name}: transmission and mechanical advantage")
    return fig


# --------------------------------------------------------------------------- mechanism drawing
class _Drawer:
    """Artists for one drawing spec; ``update(i)`` moves them to sample ``i``."""

    def __init__(self, result, ax, spec=None, trace=None, labels=False, progressive=False):
        self.result = result
        self.ax = ax
        self.spec = drawing_spec(result) if spec is None else _check_spec(result.scene, spec)
        if trace is not None:
            if isinstance(trace, str):
                trace = [trace]
            for t in trace:
                _check_point(result.scene, t)
        self.trace = list(self.spec.get("trace", ()) if trace is None else trace)
        self.pos = _positions(result, _spec_points(self.spec) + self.trace)
        self.u = np.asarray(result.motion.u[:, 0], float)
        self.progressive = progressive
        self.labels = labels
        self.artists = []  # (kind, artist, points)
        self._build()

    def _xy(self, names, i):
        z = np.array([self.pos[n][i] for n in names])
        return z.real, z.imag

    def _build(self):
        ax, spec = self.ax, self.spec
        for k, n in enumerate(self.trace):
            z = self.pos[n]
            full, = ax.plot(z.real, z.imag, ls="--", lw=0.8, color=f"C{(k + 1) % 10}", alpha=0.6 if self.progressive else 0.9, label=f"path of {n}")
            full.set_gid("trace")
            if self.progressive:
                done, = ax.plot([], [], ls="-", lw=1.5, color=f"C{(k + 1) % 10}")
                done.set_gid("trace-progress")
                self.artists.append(("progress", done, [n]))
        for s in spec.get("slots", ()):
            band, centre_line = self._slot(s)
            self.artists.append(("slot", (band, centre_line), s))
        for poly in spec.get("polygons", ()):
            patch = Polygon(np.zeros((len(poly), 2)), closed=True, facecolor="0.75", edgecolor="0.3", alpha=0.7)
            patch.set_gid("polygon")
            ax.add_patch(patch)
            self.artists.append(("polygon", patch, list(poly)))
        for a, b in spec.get("chords", ()):
            line, = ax.plot([], [], "-", lw=4, color="tab:blue", solid_capstyle="round")
            line.set_gid("chord")
            self.artists.append(("segment", line, [a, b]))
        for a, b in spec.get("links", ()):
            line, = ax.plot([], [], "-o", lw=2.2, color="0.15", ms=5, mfc="white", mew=1.3)
            line.set_gid("link")
            self.artists.append(("segment", line, [a, b]))
        for g in spec.get("ground", ()):
            mark, = ax.plot([], [], "^", ms=11, color="0.4", mec="0.1", zorder=1)
            mark.set_gid("ground")
            self.artists.append(("segment", mark, [g]))
        extra = list(spec.get("points", ()))
        if extra:
            pts, = ax.plot([], [], "o", ms=4, color="tab:red")
            pts.set_gid("point")
            self.artists.append(("segment", pts, extra))
        self.texts = []
        if self.labels:
            named = [n for n in dict.fromkeys(_spec_points(spec)) if isinstance(n, str)]
            for n in named:
                self.texts.append((n, ax.annotate(n, (0, 0), textcoords="offset points", xytext=(4, 4), fontsize=8)))
        self.title = ax.set_title("")
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.grid(True, alpha=0.2)
        self._limits()

    def _slot(self, s):
        kw = dict(lw=9, color="tab:orange", alpha=0.25, solid_capstyle="round")
        band, = self.ax.plot([], [], **kw)
        band.set_gid("slot")
        centre_line, = self.ax.plot([], [], lw=0.8, color="tab:orange")
        centre_line.set_gid("slot-centre")
        return band, centre_line

    def _slot_xy(self, s, i):
        if "line" in s:
            return self._xy(list(s["line"]), i)
        c = self.pos[s["centre"]][i]
        r = float(s["radius"])
        if "angles" in s:
            a0, a1 = (float(v) for v in s["angles"])
        elif "pin" in s:
            ang = np.unwrap(np.angle(self.pos[s["pin"]] - self.pos[s["centre"]]))
            ang = ang[np.isfinite(ang)]
            lo, hi = (float(ang.min()), float(ang.max())) if ang.size else (0.0, 2 * np.pi)
            margin = 0.1 * (hi - lo) + 0.02
            a0, a1 = lo - margin, hi + margin
        else:
            a0, a1 = 0.0, 2 * np.pi
        th = np.linspace(a0, a1, 90)
        z = c + r * np.exp(1j * th)
        return z.real, z.imag

    def _limits(self):
        zs = [v for v in self.pos.values()]
        for s in self.spec.get("slots", ()):
            if "centre" in s:
                for i in (0, len(self.u) - 1):
                    x, y = self._slot_xy(s, i)
                    zs.append(x + 1j * y)
        z = np.concatenate([np.ravel(v) for v in zs]) if zs else np.zeros(1)
        z = z[np.isfinite(z)]
        if z.size == 0:
            return
        x0, x1, y0, y1 = z.real.min(), z.real.max(), z.imag.min(), z.imag.max()
        span = max(x1 - x0, y1 - y0, 1e-12)
        m = 0.08 * span
        self.ax.set_xlim(x0 - m, x1 + m)
        self.ax.set_ylim(y0 - m, y1 + m)

    def update(self, i: int):
        for kind, art, pts in self.artists:
            if kind == "segment":
                art.set_data(*self._xy(pts, i))
            elif kind == "polygon":
                x, y = self._xy(pts, i)
                art.set_xy(np.column_stack([x, y]))
            elif kind == "slot":
                x, y = self._slot_xy(pts, i)
                for a in art:
                    a.set_data(x, y)
            elif kind == "progress":
                z = self.pos[pts[0]][: i + 1]
                art.set_data(z.real, z.imag)
        for n, text in self.texts:
            z = self.pos[n][i]
            text.xy = (z.real, z.imag)
        uname = self.result.input_name
        self.title.set_text(f"{uname} = {self.u[i]:.4g} {self.result.scene.units[uname]}")
        return [a for _, art, _ in self.artists for a in (art if isinstance(art, tuple) else (art,))] + [self.title]


def _index(result, index: int) -> int:
    n = result.motion.q.shape[0]
    if not -n <= index < n:
        raise ValueError(f"pose index {index} out of range for {n} samples")
    return index % n


def draw_mechanism(result, index: int = 0, *, ax=None, spec: Mapping | None = None, trace: Sequence | None = None, labels: bool = False):
    """Draw the mechanism at sample ``index`` of a run, from its drawing spec.

    Artists carry a gid by role: ``"link"`` (one line per link), ``"ground"`` (one per
    pivot), ``"slot"``, ``"chord"``, ``"polygon"``, ``"point"``, ``"trace"`` (one path per
    traced point, over the whole stroke).

    **Arguments**

    - `index`: the sample (negative counts from the end).
    - `ax`: draw into these axes (default: a new figure).
    - `spec`: a drawing spec to use instead of the scene's.
    - `trace`: points whose paths to draw, instead of the spec's ``trace``.
    - `labels`: write the point names.

    **Returns** the ``Axes``.
    """
    i = _index(result, index)
    if ax is None:
        _, (ax,) = _figure(width=5.5, height=4.5)
    drawer = _Drawer(result, ax, spec=spec, trace=trace, labels=labels)
    drawer.update(i)
    return ax


def plot_poses(result, indices: Sequence[int] | None = None, *, spec: Mapping | None = None, trace: Sequence | None = None) -> Figure:
    """The mechanism at several samples side by side (default: start, middle, end).

    **Returns** the ``Figure`` (one axes per pose, equal limits).
    """
    n = result.motion.q.shape[0]
    indices = [0, n // 2, n - 1] if indices is None else [_index(result, i) for i in indices]
    fig, axes = _figure(1, len(indices), width=4.2, height=4.0, sharex=False)
    for ax, i in zip(axes, indices):
        draw_mechanism(result, i, ax=ax, spec=spec, trace=trace)
    fig.suptitle(f"{result.scene.name}")
    return fig


# --------------------------------------------------------------------------- animation
def animate(
    result,
    path: str | Path | None = None,
    *,
    frames: int = 60,
    trace: Sequence | None = None,
    fps: int = 20,
    spec: Mapping | None = None,
    dpi: int = 80,
) -> FuncAnimation:
    """Animate the stroke: the mechanism moves while the traced paths are drawn.

    **Arguments**

    - `path`: ``*.gif`` (written with Pillow) or ``*.html`` (a self-contained JavaScript
      player, ``to_jshtml``); ``None`` writes nothing (call ``.to_jshtml()`` yourself, in a
      notebook ``IPython.display.HTML(animate(result).to_jshtml())``).
    - `frames`: number of frames, evenly spaced over the samples (at most the number of
      samples: run the scene with ``points >= frames``).
    - `trace`: points whose paths are traced (default: the spec's ``trace``).
    - `fps`: frames per second; `dpi`: resolution of a GIF.

    **Returns** the ``FuncAnimation``.  **Raises** ``ValueError`` for a bad suffix or
    frame count.
    """
    if path is not None and Path(path).suffix.lower() not in (".gif", ".html"):
        raise ValueError(f"animation path must end in .gif or .html, got {str(path)!r}")
    if int(frames) < 1:
        raise ValueError(f"frames must be at least 1, got {frames}")
    n = result.motion.q.shape[0]
    idx = np.unique(np.round(np.linspace(0, n - 1, min(int(frames), n))).astype(int))
    # A fixed layout: constrained layout would be recomputed for every frame (3x slower).
    fig, (ax,) = _figure(width=5.5, height=4.5, layout=None, dpi=dpi)
    fig.subplots_adjust(left=0.14, right=0.97, bottom=0.11, top=0.92)
    drawer = _Drawer(result, ax, spec=spec, trace=trace, progressive=True)
    anim = FuncAnimation(fig, drawer.update, frames=list(idx), init_func=lambda: drawer.update(int(idx[0])), interval=1000.0 / fps, blit=False, repeat=True)
    anim.frame_indices = idx  # the samples shown, one per frame
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.suffix.lower() == ".gif":
            anim.save(str(path), writer=PillowWriter(fps=fps), dpi=dpi)
        else:
            path.write_text(anim.to_jshtml(fps=fps), encoding="utf-8")
    return anim


# --------------------------------------------------------------------------- default set of plots
def save_default_plots(result, outdir: str | Path, *, dpi: int = 110) -> list[Path]:
    """Write the default plots of a run as PNG into `outdir` (created if needed).

    ``NAME_coordinates.png``, ``NAME_velocities.png``, ``NAME_accelerations.png``,
    ``NAME_outputs.png`` (if the scene has outputs), ``NAME_transmission.png`` (mechanical
    advantage and, if defined, transmission angle, toggles marked) and ``NAME_poses.png``
    (the mechanism at start, middle and end).  **Returns** the paths written.
    """
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    name = result.scene.name
    figs = {
        "coordinates": plot_coordinates(result),
        "velocities": plot_velocities(result),
        "accelerations": plot_accelerations(result),
    }
    if result.outputs:
        figs["outputs"] = plot_outputs(result)
    if result.scene.mechanism.dof == 1:
        figs["transmission"] = plot_transmission(result)
    figs["poses"] = plot_poses(result)
    paths = []
    for key, fig in figs.items():
        path = outdir / f"{name}_{key}.png"
        fig.savefig(path, dpi=dpi)
        paths.append(path)
    return paths
