"""From a drawing to a refined, toleranced design: the design workflow, in four steps.

1. The README's Watt six-bar, from its drawing (``jm.Linkage``).
2. A sweep of random designs of its ten geometric parameters (every length, the rocker
   plate's angle, the two free ground pivots), +-10% of the drawing, to a Parquet dataset,
   keeping two figures per design: the peak crank torque and the least transmission quality
   (``|sin mu|`` at the two output joints; ``|sin mu| >= 0.5`` is ``30 <= mu <= 150 deg``).
3. The best feasible designs (least peak torque with ``|sin mu| >= 0.5``) refined in one
   call (``jaxmech.design.refine``): least peak crank torque, ``|sin mu| >= 0.5`` at every
   sample, the same +-10% box.
4. A tolerance study of the winner: first-order spread of its peak torque for +-0.5 mm on
   every length, and the Monte Carlo check.

Run: ``python -m examples.design_workflow [--designs D] [--starts K] [--out DIR]`` (the
benchmark ``benchmarks/workflow.py`` times each step, cold, at a million designs).
"""

from __future__ import annotations

import argparse
import math
import tempfile

import jax
import jax.numpy as jnp

import jaxmech as jm
from jaxmech.design import refine, scene_figure
from jaxmech.design.tolerance import analyse, monte_carlo
from jaxmech.sweep import Figures, random_designs, read_dataset, sweep_dataset

#: Samples along the crank's turn.
POINTS = 37
#: The figures' names in the dataset.
TORQUE, QUALITY = "peak_torque", "least_sin_mu"
#: The drive's effort column of the linkage's table (N m).
EFFORT = "effort_theta_crank[N m]"


def watt() -> jm.Linkage:
    """Step 1: the README's Watt six-bar, as drawn (m, kg)."""
    return jm.Linkage(
        points={"O2": (0, 0), "A": (0.5, 0.866), "B": (3.15, 2.0), "O4": (3.5, 0), "E": (4.6, 1.6), "F": (6.2, 3.2), "O6": (7.0, 1.0)},
        links={"crank": "O2 A", "coupler": "A B", "rocker": "O4 B E", "link5": "E F", "link6": "O6 F"},
        ground="O2 O4 O6", driver="crank", mass={"crank": 1.0, "coupler": 3.0, "rocker": 4.0, "link5": 2.5, "link6": 2.0},
        gravity=9.81)


def sin_mu(columns, p):
    """``|sin mu|`` at B (coupler A->B against the rocker's O4->B) and at F (link5 E->F against
    link6 O6->F), ``(2, points)``: 1 at a right angle, 0 at a toggle."""
    c = columns
    return jnp.abs(jnp.stack([jnp.sin(c["theta_coupler[rad]"] - c["theta_rocker[rad]"]),
                              jnp.sin(c["theta_link5[rad]"] - c["theta_link6[rad]"])]))


def peak_torque(columns, p):
    """The crank torque's largest magnitude over the turn (N m)."""
    return jnp.max(jnp.abs(columns[EFFORT]))


def least_sin_mu(columns, p):
    """The least ``|sin mu|`` over the turn and both output joints."""
    return jnp.min(sin_mu(columns, p))


def box(linkage: jm.Linkage, frac: float = 0.10) -> dict:
    """The ten geometric parameters and their +-`frac` box around the drawing."""
    names = [k for k in linkage.params if k.startswith(("len_", "ang_")) or k in ("x_O4", "x_O6", "y_O6")]
    return {k: tuple(sorted((linkage.params[k] * (1 - frac), linkage.params[k] * (1 + frac)))) for k in names}


def sweep(scene, bounds: dict, designs: int, out: str):
    """Step 2: `designs` random designs to a Parquet dataset of figures."""
    figures = Figures(columns=[], reductions=(), functions={TORQUE: peak_torque, QUALITY: least_sin_mu})
    return sweep_dataset(scene, out, table=random_designs(bounds, designs, seed=0), figures=figures, points=POINTS, progress=False)


def refined(scene, bounds: dict, out: str, starts: int):
    """Step 3: the `starts` best feasible designs of the dataset, refined in one call."""
    designs = read_dataset(out, columns=[*bounds, "status", TORQUE, QUALITY])
    return refine(scene, designs, bounds, peak=EFFORT, limits={"transmission": (sin_mu, 0.5, None)},
                  best=starts, rank=TORQUE, where={QUALITY: (0.5, None)}, points=POINTS)


def tolerances(scene, winner: dict, samples: int = 2000):
    """Step 4: the winner's peak torque under +-0.5 mm on every length: first order, and
    the Monte Carlo check."""
    figure = scene_figure(scene, peak_torque, points=POINTS)

    def figures(p):
        value, ok = figure(p)
        return {TORQUE: jnp.where(ok, value, jnp.nan)}

    tol = {k: 5e-4 for k in winner if k.startswith("len_")}
    design = {**scene.defaults, **winner}
    return analyse(figures, design, tol), monte_carlo(figures, design, tol, samples)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--designs", type=int, default=20_000)
    ap.add_argument("--starts", type=int, default=64)
    ap.add_argument("--out", default=None, help="the dataset's folder (default: a temporary one)")
    args = ap.parse_args(argv)
    jax.config.update("jax_enable_x64", True)
    linkage = watt()
    scene = linkage.scene(speed=2 * math.pi)
    bounds = box(linkage)
    out = args.out or tempfile.mkdtemp(prefix="watt_sweep_")
    sweep(scene, bounds, args.designs, out)
    table = read_dataset(out, columns=["status", TORQUE, QUALITY]).to_pandas()
    print(f"{len(table)} designs, {int((table['status'] != 'CONVERGED').sum())} failed; best feasible peak torque "
          f"{table[table[QUALITY] >= 0.5][TORQUE].min():.4g} N m")
    res = refined(scene, bounds, out, args.starts)
    print(res.report(show=5))
    first, mc = tolerances(scene, res.best_params)
    print(f"peak torque {float(first.value[TORQUE][0]):.6g} N m; +-0.5 mm on every length: rss {float(first.rss[TORQUE][0]):.3g} N m "
          f"(first order), Monte Carlo 3 sigma {3 * float(mc[TORQUE]['std'][0]):.3g} N m")


if __name__ == "__main__":
    main()
