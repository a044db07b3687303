"""Live design exploration: change a parameter, see the mechanism, its traced paths and an
output curve (the driving torque) redrawn at once.

A ``LiveView`` holds one figure (the mechanism on the left, an output against the input on
the right) whose artists are built once; ``update(view, **params)`` evaluates the scene with
the changed parameters (``evaluate``: the stroke, its kinematics and the scene's outputs as
one compiled program of the parameters, so a change costs no Python-level work per array),
moves the artists and renders the figure to PNG.  It is a plain function: a
notebook calls it from a widget callback (``sliders`` builds ipywidgets sliders for it),
and ``benchmarks/live.py`` times it without a browser.

A design that cannot be assembled over its stroke, or a bad value (a negative length),
does not raise: the view keeps the last good drawing greyed out and says why in its status
line, as the returned string and in red on the figure.
"""

from __future__ import annotations

import dataclasses
import functools
import io
from collections.abc import Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from matplotlib.figure import Figure

from .drawing import Drawer, new_figure
from ..scenes import Scene, SceneResult, get_scene
from ..scenes.outputs import merged_status, output_units, sample_status
from ..solver.status import Status, status_counts
from ..sweep import design_motion
from ..units import for_reading
from ..solver.xla import jit

__all__ = ["live_view", "update", "sliders", "evaluate"]

@functools.partial(jit, static_argnums=(0, 1))
def _evaluate(scene: Scene, points: int, p):
    mo, ok = design_motion(scene, points, p)
    outs, own = sample_status(scene, p, mo) if scene.outputs is not None else ({}, None)
    if own is not None:  # outputs with a status of their own (joint friction's jammed samples)
        mo = dataclasses.replace(mo, status=merged_status(mo.status, own))
        ok = mo.status == Status.CONVERGED

    def nan(x):  # failed samples: NaN for drawing, as run_scene gives them
        return jnp.where(jnp.reshape(ok, (-1,) + (1,) * (x.ndim - 1)), x, jnp.nan)

    mo = dataclasses.replace(mo, q=nan(mo.q), q_dot=nan(mo.q_dot), q_ddot=nan(mo.q_ddot), dq_du=nan(mo.dq_du),
                             d2q_du2=nan(mo.d2q_du2), points=jax.tree_util.tree_map(nan, mo.points))
    return mo, {k: nan(jnp.asarray(v)) for k, (v, _) in outs.items()}


def evaluate(scene: Scene, points: int, params: Mapping) -> SceneResult:
    """``run_scene(scene, points, **params)`` as one compiled program of the parameters
    (compiled once per scene and ``points``; later calls only pass numbers).

    **Returns** the ``SceneResult`` (failed samples NaN).  **Raises** ``ValueError`` as
    ``run_scene`` does: a bad value (``scene.params``) or a design that cannot be assembled
    over its stroke (an infeasible or non-finite sample), saying where it fails.
    """
    p = scene.params(**params)
    mo, outs = _evaluate(scene, points, {k: jnp.asarray(v, float) for k, v in p.items()})
    status = np.asarray(mo.status)
    bad = np.flatnonzero((status == Status.INFEASIBLE) | (status == Status.NONFINITE))
    if bad.size:
        uname = scene.mechanism.inputs[0]
        u, unit = for_reading(float(mo.u[bad[0], 0]), scene.units[uname])
        raise ValueError(f"scene {scene.name!r} cannot be assembled over its stroke with these parameters: {bad.size} "
                         f"of {points} positions fail, first at {uname} = {u:.6g} {unit} ({status_counts(status)}); "
                         f"change the link lengths or the stroke")
    units = output_units(scene)  # strings cannot leave the compiled program
    return SceneResult(scene=scene, params=p, motion=mo, outputs={k: (v, units[k]) for k, v in outs.items()})


@dataclasses.dataclass(eq=False)
class LiveView:
    """The state of a live view (built by ``live_view``; changed by ``update``).

    - `scene`, `points`, `output`: the scene, samples over its stroke, the output plotted.
    - `params`: the parameters of the last update (SI), good or not.
    - `result`: the last run that could be assembled (``SceneResult``).
    - `status`: one line: the status counts, or why the last design failed.
    - `ok`: whether the last update's design could be assembled.
    - `index`: the sample whose pose is drawn.
    - `figure`, `drawer`: the figure and the mechanism's artists.
    - `png`: the figure rendered by the last update (bytes).
    - `ran`: the parameters last run (a pose change with the same ones runs nothing).
    - `full_renders`: how many renders redrew the axes (limits changed) rather than
      only the moving artists.
    """

    scene: Scene
    points: int
    output: str
    params: dict
    result: object
    status: str
    ok: bool
    index: int
    figure: Figure
    drawer: Drawer
    curve: object
    marker: object
    status_text: object
    png: bytes = b""
    background: object = None
    full_renders: int = 0
    ran: dict | None = None


def live_view(scene: str | Scene = "flap_msd", *, points: int = 61, output: str = "torque", index: int | None = None,
              width: float = 9.0, height: float = 3.6, dpi: int = 72) -> LiveView:
    """A live view of ``scene`` at its default parameters (the first call compiles).

    **Arguments**

    - `scene`: a scene or its registry name.
    - `points`: samples over the stroke (a fixed number: every update reuses one program).
    - `output`: the scene output plotted against the input (default the driving torque).
    - `index`: the sample whose pose is drawn (default the middle of the stroke).
    - `width`, `height` (inches), `dpi`: the figure; smaller renders faster.

    **Raises** ``ValueError`` for an unknown scene or output, or if the defaults fail.
    """
    if int(points) < 2:
        raise ValueError(f"points must be at least 2 (both ends of the stroke), got {points}")
    scene = get_scene(scene) if isinstance(scene, str) else scene
    result = evaluate(scene, int(points), {})
    if output not in result.outputs:
        raise ValueError(f"scene {scene.name!r} has no output {output!r}; outputs: {list(result.outputs)}")
    fig, (ax_m, ax_o) = new_figure(1, 2, width=width / 2, height=height, sharex=False, layout=None, dpi=dpi)
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.16, top=0.86, wspace=0.3)
    drawer = Drawer(result, ax_m)
    i = points // 2 if index is None else int(index) % points
    x, xunit = for_reading(np.asarray(result.motion.u[:, 0], float), scene.units[result.input_name])
    y, yunit = for_reading(np.asarray(result.outputs[output][0], float), result.outputs[output][1])
    curve, = ax_o.plot(x, y, lw=1.5)
    marker, = ax_o.plot([x[i]], [y[i]], "o", color="tab:red")
    ax_o.set_xlabel(f"{result.input_name} [{xunit}]")
    ax_o.set_ylabel(f"{output} [{yunit}]")
    ax_o.grid(True, alpha=0.3)
    status_text = fig.text(0.5, 0.95, "", ha="center", va="center", fontsize=9)
    view = LiveView(scene=scene, points=points, output=output, params=dict(result.params), result=result,
                    status="", ok=True, index=i, figure=fig, drawer=drawer, curve=curve, marker=marker,
                    status_text=status_text, ran=dict(result.params))
    update(view)
    _render(view, full=True)
    return view


def _inside(lo_hi, values, *, shrink: float = 0.25) -> bool:
    """Whether finite ``values`` lie within the limits ``lo_hi`` and fill at least
    ``shrink`` of them (else the axes are refitted)."""
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return True
    lo, hi = sorted(lo_hi)
    return lo <= v.min() and v.max() <= hi and (v.max() - v.min()) >= shrink * (hi - lo)


def _dynamic(view: LiveView):
    return [*view.drawer.ax.lines, *view.drawer.ax.patches, view.drawer.title, view.curve, view.marker, view.status_text]


def _render(view: LiveView, *, full: bool) -> None:
    """Draw into the Agg canvas and encode ``view.png``.  The axes, ticks and labels are
    drawn only when ``full`` (limits changed); otherwise the saved background is restored
    and only the moving artists are drawn over it (blitting: a few ms instead of ~50)."""
    from PIL import Image

    canvas = view.figure.canvas
    if full or view.background is None:
        for a in _dynamic(view):
            a.set_animated(True)
        canvas.draw()  # everything but the animated artists
        view.background = canvas.copy_from_bbox(view.figure.bbox)
        view.full_renders += 1
    else:
        canvas.restore_region(view.background)
    for a in _dynamic(view):
        (a.axes or view.figure).draw_artist(a)
    w, h = canvas.get_width_height()
    buf = io.BytesIO()
    # RGB at the lowest compression: a third of the encoding time of matplotlib's PNG
    Image.frombuffer("RGBA", (w, h), canvas.buffer_rgba(), "raw", "RGBA", 0, 1).convert("RGB").save(buf, format="png", compress_level=1)
    view.png = buf.getvalue()


def update(view: LiveView, index: int | None = None, **params) -> str:
    """Run the view's scene with ``params`` (SI; names of ``scene.defaults``, the others
    keep their last values), redraw the mechanism at sample ``index`` (default: unchanged),
    its traced paths and the output curve, and render the figure (``view.png``).

    **Returns** the status line: the status counts of the run, or, when the design cannot be
    assembled or a value is invalid, why (the last good drawing is kept, greyed out).
    **Raises** ``ValueError`` only for a name that is not a parameter of the scene.
    """
    for k in params:
        view.scene.check_name(k)
    view.params = {**view.params, **{k: float(v) for k, v in params.items()}}
    if index is not None:
        view.index = int(index) % view.points
    full = False
    try:
        # the pose slider changes no parameter: nothing to solve again
        if view.params == view.ran:
            if not view.ok:
                raise ValueError(view.status.removeprefix("cannot draw this design: "))
            result = view.result
        else:
            view.ran = dict(view.params)
            result = evaluate(view.scene, view.points, view.params)
    except ValueError as e:  # unassemblable design or bad value: shown, not raised
        view.ok, view.status = False, f"cannot draw this design: {' '.join(str(e).split())}"
    else:
        view.ok, view.result = True, result
        view.status = f"{view.scene.name}: {status_counts(result.motion.status)}"
        drawer = view.drawer
        drawer.set_result(result, limits=False)
        z = drawer.extent()
        if not (_inside(drawer.ax.get_xlim(), z.real, shrink=0.0) and _inside(drawer.ax.get_ylim(), z.imag, shrink=0.0)):
            drawer.fit_limits(0.2)  # room to move: fewer refits (each redraws the axes)
            full = True
        x, _ = for_reading(np.asarray(result.motion.u[:, 0], float), view.scene.units[result.input_name])
        y, _ = for_reading(np.asarray(result.outputs[view.output][0], float), result.outputs[view.output][1])
        view.curve.set_data(x, y)
        ax = view.curve.axes
        if not (_inside(ax.get_xlim(), x, shrink=0.0) and _inside(ax.get_ylim(), y, shrink=0.1)):
            ax.relim()
            ax.margins(y=0.25)  # room to move: fewer refits (each redraws the axes)
            ax.autoscale_view()
            full = True
    view.drawer.update(view.index)
    x, y = view.curve.get_data()
    view.marker.set_data([x[view.index]], [y[view.index]])
    alpha = None if view.ok else 0.3
    for artist in (*view.drawer.ax.lines, *view.drawer.ax.patches, view.curve, view.marker):
        artist.set_alpha(alpha)
    view.status_text.set_text(view.status if len(view.status) < 120 else view.status[:117] + "...")
    view.status_text.set_color("black" if view.ok else "tab:red")
    _render(view, full=full)
    return view.status


def sliders(view: LiveView, names: Sequence[str], *, spread: float = 0.3, limits: Mapping | None = None,
            steps: int = 60):
    """ipywidgets controls for a live view: one ``FloatSlider`` per parameter in ``names``
    (from ``(1 - spread)`` to ``(1 + spread)`` times its default, or ``limits[name] =
    (low, high)``, SI units in the label), a pose slider, an ``Image`` showing ``view.png``
    and a status ``Label``; moving a slider calls ``update``.

    **Returns** the ``ipywidgets.VBox`` (display it).  Needs ``ipywidgets``.
    """
    import ipywidgets as widgets

    limits = dict(limits or {})
    image = widgets.Image(value=view.png, format="png")
    label = widgets.Label(value=view.status)
    controls = []
    for name in names:
        view.scene.check_name(name)
        v0 = float(view.scene.defaults[name])
        lo, hi = limits.get(name, sorted(((1 - spread) * v0, (1 + spread) * v0)))
        unit = view.scene.parameters.get(name, ("", ""))[0]
        s = widgets.FloatSlider(value=v0, min=lo, max=hi, step=(hi - lo) / steps, description=f"{name} [{unit}]",
                                readout_format=".4g", continuous_update=True)
        controls.append(s)
    pose = widgets.IntSlider(value=view.index, min=0, max=view.points - 1, description="pose")

    def changed(change):
        owner = change["owner"]
        if owner is pose:
            label.value = update(view, index=change["new"])
        else:
            label.value = update(view, **{names[controls.index(owner)]: change["new"]})
        image.value = view.png

    for s in (*controls, pose):
        s.observe(changed, names="value")
    return widgets.VBox([widgets.HBox([widgets.VBox(controls[: (len(controls) + 1) // 2]),
                                       widgets.VBox([*controls[(len(controls) + 1) // 2:], pose])]), label, image])
