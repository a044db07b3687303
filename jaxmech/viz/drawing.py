"""Drawings of a mechanism from its scene's drawing spec: one pose, several poses side by
side, an animation of the stroke.

Every function builds a Matplotlib ``Figure`` with an Agg canvas (no ``pyplot``, no
global figure list, no display needed).  Drawn coordinates are in m; the input shown in a
title is in the reader's unit (an angle in degrees).

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
"""

from __future__ import annotations

import shutil
from collections.abc import Mapping, Sequence
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.animation import FFMpegWriter, FuncAnimation, PillowWriter
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Polygon

from ..units import for_reading

__all__ = [
    "animate",
    "check_point",
    "check_spec",
    "draw_mechanism",
    "drawing_spec",
    "Drawer",
    "ffmpeg_path",
    "new_figure",
    "plot_poses",
    "point_positions",
    "spec_points",
]

_SPEC_KEYS = ("links", "ground", "slots", "chords", "polygons", "points", "trace", "transmission", "output")


def new_figure(nrows: int = 1, ncols: int = 1, *, width: float = 6.4, height: float = 2.6, sharex: bool = True, layout="constrained", dpi=100):
    """A pyplot-free ``Figure`` (Agg canvas) and its axes as a flat list."""
    fig = Figure(figsize=(width * ncols, height * nrows), layout=layout, dpi=dpi)
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, sharex=sharex, squeeze=False)
    return fig, list(axes.ravel())


SCREEN = (1600, 1000)  # px: every PNG the command line writes fits a 1920x1080 screen at its dpi
SAVE_DPI = 110  # the command line's PNG resolution


def screen_figure(n: int, *, width: float = 6.4, height: float = 2.6, min_height: float = 1.8, dpi: int = SAVE_DPI):
    """A ``new_figure`` of `n` panels sized for a screen: one column of `width` x `height`
    in panels while it fits ``SCREEN`` at `dpi`, else a grid (row by row) that grows within
    that box, each panel at least `min_height` in tall while it can be; fonts keep their
    size in points.  Panels of a column share x; the lowest one of each column shows its
    tick labels.  Returns ``(fig, axes)``, `n` axes (the grid's spare cells removed)."""
    box_w, box_h = SCREEN[0] / dpi, SCREEN[1] / dpi
    rows = max(1, min(n, int(box_h // height)))
    if n > rows:
        rows = max(1, int(box_h // min_height))
    cols = -(-n // rows)
    rows = -(-n // cols)
    fig, axes = new_figure(rows, cols, width=min(width, box_w / cols), height=min(height, box_h / rows))
    for ax in axes[n:]:
        fig.delaxes(ax)
    for k in range(max(0, n - cols), n):  # the lowest panel of each column
        axes[k].xaxis.set_tick_params(labelbottom=True)
    return fig, axes[:n]


def label_columns(axes, label: str) -> None:
    """`label` under the lowest panel of each column of a ``screen_figure``."""
    cols = axes[0].get_gridspec().ncols if axes else 1
    for ax in axes[max(0, len(axes) - cols):]:
        ax.set_xlabel(label)



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
    return check_spec(scene, spec)


def check_spec(scene, spec) -> dict:
    if not isinstance(spec, Mapping):
        raise ValueError(f"scene {scene.name!r}: drawing must return a dict, got {type(spec).__name__}")
    unknown = [k for k in spec if k not in _SPEC_KEYS]
    if unknown:
        raise ValueError(f"scene {scene.name!r}: unknown drawing key(s) {unknown}; known keys: {list(_SPEC_KEYS)}")
    spec = dict(spec)
    for name in spec_points(spec):
        check_point(scene, name)
    out = spec.get("output")
    if out is not None and out not in scene.mechanism.coords and out not in scene.mechanism.points:
        raise ValueError(f"scene {scene.name!r}: drawing output {out!r} is neither a coordinate nor a point")
    return spec


def check_point(scene, name):
    if isinstance(name, str):
        if name not in scene.mechanism.points:
            raise ValueError(
                f"scene {scene.name!r}: drawing names unknown point {name!r}; "
                f"points: {list(scene.mechanism.points)} (or give a complex number in m)"
            )
    elif not isinstance(name, (int, float, complex, np.number)):
        raise ValueError(f"scene {scene.name!r}: a drawing point must be a point name or a complex number, got {name!r}")


def spec_points(spec) -> list:
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


def point_positions(result, names) -> dict:
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
            check_point(result.scene, name)
            f = jax.vmap(lambda q, u, name=name: mech.point(name, q, u, p))
            out[name] = np.broadcast_to(np.asarray(f(mo.q, mo.u), complex), (n,)).copy()
    return out


# --------------------------------------------------------------------------- mechanism drawing
class Drawer:
    """The artists of one drawing spec in an ``Axes``: ``update(i)`` moves them to sample
    ``i`` of the run, ``set_result(result)`` binds them to another run of the same scene
    (a changed design: the paths, limits and poses follow) without rebuilding them."""

    def __init__(self, result, ax, spec=None, trace=None, labels=False, progressive=False):
        self.result = result
        self.ax = ax
        self.spec = drawing_spec(result) if spec is None else check_spec(result.scene, spec)
        if trace is not None:
            if isinstance(trace, str):
                trace = [trace]
            for t in trace:
                check_point(result.scene, t)
        self.trace = list(self.spec.get("trace", ()) if trace is None else trace)
        self.pos = point_positions(result, spec_points(self.spec) + self.trace)
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
            self.artists.append(("trace", full, [n]))
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
            named = [n for n in dict.fromkeys(spec_points(spec)) if isinstance(n, str)]
            for n in named:
                self.texts.append((n, ax.annotate(n, (0, 0), textcoords="offset points", xytext=(4, 4), fontsize=8)))
        self.title = ax.set_title("")
        ax.set_aspect("equal", adjustable="box")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.grid(True, alpha=0.2)
        self.fit_limits()

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

    def extent(self) -> np.ndarray:
        """Every finite drawn position over the stroke (points and slot arcs), complex, m."""
        zs = [v for v in self.pos.values()]
        for s in self.spec.get("slots", ()):
            if "centre" in s:
                for i in (0, len(self.u) - 1):
                    x, y = self._slot_xy(s, i)
                    zs.append(x + 1j * y)
        z = np.concatenate([np.ravel(v) for v in zs]) if zs else np.zeros(1)
        return z[np.isfinite(z)]

    def fit_limits(self, margin: float = 0.08):
        """Axis limits around ``extent()`` with a ``margin`` (fraction of the larger span)."""
        z = self.extent()
        if z.size == 0:
            return
        x0, x1, y0, y1 = z.real.min(), z.real.max(), z.imag.min(), z.imag.max()
        span = max(x1 - x0, y1 - y0, 1e-12)
        m = margin * span
        self.ax.set_xlim(x0 - m, x1 + m)
        self.ax.set_ylim(y0 - m, y1 + m)

    def set_result(self, result, *, limits: bool = True):
        """Bind to ``result`` (same scene and drawing spec, other parameters): positions,
        traced paths and (``limits``) the axis limits are recomputed; call ``update(i)`` to
        draw a pose."""
        self.result = result
        self.pos = point_positions(result, spec_points(self.spec) + self.trace)
        self.u = np.asarray(result.motion.u[:, 0], float)
        for kind, art, pts in self.artists:
            if kind == "trace":
                art.set_data(self.pos[pts[0]].real, self.pos[pts[0]].imag)
        if limits:
            self.fit_limits()

    def update(self, i: int):
        for kind, art, pts in self.artists:
            if kind == "trace":
                continue
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
        shown, unit = for_reading(self.u[i], self.result.scene.units[uname])
        self.title.set_text(f"{uname} = {shown:.4g} {unit}")
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
        _, (ax,) = new_figure(width=5.5, height=4.5)
    drawer = Drawer(result, ax, spec=spec, trace=trace, labels=labels)
    drawer.update(i)
    return ax


def plot_poses(result, indices: Sequence[int] | None = None, *, spec: Mapping | None = None, trace: Sequence | None = None) -> Figure:
    """The mechanism at several samples side by side (default: start, middle, end).

    **Returns** the ``Figure`` (one axes per pose, equal limits).
    """
    n = result.motion.q.shape[0]
    indices = [0, n // 2, n - 1] if indices is None else [_index(result, i) for i in indices]
    fig, axes = new_figure(1, len(indices), width=min(4.2, SCREEN[0] / SAVE_DPI / len(indices)), height=4.0, sharex=False)
    for ax, i in zip(axes, indices):
        draw_mechanism(result, i, ax=ax, spec=spec, trace=trace)
    fig.suptitle(f"{result.scene.name}")
    return fig


# --------------------------------------------------------------------------- animation
_ANIMATION_SUFFIXES = (".gif", ".mp4", ".html")

NO_FFMPEG = 'writing an MP4 needs ffmpeg: pip install "jaxmech[video]" (or put ffmpeg on PATH)'


def ffmpeg_path() -> str | None:
    """The ffmpeg binary that ``animate`` writes an MP4 with, or ``None`` when there is none.

    The one the ``video`` extra installs (``imageio-ffmpeg``, a binary inside the wheel; its
    ``IMAGEIO_FFMPEG_EXE`` overrides it) when that is installed, else the one Matplotlib is
    set to use (``rcParams["animation.ffmpeg_path"]``, by default ``ffmpeg`` on ``PATH``).
    Nothing global is changed: ``animate`` points Matplotlib at it for its save only.
    """
    try:
        import imageio_ffmpeg
    except ImportError:
        pass
    else:
        try:
            return imageio_ffmpeg.get_ffmpeg_exe()
        except RuntimeError:  # the package without a usable binary (an unsupported platform)
            pass
    return shutil.which(str(matplotlib.rcParams["animation.ffmpeg_path"]))


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

    - `path`: ``*.gif`` (written with Pillow), ``*.mp4`` (H.264, written by ffmpeg: see
      ``ffmpeg_path``) or ``*.html`` (a self-contained JavaScript player, ``to_jshtml``);
      ``None`` writes nothing (call ``.to_jshtml()`` yourself, in a notebook
      ``IPython.display.HTML(animate(result).to_jshtml())``).
    - `frames`: number of frames, evenly spaced over the samples (at most the number of
      samples: run the scene with ``points >= frames``).
    - `trace`: points whose paths are traced (default: the spec's ``trace``).
    - `fps`: frames per second; `dpi`: resolution of a GIF or an MP4.

    **Returns** the ``FuncAnimation``.  **Raises** ``ValueError`` for a bad suffix or
    frame count; ``RuntimeError`` for an MP4 with no ffmpeg (before anything is drawn).
    """
    if path is not None and Path(path).suffix.lower() not in _ANIMATION_SUFFIXES:
        raise ValueError(f"animation path must end in .gif, .mp4 or .html, got {str(path)!r}")
    if int(frames) < 1:
        raise ValueError(f"frames must be at least 1, got {frames}")
    ffmpeg = None
    if path is not None and Path(path).suffix.lower() == ".mp4":
        ffmpeg = ffmpeg_path()
        if ffmpeg is None:
            raise RuntimeError(NO_FFMPEG)
    n = result.motion.q.shape[0]
    idx = np.unique(np.round(np.linspace(0, n - 1, min(int(frames), n))).astype(int))
    # A fixed layout: constrained layout would be recomputed for every frame (3x slower).
    fig, (ax,) = new_figure(width=5.5, height=4.5, layout=None, dpi=dpi)
    fig.subplots_adjust(left=0.14, right=0.97, bottom=0.11, top=0.92)
    drawer = Drawer(result, ax, spec=spec, trace=trace, progressive=True)
    anim = FuncAnimation(fig, drawer.update, frames=list(idx), init_func=lambda: drawer.update(int(idx[0])), interval=1000.0 / fps, blit=False, repeat=True)
    anim.frame_indices = idx  # the samples shown, one per frame
    if path is not None:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        if path.suffix.lower() == ".gif":
            anim.save(str(path), writer=PillowWriter(fps=fps), dpi=dpi)
        elif ffmpeg is not None:
            # Matplotlib's writer finds its binary through rcParams: set for this save only.
            with matplotlib.rc_context({"animation.ffmpeg_path": ffmpeg}):
                anim.save(str(path), writer=FFMpegWriter(fps=fps, codec="h264"), dpi=dpi)
        else:
            path.write_text(anim.to_jshtml(fps=fps), encoding="utf-8")
    return anim


