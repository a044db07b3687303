"""Block-triangular structure of the constraint equations (jaxmech.mechanism.structure) and the
block solves that use it, against the seed report's hand decomposition and numpy."""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from jax.test_util import check_grads  # noqa: E402

from jaxmech.solver.linalg import cond1, solve_blocks  # noqa: E402
from jaxmech.scenes import get_scene  # noqa: E402
from jaxmech.mechanism.structure import blocks, sparsity  # noqa: E402

from helpers import sixbar_mechanism  # noqa: E402


def test_flap_msd_decomposes_as_its_report_solves_it():
    """The MSD flap report (Section 2) solves loop 1 for (beta, delta), then loop 2 for
    (phi, psi) given delta, then loop 3 for (xi, theta) given delta and psi."""
    mech = get_scene("flap_msd").mechanism
    pattern = sparsity(mech)
    idx = {n: i for i, n in enumerate(mech.coords)}
    reads = {eq: {mech.coords[j] for j in np.flatnonzero(pattern[eq])} for eq in range(6)}
    assert reads[0] == reads[1] == {"beta", "delta"}
    assert reads[2] == reads[3] == {"delta", "phi", "psi"}
    assert reads[4] == reads[5] == {"delta", "psi", "xi", "theta"}
    order = blocks(mech)
    assert [tuple(mech.coords[j] for j in cols) for _, cols in order] == [("beta", "delta"), ("phi", "psi"), ("xi", "theta")]
    assert [rows for rows, _ in order] == [(0, 1), (2, 3), (4, 5)]
    assert idx["delta"] in order[0][1]


def test_coupled_loops_stay_one_block():
    assert len(blocks(get_scene("fourbar").mechanism)) == 1
    assert len(blocks(get_scene("arc_track_flap").mechanism)) == 1  # 4x4, coupled both ways
    assert [len(c) for _, c in blocks(sixbar_mechanism)] == [2, 2]  # Watt: loop 1, then loop 2


def test_block_solves_match_numpy_and_differentiate():
    """A random block-lower-triangular 6x6 in the flap's pattern, rows and columns permuted
    as a mechanism may number them: x, the inverse's condition number, and gradients."""
    rng = np.random.default_rng(0)
    order = ((2, 5), (0, 3)), ((1, 4), (2, 5)), ((0, 3), (1, 4))
    a = np.zeros((6, 6))
    solved = []
    for rows, cols in order:
        for i in rows:
            a[i, list(cols)] = rng.normal(size=2) + 2.0 * (np.array(cols) == cols[rows.index(i)])
            a[i, solved] = rng.normal(size=len(solved))
        solved += list(cols)
    b, bb = rng.normal(size=6), rng.normal(size=(6, 3))
    np.testing.assert_allclose(np.asarray(solve_blocks(jnp.asarray(a), jnp.asarray(b), order)), np.linalg.solve(a, b), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(np.asarray(solve_blocks(jnp.asarray(a), jnp.asarray(bb), order)), np.linalg.solve(a, bb), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(float(cond1(jnp.asarray(a), order)), np.linalg.cond(a, 1), rtol=1e-10)
    check_grads(lambda a_, b_: solve_blocks(a_, b_, order), (jnp.asarray(a), jnp.asarray(b)), order=1, modes=("fwd", "rev"))
