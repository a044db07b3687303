"""Small dense linear algebra for per-sample systems (m = 1..~10) under ``vmap``.

XLA's CPU batched LAPACK path is ~12x slower per sample than straight-line code and was
seen to hang the jaxlib 0.10 CPU runtime in large batched loops, so the solves here are
written as elementwise programs: Cramer's rule for 1x1 and 2x2, unrolled elimination with
pivoting as selects up to ``UNROLL_MAX``, a ``fori_loop`` elimination beyond.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["where", "parts", "entries", "small_tmatmul", "solve_blocks", "small_max", "small_norm", "solve_small",
           "inv_small", "cond1", "det_small"]

def where(c, x, y):
    """``where(c, x, y)`` written with ``lax.select_n``.

    ``jnp.where`` is a small jitted function; under ``vmap`` every call is traced and
    batched as a nested program, and the per-sample solver code calls it hundreds of times
    (measured: 254 nested ``_where`` programs in one stroke, a third of its tracing time).
    Same broadcasting and dtype promotion as ``jnp.where``.
    """
    x, y = jnp.asarray(x), jnp.asarray(y)
    dtype = jnp.result_type(x, y)
    c = jnp.asarray(c)
    shape = jnp.broadcast_shapes(c.shape, x.shape, y.shape)

    def full(a, dt):
        a = a if a.dtype == dt else jax.lax.convert_element_type(a, dt)
        return a if a.shape == shape else jax.lax.broadcast_in_dim(a, shape, tuple(range(len(shape) - a.ndim, len(shape))))

    return jax.lax.select_n(full(c, jnp.bool_), full(y, dtype), full(x, dtype))


def parts(x, axis: int = 0) -> list:
    """The entries of ``x`` along ``axis``, as a list of arrays without that axis: one
    ``split`` and a ``squeeze`` each (the same slices as ``x[i]``; tracing ``x[i]`` costs
    ~150 us of Python each, and the solver code takes ~1,200 entries per scene program)."""
    axis = axis % x.ndim
    n = x.shape[axis]
    pieces = [x] if n == 1 else jax.lax.split(x, (1,) * n, axis=axis)
    return [jax.lax.squeeze(y, (axis,)) for y in pieces]


def entries(a) -> list:
    """``a (n, k, ...)`` as nested lists ``e[i][j]`` of its ``(...)`` entries."""
    return [parts(row, 0) for row in parts(a, 0)]


# Per-sample systems are tiny (m = 1..8) and run under vmap over up to 1e6 samples.  XLA's
# CPU batched LAPACK path is ~12x slower per sample than straight-line code, and reductions
# over a size-m axis end an XLA fusion (everything feeding them is recomputed in the next
# one), so small sizes are unrolled into elementwise operations.  Up to 4x4: unrolling a
# 6x6 elimination (flap_msd) added ~8 s of compile per function for no measurable gain.
UNROLL_MAX = 4


def small_max(x):
    """Max over the last axis, unrolled for small sizes (0 for an empty axis: every use is a
    maximum of magnitudes, and a mechanism without dependent coordinates has none)."""
    if x.shape[-1] == 0:
        return jnp.zeros(x.shape[:-1], x.dtype)
    if x.shape[-1] > UNROLL_MAX:
        return jnp.max(x, axis=-1)
    return functools.reduce(jnp.maximum, parts(x, -1))


def small_sum(x):
    """Sum over the last axis, unrolled for small sizes."""
    if x.shape[-1] == 0 or x.shape[-1] > UNROLL_MAX:
        return jnp.sum(x, axis=-1)
    return functools.reduce(jnp.add, parts(x, -1))


def small_tmatmul(a, b):
    """``a.T @ b`` for a small ``a (n, k)`` and ``b (n,)`` or ``(n, j)``, written out as sums of
    products for ``n <= UNROLL_MAX``.  Under ``vmap`` a ``dot`` is lowered by XLA according to
    the batch size, with a different rounding (measured: a sweep in chunks of 1 and of 9
    designs differed in the last bit); the written-out sums are the same for every batch,
    and they fuse with their neighbours."""
    if a.shape[0] == 0 or a.shape[0] > UNROLL_MAX:
        return a.T @ b
    ra, rb = parts(a, 0), parts(b, 0)
    terms = [ai[:, None] * bi[None] if b.ndim == 2 else ai * bi for ai, bi in zip(ra, rb)]
    return functools.reduce(jnp.add, terms)


def small_norm(x):
    """Euclidean norm of a vector, unrolled for small sizes."""
    return jnp.sqrt(small_sum(x * x))


def _gauss_unrolled(a, b):
    """Gaussian elimination with partial pivoting, written out for ``3 <= n <= UNROLL_MAX``.

    `b` is ``(n,)`` or ``(n, k)``.  Row swaps are selects, so the whole solve is one
    straight-line elementwise program under vmap.  ``a`` and ``b`` are eliminated side by
    side (not as one augmented matrix) so the solve stays linear in ``b`` for reverse mode.
    """
    n = a.shape[-1]
    vec = b.ndim == 1
    ra = parts(a, 0)
    rb = [r.reshape(-1) for r in parts(b, 0)]
    for k in range(n):
        # pivot: bring the largest |a[i, k]|, i >= k, to row k
        for i in range(k + 1, n):
            swap = jnp.abs(ra[i][k]) > jnp.abs(ra[k][k])
            ra[k], ra[i] = where(swap, ra[i], ra[k]), where(swap, ra[k], ra[i])
            rb[k], rb[i] = where(swap, rb[i], rb[k]), where(swap, rb[k], rb[i])
        for i in range(k + 1, n):
            f = ra[i][k] / ra[k][k]
            ra[i] = ra[i] - f * ra[k]
            rb[i] = rb[i] - f * rb[k]
    x = [None] * n
    for i in reversed(range(n)):
        acc = rb[i]
        for j in range(i + 1, n):
            acc = acc - ra[i][j] * x[j]
        x[i] = acc / ra[i][i]
    out = jnp.stack(x)
    return out[:, 0] if vec else out


def _gauss_loop(a, b):
    """Gaussian elimination with partial pivoting as a ``fori_loop`` over columns, for
    ``n > UNROLL_MAX``: compact to compile, elementwise under vmap (no batched LAPACK
    call; those were seen to hang the jaxlib 0.10 CPU runtime in large batched loops).
    ``a`` and ``b`` are eliminated side by side so the solve stays linear in ``b``.
    """
    n = a.shape[-1]
    vec = b.ndim == 1
    rhs = b.reshape(n, -1)
    rows = jnp.arange(n)

    def eliminate(k, state):
        m, r = state
        col = where(rows >= k, jnp.abs(m[:, k]), -1.0)
        piv = jnp.argmax(col)
        perm = rows.at[k].set(piv).at[piv].set(k)
        m, r = m[perm], r[perm]
        f = where(rows > k, m[:, k] / m[k, k], 0.0)
        return m - f[:, None] * m[k][None, :], r - f[:, None] * r[k][None, :]

    m, r = jax.lax.fori_loop(0, n, eliminate, (a, rhs))

    def substitute(j, x):
        i = n - 1 - j
        xi = (r[i] - m[i] @ x) / m[i, i]  # x[i:] rows not yet set are zero
        return x.at[i].set(xi)

    x = jax.lax.fori_loop(0, n, substitute, jnp.zeros_like(r))
    return x[:, 0] if vec else x


def solve_small(a, b):
    """Solve ``a x = b`` for one small dense system (``b`` of shape ``(n,)`` or ``(n, k)``).

    Cramer's rule for 1x1 and 2x2, unrolled elimination up to ``UNROLL_MAX``, a loop beyond.
    """
    n = a.shape[-1]
    if n == 0:  # no unknowns (a mechanism without dependent coordinates)
        return b
    if n == 1:
        return b / jnp.reshape(a, ())
    if n == 2:
        (a00, a01), (a10, a11) = entries(a)
        b0, b1 = parts(b, 0)
        det = a00 * a11 - a01 * a10
        x0 = (a11 * b0 - a01 * b1) / det
        x1 = (a00 * b1 - a10 * b0) / det
        return jnp.stack([x0, x1])
    if n <= UNROLL_MAX:
        return _gauss_unrolled(a, b)
    return _gauss_loop(a, b)


def solve_blocks(a, b, blocks):
    """Solve ``a x = b`` where ``a`` is block lower triangular after the permutation
    ``blocks`` (``((rows, cols), ...)`` in solving order, as ``structure.blocks`` gives):
    one small solve per diagonal block, earlier blocks' unknowns moved to the right-hand
    side (written out as products, no ``dot``).  ``blocks`` of one block: ``solve_small``."""
    if len(blocks) == 1:
        return solve_small(a, b)
    vec = b.ndim == 1
    bb = parts(b[:, None] if vec else b, 0)
    e = entries(a)
    x: dict[int, jax.Array] = {}
    for rows, cols in blocks:
        rhs = [bb[i] for i in rows]
        for j, xj in x.items():
            rhs = [r - e[i][j] * xj for r, i in zip(rhs, rows)]
        sub = jnp.stack([jnp.stack([e[i][j] for j in cols]) for i in rows])
        xb = solve_small(sub, jnp.stack(rhs))
        for j, xj in zip(cols, parts(xb, 0)):
            x[j] = xj
    out = jnp.stack([x[j] for j in range(a.shape[-1])])
    return out[:, 0] if vec else out


def inv_small(a, blocks=None):
    """Inverse of a small matrix (by ``solve_blocks`` when its ``blocks`` are given)."""
    eye = np.eye(a.shape[-1], dtype=a.dtype)
    return solve_small(a, eye) if blocks is None else solve_blocks(a, eye, blocks)


def cond1(a, blocks=None):
    """1-norm condition number of a small square matrix (inf where singular); ``blocks``:
    its block-triangular structure, if any (``solve_blocks``); 1 for an empty matrix."""
    if a.shape[-1] == 0:
        return jnp.ones((), a.dtype)
    norm1 = lambda m: small_max(small_sum(jnp.abs(m).T))  # noqa: E731  (max column sum)
    c = norm1(a) * norm1(inv_small(a, blocks))
    return where(jnp.isfinite(c), c, jnp.inf)


def det_small(a):
    """Determinant of a small square matrix: written out to 3x3, Gaussian elimination with
    partial pivoting (selects, a sign flip per swap) beyond: no LAPACK call (an executable
    with one does not run when a new process loads it from the store: jaxlib 0.10)."""
    n = a.shape[-1]
    if n == 0:
        return jnp.ones((), a.dtype)
    e = entries(a)
    if n == 1:
        return e[0][0]
    if n == 2:
        return e[0][0] * e[1][1] - e[0][1] * e[1][0]
    if n == 3:
        return (e[0][0] * (e[1][1] * e[2][2] - e[1][2] * e[2][1]) - e[0][1] * (e[1][0] * e[2][2] - e[1][2] * e[2][0])
                + e[0][2] * (e[1][0] * e[2][1] - e[1][1] * e[2][0]))
    ra = parts(a, 0)
    det = jnp.ones((), a.dtype)
    for k in range(n):
        for i in range(k + 1, n):
            swap = jnp.abs(ra[i][k]) > jnp.abs(ra[k][k])
            ra[k], ra[i] = where(swap, ra[i], ra[k]), where(swap, ra[k], ra[i])
            det = where(swap, -det, det)
        for i in range(k + 1, n):
            ra[i] = ra[i] - (ra[i][k] / ra[k][k]) * ra[k]
        det = det * ra[k][k]
    return det
