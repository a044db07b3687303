"""Plots and animations of a scene run (``SceneResult``): curves, transmission, drawings.

Every function builds a Matplotlib ``Figure`` with an Agg canvas (no ``pyplot``, no
global figure list, no display needed) and returns it, or the ``Axes`` it drew on, so
that tests and notebooks can inspect what was drawn.  In Jupyter a returned ``Figure``
displays inline; ``animate(result).to_jshtml()`` gives an HTML animation.

Axes show angles as a reader expects them, in degrees (``rad`` -> ``deg``, ``rad/s`` ->
``deg/s``, ``rad/s^2`` -> ``deg/s^2``), everything else in SI (m, s, N); every axis label
carries its unit.  The arrays behind them (``SceneResult.table()``, its CSV) stay SI.

The drawings (``draw_mechanism``, ``plot_poses``, ``animate``) and the drawing spec
they read are in ``jaxmech.viz.drawing``; their names are also here.

## Toggle positions

``find_toggles`` marks where a one-dof mechanism loses (or gains without bound) its
mechanical advantage ``MA = |dq_out/du|^-1``: the solver's ``SINGULAR`` status, a blow-up
of ``|dq_out/du|`` (``MA -> 0``: the input can no longer drive the output), a zero of
``dq_out/du`` (``MA -> inf``: the output at a limit, dead-centre position), and a
transmission angle within a tolerance of 0 or 180 deg.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
from matplotlib.figure import Figure

from .drawing import animate as animate
from .drawing import label_columns, point_positions, screen_figure
from .drawing import draw_mechanism as draw_mechanism
from .drawing import drawing_spec as drawing_spec
from .drawing import plot_poses as plot_poses
from ..solver.status import Status
from ..units import for_reading

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

_QUANTITY = {0: "position", 1: "velocity", 2: "acceleration"}
_SUFFIX = {0: "", 1: "_dot", 2: "_ddot"}


# --------------------------------------------------------------------------- helpers
def _per(unit: str, order: int) -> str:
    """Unit of the ``order``-th time derivative: ``rad`` -> ``rad/s`` -> ``rad/s^2``."""
    return unit if order == 0 else f"{unit}/s" if order == 1 else f"{unit}/s^2"


def _abscissa(result, against: str):
    """``(values, label)`` of the x axis: the input (in the reader's unit: an angle in
    degrees) or the time (s)."""
    if against == "input":
        name = result.input_name
        x, unit = for_reading(np.asarray(result.motion.u[:, 0], float), result.scene.units[name])
        return x, f"{name} [{unit}]"
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
    fig, axes = screen_figure(len(units))
    for ax, unit in zip(axes, units):
        for n in names:
            if result.scene.units[n] == unit:
                y, _ = for_reading(np.asarray(data[:, mech.coords.index(n)], float), unit)
                ax.plot(x, y, label=f"{n}{_SUFFIX[order]}")
        unit = for_reading(0.0, unit)[1]
        ax.set_ylabel(f"{_QUANTITY[order]} [{_per(unit, order)}]")
        ax.legend(loc="best", fontsize="small")
        ax.grid(True, alpha=0.3)
    label_columns(axes, xlabel)
    fig.suptitle(f"{result.scene.name}: {_QUANTITY[order]}s")
    return fig


def plot_velocities(result, *, against: str = "input", names: Sequence[str] | None = None) -> Figure:
    """``plot_coordinates(result, order=1, ...)``: velocities (rad/s, m/s)."""
    return plot_coordinates(result, order=1, against=against, names=names)


def plot_accelerations(result, *, against: str = "input", names: Sequence[str] | None = None) -> Figure:
    """``plot_coordinates(result, order=2, ...)``: accelerations (rad/s^2, m/s^2)."""
    return plot_coordinates(result, order=2, against=against, names=names)


def plot_outputs(result, *, names: Sequence[str] | None = None, against: str = "input") -> Figure:
    """The scene's outputs (torque, force, voltage...), one axes each, y label ``NAME [UNIT]``,
    on a screen-sized grid (``screen_figure``).  `names`: the columns to plot (default: every
    output): outputs, or any other column of ``result.table()`` (a coordinate, its rates),
    named without the unit.

    **Raises** ``ValueError`` if the scene has no outputs or a name is unknown.
    """
    outs = result.outputs
    names = list(outs if names is None else names)
    if not names:
        raise ValueError(f"scene {result.scene.name!r} has no outputs to plot")
    columns = plot_columns(result)
    for n in names:
        if n not in outs and n not in columns:
            raise ValueError(f"unknown output {n!r}; outputs: {list(outs)}")
    x, xlabel = _abscissa(result, against)
    fig, axes = screen_figure(len(names))
    for ax, n in zip(axes, names):
        values, unit = for_reading(*(outs[n] if n in outs else columns[n]))
        values = np.asarray(values, float)
        ax.plot(x, values if values.ndim else np.full_like(x, values), label=n)
        ax.set_ylabel(f"{n} [{unit}]")
        ax.grid(True, alpha=0.3)
    label_columns(axes, xlabel)
    fig.suptitle(f"{result.scene.name}: outputs")
    return fig


def plot_columns(result) -> dict:
    """``{name: (values, unit)}``: the columns of ``result.table()`` (its CSV) by name
    without the unit, the names ``--plot`` takes."""
    out = {}
    for key, values in result.table().items():
        name, _, unit = key.partition("[")
        out[name] = (np.asarray(values, float), unit.rstrip("]") or "-")
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
    pos = point_positions(result, [a, j, b])
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
    if transmission:  # () checks none
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
    """Transmission angle(s) (deg; when the scene defines one or they are given) and
    mechanical advantage, with the toggle positions from ``find_toggles`` marked as vertical
    lines (gid ``"toggle"``, labelled by kind).

    `transmission`: ``(a, joint, b)``, or a list of them (a linkage of several loops, a
    slider: one curve each, labelled ``a-joint-b``); default the drawing spec's.  `output`:
    the coordinate or point whose mechanical advantage is drawn (``mechanical_advantage``).
    The mechanical advantage is drawn on a log scale (it spans decades near toggles).

    **Returns** the ``Figure`` (axes: transmission angle if defined, then MA).
    """
    if transmission is None:
        transmission = drawing_spec(result).get("transmission")
    several = [] if transmission is None else [tuple(transmission)] if isinstance(transmission[0], str) else [tuple(t) for t in transmission]
    toggles = find_toggles(result, output=output, transmission=(), **toggle_options)
    for t in several:
        toggles += [g for g in find_toggles(result, output=output, transmission=t, **toggle_options) if g.kind == "transmission"]
    x, xlabel = _abscissa(result, against)
    xt = np.asarray(result.motion.t if against == "time" else result.motion.u[:, 0], float)
    fig, axes = screen_figure(2 if several else 1)
    if several:
        ax = axes[0]
        for t in several:
            ax.plot(x, np.degrees(transmission_angle(result, t)), label="transmission angle" if len(several) == 1 else "-".join(t))
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
            # the input where it toggles, mapped linearly onto the axis (deg, or s)
            pos = float(x[0] + (t.u - xt[0]) * (x[-1] - x[0]) / (xt[-1] - xt[0]))
            colour, style = _TOGGLE_STYLE[t.kind]
            line = ax.axvline(pos, color=colour, linestyle=style, lw=1.2, label=None if t.kind in seen else f"toggle: {t.kind}")
            line.set_gid("toggle")
            seen.add(t.kind)
        ax.grid(True, alpha=0.3)
        ax.legend(loc="best", fontsize="small")
    label_columns(axes, xlabel)
    fig.suptitle(f"{result.scene.name}: transmission and mechanical advantage")
    return fig


# --------------------------------------------------------------------------- default set of plots
def save_default_plots(result, outdir: str | Path, *, dpi: int = 110, columns: Sequence[str] | None = None,
                       transmission=None, output: str | None = None) -> list[Path]:
    """Write the default plots of a run as PNG into `outdir` (created if needed).

    ``NAME_coordinates.png``, ``NAME_velocities.png``, ``NAME_accelerations.png``,
    ``NAME_outputs.png`` (if the scene has outputs), ``NAME_transmission.png`` (mechanical
    advantage and, if defined, transmission angle, toggles marked) and ``NAME_poses.png``
    (the mechanism at start, middle and end).  `columns`: the outputs figure's columns
    (``plot_outputs``' `names`; default every output); `transmission`, `output`: the
    transmission figure's (``plot_transmission``).  **Returns** the paths written.
    """
    outdir = Path(outdir)
    outdir.mkdir(parents=True, exist_ok=True)
    name = result.scene.name
    figs = {
        "coordinates": plot_coordinates(result),
        "velocities": plot_velocities(result),
        "accelerations": plot_accelerations(result),
    }
    if result.outputs or columns:
        figs["outputs"] = plot_outputs(result, names=columns)
    if result.scene.mechanism.dof == 1:
        figs["transmission"] = plot_transmission(result, transmission=transmission, output=output)
    figs["poses"] = plot_poses(result)
    paths = []
    for key, fig in figs.items():
        path = outdir / f"{name}_{key}.png"
        fig.savefig(path, dpi=dpi)
        paths.append(path)
    return paths
