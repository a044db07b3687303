"""The ``jaxmech`` command: list, run, animate, sweep and report the scenes.

```
jaxmech scenes [SCENE]
jaxmech run SCENE [--set NAME=VALUE ...] [--points N] [--out DIR]
jaxmech animate SCENE [--set NAME=VALUE ...] [--frames N] [--out FILE.gif|FILE.html]
jaxmech export SCENE [--at VALUE] --out FILE.dxf|FILE.svg [--set NAME=VALUE ...] [--stroke [--points N]] [--units m|mm]
jaxmech sweep SCENE --grid NAME=START:STOP:N [--grid ...] [--points N] [--out FILE.csv] [--chunk-size K]
jaxmech sweep SCENE --random COUNT [--range NAME=LOW:HIGH ...] [--seed S] [--figures [--figure NAME=MOD:FN]] --out DIR.parquet
jaxmech report [--out DIR] [--points N] [--scenes NAME ...]
```

Values are SI (m, rad, s, kg, N); a ``--set`` value may carry a unit instead
(``--set alpha0=65deg``, ``--set a1=275mm``), which is checked against the parameter's.  The command is an application, not the library: it
configures JAX for its own process, where the library never does: float64 on, and JAX's
persistent compilation cache switched on (``jaxmech.enable_compile_cache``, in
``$XDG_CACHE_HOME/jaxmech/xla``, default ``~/.cache/jaxmech/xla``; ``JAXMECH_COMPILE_CACHE=DIR``
moves it, ``=0`` turns it off, a ``JAX_COMPILATION_CACHE_DIR`` of your own is used as it
is), beside the library's stored executables (``jaxmech.stored``): a second run is several
times faster.

A user's mistake (unknown scene or parameter, a bad value, a design that cannot be
assembled) is one line on stderr and exit status 2; no traceback.
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

from . import cli_values as values
from .cli_values import UsageError

__all__ = ["main"]

PROG = "jaxmech"


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors (its default prints the whole usage first)."""

    def error(self, message):
        raise UsageError(f"{message} (see '{self.prog} --help')")


# --------------------------------------------------------------------------- setup
def _setup_jax():
    """The command's own process: float64, and JAX's persistent compilation cache on (unless
    ``JAXMECH_COMPILE_CACHE=0``, or a JAX cache the user set); called before any array exists."""
    import jax

    from .cache import enable_compile_cache, switched_off

    jax.config.update("jax_enable_x64", True)
    # an application may configure its process (the library never does): JAX's cache keeps
    # what the executable store does not (plots' and tables' small programs, user outputs)
    if not switched_off() and jax.config.jax_compilation_cache_dir is None:
        enable_compile_cache()


def _parser() -> _Parser:
    p = _Parser(
        prog=PROG,
        description="Planar mechanisms in JAX: run, plot, animate and sweep the built-in scenes (SI units).",
        epilog="Compiled programs are cached in ~/.cache/jaxmech (JAXMECH_COMPILE_CACHE=DIR moves it, =0 turns it off).",
    )
    sub = p.add_subparsers(dest="verb", metavar="VERB", required=True, parser_class=_Parser)
    _add_scenes(sub)
    _add_run(sub)
    _add_animate(sub)
    _add_export(sub)
    _add_sweep(sub)
    _add_report(sub)
    return p


def _add_scenes(sub) -> None:
    """Add the ``scenes`` verb: the scenes, or one scene's parameters."""
    sc = sub.add_parser(
        "scenes",
        help="list the scenes, or the parameters of one",
        description="List the scenes, one line each: name and summary; with SCENE, list its parameters "
        "(name, SI unit, default, meaning).",
    )
    sc.add_argument("scene", metavar="SCENE", nargs="?", default=None, help="a scene whose parameters to list")


def _add_run(sub) -> None:
    """Add the ``run`` verb: a scene over its stroke to CSV and PNG plots."""
    r = sub.add_parser(
        "run",
        help="run a scene over its stroke: CSV, PNG plots, summary",
        description="Run SCENE over its stroke and write DIR/SCENE.csv (one row per input, columns NAME[UNIT]) "
        "and the scene's plots as PNG; print the summary table.",
    )
    r.add_argument("scene", metavar="SCENE", help="scene name (see 'jaxmech scenes'), or a linkage file LINKAGE.toml / .json")
    r.add_argument("--set", dest="sets", action="append", metavar="NAME=VALUE", default=[], help="override a parameter (SI, or a number with its unit: 65deg, 275mm); repeatable; 'jaxmech scenes SCENE' lists them")
    r.add_argument("--points", type=values.points, default=101, metavar="N", help="number of inputs over the stroke, ends included (default 101)")
    r.add_argument("--out", default="jaxmech-out", metavar="DIR", help="output folder (default ./jaxmech-out)")


def _add_animate(sub) -> None:
    """Add the ``animate`` verb: a GIF or HTML of the stroke."""
    a = sub.add_parser(
        "animate",
        help="animate a scene's stroke to GIF or HTML",
        description="Animate SCENE over its stroke, with the paths of its traced points, to a GIF (Pillow) or a self-contained HTML player.",
    )
    a.add_argument("scene", metavar="SCENE", help="scene name (see 'jaxmech scenes'), or a linkage file LINKAGE.toml / .json")
    a.add_argument("--set", dest="sets", action="append", metavar="NAME=VALUE", default=[], help="override a parameter (SI, or a number with its unit: 65deg, 275mm); repeatable")
    a.add_argument("--frames", type=values.positive("--frames"), default=60, metavar="N", help="number of frames (default 60)")
    a.add_argument("--fps", type=values.positive("--fps"), default=20, metavar="N", help="frames per second (default 20)")
    a.add_argument("--out", default=None, metavar="FILE", help="FILE.gif or FILE.html (default ./SCENE.gif)")


def _add_export(sub) -> None:
    """Add the ``export`` verb: a pose or the stroke as DXF or SVG."""
    e = sub.add_parser(
        "export",
        help="export a pose (or the stroke) of a scene to DXF or SVG for CAD",
        description="Solve SCENE at input VALUE (moved there from the stroke's start) and write it to FILE.dxf (ezdxf: "
        "a layer per link, joints as circles, ground marks) or FILE.svg (a group per link), coordinates in full "
        "precision. --stroke adds the traced points' paths and the positions the links sweep through.",
    )
    e.add_argument("scene", metavar="SCENE", help="scene name (see 'jaxmech scenes'), or a linkage file LINKAGE.toml / .json")
    e.add_argument("--at", default=None, metavar="VALUE", help="the input's value (SI, or with its unit: 60deg, 450mm); default: the stroke's start")
    e.add_argument("--out", required=True, metavar="FILE", help="FILE.dxf or FILE.svg")
    e.add_argument("--set", dest="sets", action="append", metavar="NAME=VALUE", default=[], help="override a parameter (SI, or a number with its unit: 65deg, 275mm); repeatable")
    e.add_argument("--stroke", action="store_true", help="add the paths of the traced points over the stroke and the swept positions of the links")
    e.add_argument("--points", type=values.points, default=101, metavar="N", help="with --stroke: inputs over the stroke (default 101)")
    e.add_argument("--units", choices=("m", "mm"), default="m", help="the drawing's unit (default m)")


def _add_sweep(sub) -> None:
    """Add the ``sweep`` verb: a grid or random designs to CSV or Parquet."""
    s = sub.add_parser(
        "sweep",
        help="sweep a scene over a grid or random designs to CSV or a Parquet dataset",
        description="Run SCENE for every design on the grid (the product of the --grid axes) or for COUNT random "
        "designs (--random), and write one CSV, or, with --out DIR.parquet, a Parquet dataset streamed chunk by chunk "
        "(bounded memory; rerun the same command to resume an interrupted sweep). --figures keeps a few numbers "
        "per design (max, its position, min, its position, travel of every column; status) instead of every sample.",
    )
    s.add_argument("scene", metavar="SCENE", help="scene name (see 'jaxmech scenes'), or a linkage file LINKAGE.toml / .json")
    s.add_argument("--grid", action="append", metavar="NAME=START:STOP:N", default=[], help="a parameter axis: N values from START to STOP (SI units); repeatable")
    s.add_argument("--random", type=values.positive("--random"), default=None, metavar="COUNT", help="COUNT random designs, uniform in the --range box")
    s.add_argument("--range", dest="ranges", action="append", metavar="NAME=LOW:HIGH", default=[],
                   help="range of a parameter for --random (SI units); repeatable; default: every parameter within +-10%% of its default")
    s.add_argument("--seed", type=int, default=0, metavar="S", help="seed of the random designs (default 0)")
    s.add_argument("--figures", action="store_true", help="one row per design: figures reduced over the stroke (needs --out DIR.parquet)")
    s.add_argument("--figure", dest="figure_fns", action="append", metavar="NAME=MODULE:FUNCTION", default=[],
                   help="with --figures, one more column NAME: FUNCTION(columns, p) -> scalar from an importable module "
                   "(jax.numpy; see jaxmech.sweep.Figures); repeatable")
    s.add_argument("--points", type=values.points, default=101, metavar="N", help="number of inputs over each stroke (default 101)")
    s.add_argument("--out", default=None, metavar="FILE",
                   help="output: FILE.csv, or DIR.parquet for a streamed, resumable dataset (default ./SCENE_sweep.csv, "
                   "./SCENE_figures.parquet with --figures)")
    s.add_argument("--chunk-size", type=values.positive("--chunk-size"), default=None, metavar="K", help="designs per compiled batch (default: the sweep's own)")
    s.add_argument("--no-progress", dest="progress", action="store_false", help="no progress bar (it is shown only on a terminal anyway)")


def _add_report(sub) -> None:
    """Add the ``report`` verb: every scene into one folder."""
    rep = sub.add_parser(
        "report",
        help="run every scene (CSV, plots, summary) into one folder",
        description="Run every available scene (or those named) into DIR/SCENE/: CSV, PNG plots; write DIR/README.md "
        "with every summary and plot, and print the summaries.",
    )
    rep.add_argument("--out", default="jaxmech-report", metavar="DIR", help="output folder (default ./jaxmech-report)")
    rep.add_argument("--points", type=values.points, default=101, metavar="N", help="number of inputs over each stroke (default 101)")
    rep.add_argument("--scenes", nargs="+", metavar="NAME", default=None, help="only these scenes (default: all)")


# --------------------------------------------------------------------------- shared steps
def _scene(name):
    from .scenes import get_scene

    if name.lower().endswith((".toml", ".json")):
        from .scenes.linkage_scene import scene_from_file

        try:
            return scene_from_file(name)
        except OSError as e:
            raise UsageError(f"cannot read {name}: {e.strerror or e}") from None
        except ValueError as e:
            raise UsageError(" ".join(str(e).split())) from None
    try:
        return get_scene(name)
    except ValueError as e:
        raise UsageError(str(e)) from None


def _run(scene, points, overrides):
    from .scenes import run_scene

    overrides = values.overrides(scene, overrides)
    try:
        return run_scene(scene, points=points, **overrides)
    except ValueError as e:
        raise UsageError(str(e)) from None


def write_csv(table: dict, path: Path) -> None:
    """Write ``SceneResult.table()`` columns to CSV: a header ``NAME[UNIT]``, one row per input."""
    cols = list(table)
    data = [np.asarray(table[c]) for c in cols]
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="", encoding="utf-8") as f:
        w = csv.writer(f)
        w.writerow(cols)
        for row in zip(*data):
            w.writerow([int(v) if np.issubdtype(np.asarray(v).dtype, np.integer) else repr(float(v)) for v in row])


def _write_run(result, outdir: Path) -> list[Path]:
    """CSV + plots of one run into ``outdir``; returns the paths written."""
    from .plot import save_default_plots

    name = result.scene.name
    csv_path = outdir / f"{name}.csv"
    write_csv(result.table(), csv_path)
    if result.scene.plots is not None:
        plots = [Path(x) for x in result.scene.plots(result, outdir)]
    else:
        plots = save_default_plots(result, outdir)
    return [csv_path, *plots]


# --------------------------------------------------------------------------- verbs
def _cmd_scenes(args) -> int:
    from .scenes import get_scene, scene_names

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
    result = _run(scene, args.points, args.overrides)
    paths = _write_run(result, Path(args.out))
    print(result.summary())
    for path in paths:
        print(f"wrote {path}")
    return 0


def _cmd_animate(args) -> int:
    from .plot import animate

    scene = _scene(args.scene)
    out = Path(args.out) if args.out else Path(f"{scene.name}.gif")
    result = _run(scene, max(101, args.frames), args.overrides)
    anim = animate(result, out, frames=args.frames, fps=args.fps)
    print(f"wrote {out} ({len(anim.frame_indices)} frames)")
    return 0


def _cmd_export(args) -> int:
    from .export import SUFFIXES, export_pose, export_stroke, input_value
    from .units import for_reading

    out = Path(args.out)
    if out.suffix.lower() not in SUFFIXES:
        raise UsageError(f"--out must end in .dxf or .svg, got {args.out!r}")
    values.check_writable_file(out, "--out")
    scene = _scene(args.scene)
    overrides = values.overrides(scene, args.overrides)
    # a linkage file is passed on as its path: its layers are named after its links
    source = args.scene if args.scene.lower().endswith((".toml", ".json")) else scene
    try:
        at = None if args.at is None else input_value(scene, args.at)
        if args.stroke:
            export_stroke(source, out, at=at, params=overrides, points=args.points, units=args.units)
        else:
            export_pose(source, at, out, params=overrides, units=args.units)
    except ValueError as e:
        raise UsageError(str(e)) from None
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
    default = f"{args.scene}_figures.parquet" if args.figures else f"{args.scene}_sweep.csv"
    out = Path(args.out or default)
    if out.suffix.lower() == ".parquet":
        values.check_writable_dir(out, "--out")
    elif args.figures:
        raise UsageError(f"--figures writes a Parquet dataset: give --out DIR.parquet, got {str(out)!r}")
    else:
        values.check_writable_file(out, "--out")
    return out


def _cmd_sweep(args) -> int:
    scene = _scene(args.scene)
    ranges = values.parse_ranges(args.ranges)
    named = {**args.grid_values, **ranges}
    unknown = [n for n in named if n not in scene.defaults]
    if unknown:
        raise UsageError(f"scene {scene.name!r} has no parameter(s) {unknown}; its parameters are: {', '.join(scene.defaults)}")
    from .sweep import Figures, random_designs, sweep_dataset, sweep_scene  # imported only when sweeping

    if args.random is not None:
        box = ranges or {k: tuple(sorted((0.9 * v, 1.1 * v))) for k, v in scene.defaults.items() if v != 0}
        designs = dict(grid=None, table=random_designs(box, args.random, seed=args.seed))
    else:
        designs = dict(grid=args.grid_values, table=None)
    out = args.out_path
    figures = Figures(functions=values.figure_functions(args.figure_fns)) if args.figures else None
    try:
        if out.suffix.lower() == ".parquet":
            res = sweep_dataset(scene, out, **designs, figures=figures, points=args.points, chunk_size=args.chunk_size,
                                progress=None if args.progress else False)
            if not (args.progress and sys.stderr.isatty()):  # else the progress display ended with it
                print(res.line())
            return 0
        res = sweep_scene(scene, **designs, points=args.points, chunk_size=args.chunk_size, progress=None if args.progress else False)
    except ValueError as e:
        raise UsageError(str(e)) from None
    out.parent.mkdir(parents=True, exist_ok=True)
    res.to_csv(out)
    print(res.summary())
    print(f"wrote {out} ({res.n_designs} designs)")
    return 0


def _cmd_report(args) -> int:
    from .scenes import scene_names

    names = scene_names() if args.scenes is None else args.scenes
    known = scene_names()
    unknown = [n for n in names if n not in known]
    if unknown:
        raise UsageError(f"unknown scene(s) {unknown}; known scenes: {', '.join(known)}")
    root = Path(args.out)
    root.mkdir(parents=True, exist_ok=True)
    md = ["# jaxmech report", "", f"{len(names)} scene(s), {args.points} inputs over each stroke, SI units.", ""]
    failed = []
    for name in names:
        md += [f"## {name}", ""]
        try:
            scene = _scene(name)
            result = _run(scene, args.points, {})
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


_VERBS = {"scenes": _cmd_scenes, "run": _cmd_run, "animate": _cmd_animate, "export": _cmd_export, "sweep": _cmd_sweep,
          "report": _cmd_report}


def main(argv=None) -> int:
    """Entry point of the ``jaxmech`` command; returns the exit status (0 ok, 1 a scene of a
    report failed, 2 a usage error: unknown scene or parameter, bad value, unassemblable design)."""
    try:
        args = _parser().parse_args(argv)
        # Syntax first (no JAX touched for a mistyped command line), then float64 and the cache.
        args.overrides = values.parse_set(getattr(args, "sets", None))
        args.grid_values = values.parse_grid(getattr(args, "grid", None))
        if args.verb == "sweep":
            args.out_path = _sweep_out(args)
        if args.verb == "animate" and args.out and Path(args.out).suffix.lower() not in (".gif", ".html"):
            raise UsageError(f"--out must end in .gif or .html, got {args.out!r}")
        # Destinations are checked before anything is computed.
        if args.verb in ("run", "report"):
            values.check_writable_dir(Path(args.out), "--out")
        elif args.verb == "animate" and args.out:
            values.check_writable_file(Path(args.out), "--out")
        _setup_jax()
        return _VERBS[args.verb](args)
    except UsageError as e:
        print(f"{PROG}: error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    except MemoryError as e:  # a grid (or a stroke) too large to hold: numpy refuses it at once
        print(f"{PROG}: error: out of memory: {' '.join(str(e).split())}; ask for fewer --grid values or --points",
              file=sys.stderr)
        return 2
    except OSError as e:  # a destination that failed after the checks (disk full, races)
        print(f"{PROG}: error: cannot write {e.filename or ''}: {e.strerror or e}".replace("  ", " "), file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
