"""The ``jaxmech`` command's grammar: its verbs, their arguments and help (``jaxmech.cli``
runs them)."""

from __future__ import annotations

import argparse

from . import values
from .values import UsageError

__all__ = ["PROG", "parser"]

PROG = "jaxmech"
PLOTS = ("none", "summary", "all")  # jaxmech run --plots
VARY = ("geometry", "all")  # jaxmech sweep --random --vary


class Parser(argparse.ArgumentParser):
    """argparse with one-line errors (its default prints the whole usage first)."""

    def error(self, message):
        raise UsageError(f"{message} (see '{self.prog} --help')")


def parser() -> Parser:
    """The ``jaxmech`` command's parser: one sub-parser per verb."""
    p = Parser(
        prog=PROG,
        description="Planar mechanisms in JAX: run, plot, animate and sweep the built-in scenes (SI units).",
        epilog="Compiled programs are cached in ~/.cache/jaxmech (JAXMECH_COMPILE_CACHE=DIR moves it, =0 turns it off).",
    )
    sub = p.add_subparsers(dest="verb", metavar="VERB", required=True, parser_class=Parser)
    _add_scenes(sub)
    _add_run(sub)
    _add_animate(sub)
    _add_export(sub)
    _add_sweep(sub)
    _add_report(sub)
    _add_simulate(sub)
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
    r.add_argument("--points", type=values.points, default=101, metavar="N", help="number of inputs over the stroke, ends included (default 101; over all cycles of a linkage file's rocking stroke; a sampled stroke has its own)")
    r.add_argument("--out", default="jaxmech-out", metavar="DIR",
                   help="output folder (default ./jaxmech-out; made if missing, inside a folder that exists)")
    r.add_argument("--plots", choices=PLOTS, default="all",
                   help="the PNG plots to write: all (default: coordinates, velocities, accelerations, outputs, transmission, "
                   "poses), summary (the poses, and the outputs or else the coordinates), none (the CSV and the summary only; "
                   "plots take seconds of CPU)")
    r.add_argument("--plot", dest="plot_columns", action="append", metavar="COLUMN[,COLUMN...]", default=[],
                   help="a CSV column to plot in the outputs figure, named without its unit (effort_theta_crank, F_B_x, "
                   "theta_rocker); repeatable or comma-separated (default: every output)")
    r.add_argument("--transmission", action="append", metavar="A,J,B", default=[],
                   help="a transmission angle to plot: the angle at joint J between J->A and J->B (repeatable: one curve each, "
                   "as for a linkage of several loops or with a slider; default the scene's own, none for a linkage file)")
    r.add_argument("--ma-output", metavar="NAME", default=None,
                   help="the coordinate (or point) whose mechanical advantage the transmission figure draws (default the "
                   "scene's output, else its last coordinate)")
    r.add_argument("--point-kinematics", action="store_true",
                   help="add every named point's position, velocity and acceleration to the CSV: x_P[m], y_P[m], vx_P[m/s], "
                   "vy_P[m/s], ax_P[m/s^2], ay_P[m/s^2] (joints, traced points, centres of mass G_<link>)")


def _add_animate(sub) -> None:
    """Add the ``animate`` verb: a GIF, MP4 or HTML of the stroke."""
    a = sub.add_parser(
        "animate",
        help="animate a scene's stroke to GIF, MP4 or HTML",
        description="Animate SCENE over its stroke, with the paths of its traced points, to a GIF (Pillow), an MP4 (ffmpeg: pip install \"jaxmech[video]\") or a self-contained HTML player.",
    )
    a.add_argument("scene", metavar="SCENE", help="scene name (see 'jaxmech scenes'), or a linkage file LINKAGE.toml / .json")
    a.add_argument("--set", dest="sets", action="append", metavar="NAME=VALUE", default=[], help="override a parameter (SI, or a number with its unit: 65deg, 275mm); repeatable")
    a.add_argument("--frames", type=values.positive("--frames"), default=60, metavar="N", help="number of frames (default 60)")
    a.add_argument("--fps", type=values.positive("--fps"), default=20, metavar="N", help="frames per second (default 20)")
    a.add_argument("--out", default=None, metavar="FILE", help="FILE.gif, FILE.mp4 or FILE.html (default ./SCENE.gif)")


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
                   help="range of a parameter for --random (SI units); repeatable; default: the parameters --vary names, "
                   "each within +-10%% of its default")
    s.add_argument("--vary", choices=VARY, default=None,
                   help="with --random and no --range, the parameters the default ranges vary: geometry (default: the "
                   "drawing's lengths, angles and positions, parameters in m or rad) or all (masses, inertias, g, loads and "
                   "stiffnesses too)")
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


def _add_simulate(sub) -> None:
    """Add the ``simulate`` verb: forward dynamics of a linkage file to CSV and a PNG plot."""
    s = sub.add_parser(
        "simulate",
        help="forward dynamics of a linkage file (its [simulate] table): CSV, PNG plot, summary",
        description="Integrate the equations of motion of the linkage in FILE (Linkage.forward_dynamics) as its "
        "[simulate] table says (duration, step, start, drive: a DC motor, a constant torque or none) and write "
        "DIR/NAME_simulate.csv (one row per time step, columns NAME[UNIT]) and DIR/NAME_simulate.png (the input's "
        "position and speed, the motor's current, against time); print a summary.",
    )
    s.add_argument("file", metavar="FILE", help="a linkage file LINKAGE.toml / .json (docs/linkage_files.md)")
    s.add_argument("--duration", default=None, metavar="TIME", help="the run's time, replacing [simulate] duration (s, or with a unit: 2s, 500ms)")
    s.add_argument("--step", default=None, metavar="TIME", help="the integrator's step, replacing [simulate] step (s, or with a unit: 1ms)")
    s.add_argument("--set", dest="sets", action="append", metavar="NAME=VALUE", default=[],
                   help="override a parameter of the linkage ('jaxmech scenes FILE' lists them) or of the run (R_a, K_m, "
                   "L_a, ratio, voltage, torque); SI or with its unit; repeatable")
    s.add_argument("--out", default="jaxmech-out", metavar="DIR",
                   help="output folder (default ./jaxmech-out; made if missing, inside a folder that exists)")
    s.add_argument("--plots", choices=("all", "none"), default="all", help="all (default: the PNG plot) or none (CSV and summary only)")
