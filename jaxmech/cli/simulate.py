"""``jaxmech simulate FILE``: forward dynamics of a linkage file (its ``[simulate]`` table,
``linkage.simulate_file``) to a CSV, a plot of the input against time and a summary.

```
jaxmech simulate FILE.toml [--duration 2s] [--step 1ms] [--set NAME=VALUE ...] [--out DIR] [--plots all|none]
```
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .commands import is_linkage_file, mistakes_of, write_csv
from .values import UsageError
from ..names import did_you_mean

__all__ = ["simulate_command", "parameter_units", "summary"]

def parameter_units(lk, sim) -> dict[str, str]:
    """``{parameter: SI unit}`` of every parameter ``--set`` may change: the linkage's (as
    its scene's: ``scenes.linkage_scene.parameter_unit``, "-" where none) and the run's own
    (the motor's, ``torque``)."""
    from ..scenes.linkage_scene import parameter_unit

    return {**{k: parameter_unit(k, lk) or "-" for k in lk.params}, **sim.units}


def _overrides(lk, sim, raw: dict) -> dict[str, float]:
    """``--set`` values in SI: every name a parameter of the run, every unit one that fits."""
    from ..linkage.values import read_number

    units = parameter_units(lk, sim)
    out = {}
    for name, text in raw.items():
        if name not in units:
            raise UsageError(f"--set {name}: {lk.name}'s simulation has no parameter {name!r}; "
                             f"{did_you_mean(name, units, 'its parameters are')}")
        try:
            out[name] = read_number(text, units[name], f"--set {name}")
        except ValueError as e:
            raise UsageError(str(e)) from None
    return out


def summary(lk, sim, tr, cols: dict) -> str:
    """A few lines: the run (steps, step, final time, status), the input and its rate at
    the start and the end (angles in degrees), the motor's peak current, why it stopped early."""
    from ..solver.status import Status
    from ..units import for_reading

    status = int(tr.status)
    valid = np.flatnonzero(cols["status[-]"] == 0)
    last = int(valid[-1]) if valid.size else 0
    t_end = float(cols["t[s]"][last])
    drive = {"none": "free motion", "motor": "driven by the motor", "torque": "driven by a constant torque"}[sim.drive]
    t_last = float(cols["t[s]"][-1])
    lines = [f"{lk.name}: forward dynamics over {t_last:.6g} s ({sim.steps} steps of {sim.step:.6g} s), {drive}; "
             f"status {'ok' if status == Status.CONVERGED else Status(status).name.lower()}" + (f" at t = {t_end:.6g} s" if status != 0 else "")]
    name = lk.mechanism.inputs[0]
    for key in (k for k in cols if k.startswith(f"{name}[") or k.startswith(f"{name}_dot[")):
        unit = key[key.index("[") + 1:-1]
        (a, b), shown = for_reading(np.array([cols[key][0], cols[key][last]]), unit)
        lines.append(f"  {key[:key.index('[')]:<24} {a:.6g} -> {b:.6g} {shown}")
    if "current[A]" in cols:
        lines.append(f"  {'current (peak)':<24} {np.nanmax(np.abs(cols['current[A]'])):.6g} A")
    if status != 0:
        lines.append(f"  stopped early: {tr.message()}")
    return "\n".join(lines)


def plot_simulation(lk, cols: dict, path: Path, dpi: int = 110) -> Path:
    """The input's position and rate (and the motor's current) against time, one PNG."""
    from ..viz.drawing import label_columns, screen_figure
    from ..units import for_reading

    name = lk.mechanism.inputs[0]
    keys = [k for k in cols if k.startswith(f"{name}[") or k.startswith(f"{name}_dot[")]
    keys += ["current[A]"] if "current[A]" in cols else []
    fig, axes = screen_figure(len(keys))
    for ax, key in zip(axes, keys):
        unit = key[key.index("[") + 1:-1]
        values, shown = for_reading(cols[key], unit)
        ax.plot(cols["t[s]"], values)
        ax.set_ylabel(f"{key[:key.index('[')]} [{shown}]")
        ax.grid(True, alpha=0.3)
    axes[0].set_title(f"{lk.name}: forward dynamics")
    label_columns(axes, "t [s]")
    fig.savefig(path, dpi=dpi)
    return path


def simulate_command(args) -> int:
    """The ``simulate`` verb (``jaxmech.cli``): read, run, write, print; exit status 0."""
    from ..linkage.files import read_linkage_tables
    from ..linkage.simulate_file import read_simulate, run_simulation, simulation_columns
    from ..linkage.values import read_number

    source = args.file
    if not is_linkage_file(source):
        raise UsageError(f"simulate runs a linkage file (FILE.toml or FILE.json with a [simulate] table), got {source!r}")
    times = {}
    for key in ("duration", "step"):  # the command line's own mistakes first, without the file's name
        if getattr(args, key) is not None:
            try:
                times[key] = read_number(getattr(args, key), "s", f"--{key}")
            except ValueError as e:
                raise UsageError(str(e)) from None
    try:
        with mistakes_of(source):
            lk, _, table = read_linkage_tables(source)
            sim = read_simulate(table, lk, **times)
    except OSError as e:
        raise UsageError(f"cannot read {source}: {e.strerror or e}") from None
    params = _overrides(lk, sim, args.overrides)
    with mistakes_of(source):
        tr, p = run_simulation(lk, sim, params)
        cols = simulation_columns(lk, sim, tr, p)
    out = Path(args.out)
    csv_path = out / f"{lk.name}_simulate.csv"
    write_csv(cols, csv_path)
    paths = [csv_path] if args.plots == "none" else [csv_path, plot_simulation(lk, cols, out / f"{lk.name}_simulate.png")]
    print(summary(lk, sim, tr, cols))
    for path in paths:
        print(f"wrote {path}")
    return 0
