"""The ``jaxmech`` command: list, run, animate, sweep and report the scenes.

```
jaxmech scenes [SCENE]
jaxmech run SCENE [--set NAME=VALUE ...] [--points N] [--out DIR] [--plots all|summary|none] [--plot COLUMN ...] [--transmission A,J,B ...] [--ma-output NAME]
jaxmech animate SCENE [--set NAME=VALUE ...] [--frames N] [--out FILE.gif|FILE.mp4|FILE.html]
jaxmech export SCENE [--at VALUE] --out FILE.dxf|FILE.svg [--set NAME=VALUE ...] [--stroke [--points N]] [--units m|mm]
jaxmech sweep SCENE --grid NAME=START:STOP:N [--grid ...] [--points N] [--out FILE.csv] [--chunk-size K]
jaxmech sweep SCENE --random COUNT [--range NAME=LOW:HIGH ... | --vary geometry|all] [--seed S] [--figures [--figure NAME=MOD:FN]] --out DIR.parquet
jaxmech report [--out DIR] [--points N] [--scenes NAME ...]
jaxmech simulate FILE.toml [--duration T] [--step H] [--set NAME=VALUE ...] [--out DIR] [--plots all|none]
```

Values are SI (m, rad, s, kg, N); a ``--set`` value may carry a unit instead
(``--set alpha0=65deg``, ``--set a1=275mm``), which is checked against the parameter's.  The command is an application, not the library: it
configures JAX for its own process, where the library never does: float64 on, and JAX's
persistent compilation cache switched on (``jaxmech.enable_compile_cache``, in
``$XDG_CACHE_HOME/jaxmech/xla``, default ``~/.cache/jaxmech/xla``; ``JAXMECH_COMPILE_CACHE=DIR``
moves it, ``=0`` turns it off, a ``JAX_COMPILATION_CACHE_DIR`` of your own is used as it
is), beside the library's stored executables (``jaxmech._compile.stored``): a second run is several
times faster.

A user's mistake (unknown scene or parameter, with the closest valid name; a bad value; a
design that cannot be assembled; a linkage file's error, naming the file; a destination that
cannot be written, found by writing to it before anything is computed) is one line on stderr
and exit status 2; no traceback.  The command makes the folder ``--out DIR`` names when the
folder above it exists, and no other.  Ctrl-C is one line too (exit status 130): a sweep into
a Parquet dataset keeps its finished chunks, and the same command resumes it.
"""

from __future__ import annotations

import contextlib
import csv
import sys
from pathlib import Path

import numpy as np

from . import values
from .parser import PROG, parser
from .values import UsageError
from ..names import did_you_mean

__all__ = ["main", "is_linkage_file", "mistakes_of", "write_csv"]


# --------------------------------------------------------------------------- setup
def _setup_jax():
    """The command's own process: float64, and JAX's persistent compilation cache on (unless
    ``JAXMECH_COMPILE_CACHE=0``, or a JAX cache the user set); called before any array exists."""
    import jax

    from .._compile.cache import enable_compile_cache, switched_off

    jax.config.update("jax_enable_x64", True)
    # an application may configure its process (the library never does): JAX's cache keeps
    # what the executable store does not (plots' and tables' small programs, user outputs)
    if not switched_off() and jax.config.jax_compilation_cache_dir is None:
        enable_compile_cache()


# --------------------------------------------------------------------------- shared steps
def is_linkage_file(name: str) -> bool:
    """Whether the command line reads `name` as a linkage file (TOML or JSON) rather than a scene."""
    return name.lower().endswith((".toml", ".json"))


@contextlib.contextmanager
def mistakes_of(source: str):
    """A ``ValueError`` inside (a file's, a scene's, a design's) becomes a one-line
    ``UsageError`` that names the linkage file when `source` is one."""
    try:
        yield
    except ValueError as e:
        msg = " ".join(str(e).split())
        name = Path(source).name
        raise UsageError(msg if not is_linkage_file(source) or msg.startswith(f"{name}:") else f"{name}: {msg}") from None


def _scene(name):
    from ..scenes import get_scene, scene_names

    if is_linkage_file(name):
        from ..scenes.linkage_scene import scene_from_file

        try:
            with mistakes_of(name):
                return scene_from_file(name)
        except OSError as e:
            raise UsageError(f"cannot read {name}: {e.strerror or e}") from None
    known = scene_names()
    if name not in known:
        raise UsageError(f"unknown scene {name!r}; {did_you_mean(name, known, 'known scenes')}")
    with mistakes_of(name):
        return get_scene(name)


def _run(source: str, scene, points, overrides):
    from ..scenes.linkage_scene import run_file_scene  # run_scene, or a file's rocking or sampled stroke

    overrides = values.overrides(scene, overrides)
    with mistakes_of(source):
        return run_file_scene(scene, points, **overrides)


def write_csv(table: dict, path: Path) -> None:
    """Write ``SceneResult.table()`` columns to CSV: a header ``NAME[UNIT]``, one row per input
    (its folder made when missing, not the folders above it)."""
    cols = list(table)
    data = [np.asarray(table[c]) for c in cols]
    path.parent.mkdir(exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for row in zip(*data):
            w.writerow([int(v) if np.issubdtype(np.asarray(v).dtype, np.integer) else repr(float(v)) for v in row])


def _write_run(result, outdir: Path, plots: str = "all", point_kinematics: bool = False, choice: dict | None = None) -> list[Path]:
    """CSV and the plots (``--plots``: ``all``, ``summary``, ``none``) of one run into
    ``outdir``; returns the paths written.  `point_kinematics`: every named point's
    position, velocity and acceleration in the CSV too, before its status column."""
    from ..viz.plot import save_default_plots

    name = result.scene.name
    csv_path = outdir / f"{name}.csv"
    table = result.table()
    if point_kinematics:
        from ..scenes.linkage_scene import point_columns

        status = table.pop("status[-]")
        table = {**table, **point_columns(result.motion), "status[-]": status}
    write_csv(table, csv_path)
    if plots == "none":
        return [csv_path]
    if result.scene.plots is not None:  # a scene's own plots: all of them, or none
        return [csv_path, *(Path(x) for x in result.scene.plots(result, outdir))]
    if plots == "summary":
        return [csv_path, *_summary_plots(result, outdir, columns=(choice or {}).get("columns"))]
    return [csv_path, *save_default_plots(result, outdir, **(choice or {}))]


def _plot_choice(args, result) -> dict:
    """``--plot``, ``--transmission``, ``--ma-output`` as ``save_default_plots``' options,
    every name checked against the run (``UsageError`` with a "did you mean")."""
    from ..viz.plot import plot_columns

    out = {}
    columns = [c.strip() for arg in args.plot_columns for c in arg.split(",") if c.strip()]
    if columns:
        known = plot_columns(result)
        for c in columns:
            if c.partition("[")[0] not in known:
                raise UsageError(f"--plot {c!r} is not a column of {result.scene.name}; {did_you_mean(c, known, 'its columns are')}")
        out["columns"] = [c.partition("[")[0] for c in columns]
    points = list(result.scene.mechanism.points)
    triples = []
    for arg in args.transmission:
        names = [x.strip() for x in arg.replace("-", ",").split(",")]
        if len(names) != 3:
            raise UsageError(f"--transmission {arg!r}: give three points A,J,B (the angle at J between J->A and J->B)")
        for x in names:
            if x not in points:
                raise UsageError(f"--transmission {arg!r}: {x!r} is not a point of {result.scene.name}; {did_you_mean(x, points, 'its points are')}")
        triples.append(tuple(names))
    if triples:
        out["transmission"] = triples
    if args.ma_output is not None:
        known = list(result.scene.mechanism.coords) + points
        if args.ma_output not in known:
            raise UsageError(f"--ma-output {args.ma_output!r} is not a coordinate or point of {result.scene.name}; "
                             f"{did_you_mean(args.ma_output, known, 'its coordinates and points are')}")
        out["output"] = args.ma_output
    return out


def _summary_plots(result, outdir: Path, dpi: int = 110, columns=None) -> list[Path]:
    """Two of the default plots (``save_default_plots``' files): the poses, and the outputs
    (`columns` of them: ``--plot``; the coordinates when the scene has none)."""
    from ..viz.plot import plot_coordinates, plot_outputs, plot_poses

    figs = {"outputs": lambda r: plot_outputs(r, names=columns)} if result.outputs or columns else {"coordinates": plot_coordinates}
    paths = []
    for key, plot in {**figs, "poses": plot_poses}.items():
        path = outdir / f"{result.scene.name}_{key}.png"
        plot(result).savefig(path, dpi=dpi)
        paths.append(path)
    return paths


# --------------------------------------------------------------------------- verbs
def _cmd_scenes(args) -> int:
    from ..scenes import get_scene, scene_names

    if args.scene is not None:
        print(_scene(args.scene).describe())
        return 0
    names = scene_names()
    width = max(map(len, names), default=0)
    for n in names:
        try:
            summary = get_scene(n).summary
        except Exception as e:  # noqa: BLE001 - a broken scene module must not hide the others
            summary = f"(cannot be loaded: {type(e).__name__}: {' '.join(str(e).split())})"
        print(f"{n:<{width}}  {summary}")
    return 0


def _cmd_run(args) -> int:
    scene = _scene(args.scene)
    result = _run(args.scene, scene, args.points, args.overrides)
    paths = _write_run(result, Path(args.out), args.plots, args.point_kinematics, _plot_choice(args, result))
    print(result.summary())
    for path in paths:
        print(f"wrote {path}")
    return 0


def _cmd_animate(args) -> int:
    from ..viz.plot import animate

    scene = _scene(args.scene)
    out = Path(args.out) if args.out else Path(f"{scene.name}.gif")
    result = _run(args.scene, scene, max(101, args.frames), args.overrides)
    anim = animate(result, out, frames=args.frames, fps=args.fps)
    print(f"wrote {out} ({len(anim.frame_indices)} frames)")
    return 0


def _cmd_export(args) -> int:
    from ..export.pose import export_pose, export_stroke, input_value
    from ..units import for_reading

    out = Path(args.out)
    scene = _scene(args.scene)
    overrides = values.overrides(scene, args.overrides)
    # a linkage file is passed on as its path: its layers are named after its links
    source = args.scene if is_linkage_file(args.scene) else scene
    with mistakes_of(args.scene):
        at = None if args.at is None else input_value(scene, args.at)
        if args.stroke:
            export_stroke(source, out, at=at, params=overrides, points=args.points, units=args.units)
        else:
            export_pose(source, at, out, params=overrides, units=args.units)
    name = scene.mechanism.inputs[0]
    shown = "the stroke's start" if at is None else "{} = {:.6g} {}".format(name, *for_reading(at, scene.units.get(name, ""))).rstrip()
    print(f"wrote {out} ({scene.name} at {shown}{', with its stroke' if args.stroke else ''})")
    return 0


def _sweep_out(args) -> Path:
    """The sweep's destination: checked (and the mode's needs) before anything is computed."""
    if args.random is None and not args.grid_values:
        raise UsageError("sweep needs at least one --grid NAME=START:STOP:N, or --random COUNT")
    if args.random is not None and args.grid_values:
        raise UsageError("give --grid or --random, not both")
    if args.figure_fns and not args.figures:
        raise UsageError("--figure adds a column to a figures sweep: give --figures too")
    if args.ranges and args.random is None:
        raise UsageError("--range is for --random designs; a grid takes --grid NAME=START:STOP:N")
    if args.vary is not None and (args.ranges or args.random is None):
        raise UsageError("--vary chooses the default ranges of --random designs; with --range, name every parameter to vary")
    name = Path(args.scene).stem if is_linkage_file(args.scene) else args.scene  # here, not beside the file
    default = f"{name}_figures.parquet" if args.figures else f"{name}_sweep.csv"
    out = Path(args.out or default)
    if out.suffix.lower() == ".parquet":
        values.check_writable_dir(out, "--out")
    elif args.figures:
        raise UsageError(f"--figures writes a Parquet dataset: give --out DIR.parquet, got {str(out)!r}")
    else:
        values.check_writable_file(out, "--out")
    return out


def _default_box(scene, vary: str) -> dict:
    """The default ``--random`` box: every parameter ``--vary`` names (``geometry``: those in
    m or rad, the drawing; ``all``) within +-10 % of its non-zero default."""
    box = {k: tuple(sorted((0.9 * v, 1.1 * v))) for k, v in scene.defaults.items()
           if v != 0 and (vary == "all" or scene.parameters.get(k, ("",))[0] in ("m", "rad"))}
    if not box:
        raise UsageError(f"scene {scene.name!r} has no non-zero {vary} parameter to vary: give --range NAME=LOW:HIGH"
                         + (" or --vary all" if vary != "all" else ""))
    return box


def _cmd_sweep(args) -> int:
    scene = _scene(args.scene)
    ranges = values.parse_ranges(args.ranges)
    named = {**args.grid_values, **ranges}
    unknown = [n for n in named if n not in scene.defaults]
    if unknown:
        raise UsageError(f"scene {scene.name!r} has no parameter(s) {unknown}; {did_you_mean(unknown[0], scene.defaults, 'its parameters are')}")
    from ..sweep import Figures, random_designs, sweep_dataset, sweep_scene  # imported only when sweeping

    if args.random is not None:
        box = ranges or _default_box(scene, args.vary or "geometry")
        designs = dict(grid=None, table=random_designs(box, args.random, seed=args.seed))
    else:
        designs = dict(grid=args.grid_values, table=None)
    out = args.out_path
    figures = Figures(functions=values.figure_functions(args.figure_fns)) if args.figures else None
    with mistakes_of(args.scene):
        if out.suffix.lower() == ".parquet":
            res = sweep_dataset(scene, out, **designs, figures=figures, points=args.points, chunk_size=args.chunk_size,
                                progress=None if args.progress else False)
            if not (args.progress and sys.stderr.isatty()):  # else the progress display ended with it
                print(res.line())
            return 0
        res = sweep_scene(scene, **designs, points=args.points, chunk_size=args.chunk_size, progress=None if args.progress else False)
    if args.progress and sys.stderr.isatty():  # the bar ended with the sweep; the CSV may take as long again
        print(f"writing {out} ({res.status.size} rows) ...", file=sys.stderr)
    res.to_csv(out)
    print(res.summary())
    print(f"wrote {out} ({res.n_designs} designs)")
    return 0


def _cmd_report(args) -> int:
    from ..scenes import scene_names

    names = scene_names() if args.scenes is None else args.scenes
    known = scene_names()
    unknown = [n for n in names if n not in known]
    if unknown:
        raise UsageError(f"unknown scene(s) {unknown}; {did_you_mean(unknown[0], known, 'known scenes')}")
    root = Path(args.out)
    root.mkdir(exist_ok=True)  # its folder exists (checked): nothing above it is made
    md = ["# jaxmech report", "", f"{len(names)} scene(s), {args.points} inputs over each stroke, SI units.", ""]
    failed = []
    for name in names:
        md += [f"## {name}", ""]
        try:
            scene = _scene(name)
            result = _run(name, scene, args.points, {})
            paths = _write_run(result, root / name)
        except Exception as e:  # noqa: BLE001 - one broken scene must not stop the report
            msg = " ".join(str(e).split())
            kind = "" if isinstance(e, UsageError) else f"{type(e).__name__}: "
            print(f"{PROG} report: scene {name} failed: {kind}{msg}", file=sys.stderr)
            md += [f"**failed**: {kind}{msg}", ""]
            failed.append(name)
            continue
        summary = result.summary()
        print(summary, end="\n\n")
        md += [scene.summary, "", "```", summary, "```", ""]
        for path in paths:
            rel = path.relative_to(root).as_posix()
            md.append(f"![{path.stem}]({rel})" if path.suffix == ".png" else f"- [{path.name}]({rel})")
        md.append("")
    readme = root / "README.md"
    readme.write_text("\n".join(md), encoding="utf-8")
    print(f"wrote {readme}" + (f"; failed: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0


def _cmd_simulate(args) -> int:
    from .simulate import simulate_command  # forward dynamics of a linkage file

    return simulate_command(args)


_VERBS = {"scenes": _cmd_scenes, "run": _cmd_run, "animate": _cmd_animate, "export": _cmd_export, "sweep": _cmd_sweep,
          "report": _cmd_report, "simulate": _cmd_simulate}


def _check_destination(args) -> None:
    """Every verb's destination checked (by writing) before anything is computed."""
    if args.verb == "sweep":
        args.out_path = _sweep_out(args)
    if args.verb == "animate" and args.out and Path(args.out).suffix.lower() not in (".gif", ".mp4", ".html"):
        raise UsageError(f"--out must end in .gif, .mp4 or .html, got {args.out!r}")
    if args.verb == "animate" and args.out and Path(args.out).suffix.lower() == ".mp4":
        from ..viz.drawing import NO_FFMPEG, ffmpeg_path

        if ffmpeg_path() is None:
            raise UsageError(NO_FFMPEG)
    if args.verb == "export" and Path(args.out).suffix.lower() not in (".dxf", ".svg"):
        raise UsageError(f"--out must end in .dxf or .svg, got {args.out!r}")
    if args.verb in ("run", "report", "simulate"):
        values.check_writable_dir(Path(args.out), "--out")
    elif args.verb in ("animate", "export") and args.out:
        values.check_writable_file(Path(args.out), "--out")


def _interrupted(args) -> str:
    """The one line that ends a command stopped by Ctrl-C: what stopped, and what a rerun does."""
    if args is None:
        return "interrupted"
    what = f"interrupted: {args.verb}" + (f" {args.scene}" if getattr(args, "scene", None) else "")
    out = getattr(args, "out_path", None)
    if out is not None and out.suffix.lower() == ".parquet":
        return f"{what} into {str(out)!r}; its finished chunks are kept: rerun the same command to resume the dataset"
    if out is not None:
        return f"{what}; nothing was written (a CSV is written at the end; --out DIR.parquet streams a resumable dataset)"
    return f"{what}; rerun the same command to start again"


@contextlib.contextmanager
def _interrupts_reach_main():
    """A Ctrl-C that lands in a garbage-collector callback (JAX has one) or a ``__del__``
    would be "ignored" by Python with a traceback, and the command would go on: for the
    duration, it is raised again in the main program instead."""
    import _thread
    import threading

    default, timers = sys.unraisablehook, []

    def hook(unraisable):
        if not isinstance(unraisable.exc_value, KeyboardInterrupt):
            return default(unraisable)
        # from another thread, a moment later: raised now, it would land in this hook again
        timers.append(threading.Timer(0.01, _thread.interrupt_main))
        timers[-1].daemon = True
        timers[-1].start()

    sys.unraisablehook = hook
    try:
        yield
    finally:
        sys.unraisablehook = default
        for t in timers:  # the command ended first: nothing left to stop
            t.cancel()


def main(argv=None) -> int:
    """Entry point of the ``jaxmech`` command; returns the exit status (0 ok, 1 a scene of a
    report failed, 2 a usage error: unknown scene or parameter, bad value, unassemblable design,
    130 interrupted by Ctrl-C)."""
    with _interrupts_reach_main():
        return _main(argv)


def _main(argv) -> int:
    args = None
    try:
        args = parser().parse_args(argv)
        # Syntax first (no JAX touched for a mistyped command line), then float64 and the cache.
        args.overrides = values.parse_set(getattr(args, "sets", None))
        args.grid_values = values.parse_grid(getattr(args, "grid", None))
        _check_destination(args)
        _setup_jax()
        from .._compile.quiet import quiet_loads

        # the command's programs come from JAX's cache and the library's store: jaxlib 0.10.1
        # logs a spurious machine mismatch for each it loads (jaxmech._compile.quiet)
        with quiet_loads():
            return _VERBS[args.verb](args)
    except UsageError as e:
        print(f"{PROG}: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C: one line, the shell's status for SIGINT (128 + 2)
        # (on a terminal, after the "^C" it echoed)
        print(f"{chr(10) if sys.stderr.isatty() else ''}{PROG}: {_interrupted(args)}", file=sys.stderr)
        return 130
    except MemoryError as e:  # a grid (or a stroke) too large to hold: numpy refuses it at once
        print(f"{PROG}: error: out of memory: {' '.join(str(e).split())}; ask for fewer --grid values or --points",
              file=sys.stderr)
        return 2
    except OSError as e:  # a destination that failed after the checks (disk full, races)
        print(f"{PROG}: error: cannot write {e.filename or ''}: {e.strerror or e}".replace("  ", " "), file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
