"""From a sweep to refined designs (``jaxmech.design.refine``): the starts it picks, and the
design it reaches against a brute-force scan of the same statement by ``sweep_scene``."""

import re
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxmech as jm  # noqa: E402
from jaxmech.design import best_designs, refine, scene_figure, scene_problem  # noqa: E402
from jaxmech.sweep import sweep_scene  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
EFFORT = "effort_theta_crank[N m]"


def fourbar():
    """A crank-rocker with masses and gravity: O2 A = 1, A B = 3.2, O4 B = 2.6, O2 O4 = 3 (m)."""
    y = float(np.sqrt(3.2**2 - 1.87**2))
    return jm.Linkage(points={"O2": (0, 0), "A": (1, 0), "B": (2.87, y), "O4": (3, 0)},
                      links={"crank": "O2 A", "coupler": "A B", "rocker": "O4 B"}, ground="O2 O4", driver="crank",
                      mass={"crank": 1.0, "coupler": 3.0, "rocker": 2.0}, gravity=9.81)


def sin_mu(c, p):
    """``|sin mu|`` at B: coupler A->B against the rocker O4->B."""
    return jnp.abs(jnp.sin(c["theta_coupler[rad]"] - c["theta_rocker[rad]"]))


def test_best_designs_picks_converged_rows_within_the_filter_least_rank_first():
    table = {"a": np.arange(6.0), "status": np.array(["CONVERGED", "CONVERGED", "INFEASIBLE", "CONVERGED", "CONVERGED", "CONVERGED"]),
             "torque": np.array([5.0, 1.0, 0.5, 3.0, np.nan, 2.0]), "q": np.array([1.0, 0.2, 1.0, 1.0, 1.0, 1.0])}
    got = best_designs(table, ["a"], best=2, rank="torque", where={"q": (0.5, None)})
    # row 1 fails the filter, row 2 did not converge, row 4 has no figure: 5 (2.0), then 3 (3.0)
    assert list(got["row"]) == [5, 3] and list(got["a"]) == [5.0, 3.0]
    with pytest.raises(ValueError, match="no column"):
        best_designs(table, ["b"])
    with pytest.raises(ValueError, match="best must be at least 1"):
        best_designs(table, ["a"], best=0)
    with pytest.raises(ValueError, match="no design converged"):
        best_designs(table, ["a"], where={"q": (2.0, None)})


def test_scene_problem_refuses_what_it_cannot_state():
    lk = fourbar()
    with pytest.raises(ValueError, match="no parameter"):
        scene_problem(lk, {"len_X": (1.0, 2.0)}, peak=EFFORT)
    with pytest.raises(ValueError, match="no column"):
        scene_problem(lk, {"len_A_B": (3.0, 3.4)}, peak="torque[N m]")
    with pytest.raises(ValueError, match="at least one of low and high"):
        scene_problem(lk, {"len_A_B": (3.0, 3.4)}, peak=EFFORT, limits={"mu": (sin_mu, None, None)})


def test_refine_reaches_the_brute_force_optimum():
    """One design variable, the coupler's length: least peak crank torque with ``|sin mu| >=
    0.56`` at every sample.  The scan: ``sweep_scene`` (the scene's own stroke and table
    columns) at 401 lengths; the refined design must be feasible, at least as good
    as every feasible scanned length, and within the scan's resolution of the best one."""
    lk = fourbar()
    scene = lk.scene(speed=2.0)
    box = {"len_A_B": (3.0, 3.6)}
    points = 25
    grid = np.linspace(*box["len_A_B"], 401)
    scan = sweep_scene(scene, table={"len_A_B": grid}, points=points, progress=False)
    assert scan.ok.all()
    peak = np.max(np.abs(scan.columns[EFFORT]), axis=1)
    mu = np.min(np.abs(np.sin(scan.columns["theta_coupler[rad]"] - scan.columns["theta_rocker[rad]"])), axis=1)
    feasible = mu >= 0.56
    assert feasible.any() and not feasible.all()  # the limit binds somewhere in the box
    best_scan = np.min(peak[feasible])

    starts = {"len_A_B": grid[::100], "status": np.zeros(5, int), "peak": peak[::100]}
    res = refine(scene, starts, box, peak=EFFORT, limits={"mu": (sin_mu, 0.56, None)}, best=5, rank="peak", points=points)
    assert res.converged >= 4 and res.best >= 0
    x = res.best_params["len_A_B"]
    check = sweep_scene(scene, table={"len_A_B": np.array([x])}, points=points, progress=False)
    value = float(np.max(np.abs(check.columns[EFFORT])))
    assert value == pytest.approx(float(res.value[res.best]), rel=1e-9)
    assert np.min(np.abs(np.sin(check.columns["theta_coupler[rad]"] - check.columns["theta_rocker[rad]"]))) >= 0.56 - 1e-8
    assert value <= best_scan * (1 + 1e-9)
    slope = np.max(np.abs(np.diff(peak))) / (grid[1] - grid[0])
    assert value >= best_scan - slope * (grid[1] - grid[0])
    assert list(res.origin) == list(np.argsort(starts["peak"]))


def test_the_effort_read_alone_equals_the_tables():
    """A figure that reads only the effort gets it by virtual power along the motion's tangent
    (no reactions traced); the table's comes from every body's Newton-Euler equations.  Two
    formulas, one number."""
    scene = fourbar().scene(speed=2.0)
    table = sweep_scene(scene, table={"len_A_B": np.array([3.3])}, points=25, progress=False).columns[EFFORT][0]
    peak = scene_figure(scene, lambda c, p: jnp.max(jnp.abs(c[EFFORT])), points=25, name="peak")
    value, ok = peak({"len_A_B": 3.3})
    assert bool(ok)
    assert float(value) == pytest.approx(float(np.max(np.abs(table))), rel=1e-12)
    last = scene_figure(scene, lambda c, p: c[EFFORT][-7], points=25, name="late")
    assert float(last({"len_A_B": 3.3})[0]) == pytest.approx(float(table[-7]), rel=1e-12, abs=1e-12 * float(np.max(np.abs(table))))


def test_design_workflow_page_shows_the_example():
    """The docs page's script is the example's file, word for word (the benchmark runs it)."""
    page = (ROOT / "docs" / "design_workflow.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", page, flags=re.S)
    assert (ROOT / "examples" / "design_workflow.py").read_text() in blocks
