"""Block-triangular order of the constraint equations: model only what a scene needs.

Coupled loops are often coupled one way only: flap_msd's first loop fixes ``(beta, delta)``,
its second then needs ``delta`` alone to give ``(phi, psi)``, its third ``delta`` and ``psi``
to give ``(xi, theta)``.  Its 6x6 Jacobian is then block lower triangular after a
permutation, and a linear solve is three 2x2 solves in sequence, as its report solved
them by hand, instead of one 6x6 elimination: cheaper to compile and to run.

The order is found once per mechanism, as Modelica tools do: the structural sparsity of
``d Phi / d q`` from the traced program of the constraints (which equation reads which
coordinate), a maximum matching of equations to coordinates, then Tarjan's strongly
connected components of the dependency graph, emitted dependencies first.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .mechanism import Mechanism, Vars, equation_entries

__all__ = ["sparsity", "blocks", "block_order", "coords_read"]


def _dependencies(jaxpr, inputs: list[frozenset]) -> list[frozenset]:
    """For each output of ``jaxpr``, the set of inputs it depends on (structurally: an
    equation's outputs depend on all its inputs; sub-programs are taken whole)."""
    env: dict = {}
    for var, dep in zip(jaxpr.invars, inputs):
        env[var] = dep

    def read(v):
        return frozenset() if hasattr(v, "val") else env.get(v, frozenset())  # a literal: no dependency

    for eqn in jaxpr.eqns:
        dep = frozenset().union(*[read(v) for v in eqn.invars]) if eqn.invars else frozenset()
        for v in eqn.outvars:
            env[v] = dep
    return [read(v) for v in jaxpr.outvars]


def coords_read(mech: Mechanism, fn) -> list[frozenset]:
    """For each real scalar that ``fn(q, u, p)`` (named views, as constraints take them)
    returns, the set of coordinate indices it reads (structurally, from its traced program)."""
    dtype = jnp.zeros(()).dtype
    m = mech.m

    def scalars(*qs):
        u, p = qs[m], qs[m + 1]
        return tuple(equation_entries(fn(Vars(dict(zip(mech.coords, qs[:m]))), mech.vars_u(u), mech.vars_p(p))))

    args = [jax.ShapeDtypeStruct((), dtype)] * m
    args += [jax.ShapeDtypeStruct((mech.dof,), dtype), {n: jax.ShapeDtypeStruct((), dtype) for n in mech.params}]
    closed = jax.make_jaxpr(scalars)(*args)
    n_in = len(closed.jaxpr.invars)
    inputs = [frozenset([j]) if j < m else frozenset() for j in range(n_in)]
    return _dependencies(closed.jaxpr, inputs)


def sparsity(mech: Mechanism) -> np.ndarray:
    """``(m, m)`` bool: entry ``[i, j]`` is True where equation ``i`` reads coordinate ``j``."""
    m = mech.m
    deps = coords_read(mech, mech.constraints)
    if len(deps) != m:  # the residual's own check reports this properly
        return np.ones((m, m), bool)
    pattern = np.zeros((m, m), bool)
    for i, dep in enumerate(deps):
        for j in dep:
            pattern[i, j] = True
    return pattern


def _matching(pattern: np.ndarray) -> list[int] | None:
    """A perfect matching equation -> coordinate (Kuhn's augmenting paths), or None."""
    m = pattern.shape[0]
    owner = [-1] * m  # coordinate -> equation

    def augment(i, seen):
        for j in np.flatnonzero(pattern[i]):
            if j in seen:
                continue
            seen.add(j)
            if owner[j] < 0 or augment(owner[j], seen):
                owner[j] = i
                return True
        return False

    for i in range(m):
        if not augment(i, set()):
            return None
    match = [0] * m
    for j, i in enumerate(owner):
        match[i] = j
    return match


def _components(edges: list[list[int]]) -> list[list[int]]:
    """Tarjan's strongly connected components; each is emitted after every component it
    reaches, so with edges "i needs k" the list is in solving order."""
    n = len(edges)
    index, low, on_stack, stack, out = {}, {}, set(), [], []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on_stack.add(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            out.append(sorted(comp))

    for v in range(n):
        if v not in index:
            visit(v)
    return out


def block_order(pattern: np.ndarray) -> tuple[tuple[tuple[int, ...], tuple[int, ...]], ...] | None:
    """The block lower-triangular order of a square system with structural sparsity
    ``pattern`` (``[i, j]``: equation ``i`` reads unknown ``j``): ``((rows, cols), ...)`` in
    solving order, each a square block of equations and the unknowns they determine once
    the earlier blocks are known; None when the pattern is structurally singular."""
    n = pattern.shape[0]
    match = _matching(pattern)
    if match is None:
        return None
    eq_of = {j: i for i, j in enumerate(match)}
    edges = [[eq_of[j] for j in np.flatnonzero(pattern[i]) if eq_of[j] != i] for i in range(n)]
    comps = _components(edges)
    return tuple((tuple(c), tuple(sorted(match[i] for i in c))) for c in comps)


@functools.lru_cache(maxsize=256)
def blocks(mech: Mechanism) -> tuple[tuple[tuple[int, ...], tuple[int, ...]], ...]:
    """The solving order of ``mech``'s equations: ``((rows, cols), ...)``, each a square
    block of equations and the coordinates they determine once the earlier blocks are
    known.  One block with everything when the system does not decompose (or a function
    does not trace)."""
    m = mech.m
    whole = ((tuple(range(m)), tuple(range(m))),)
    if m == 0:  # nothing to order (a mechanism without dependent coordinates)
        return whole
    try:
        pattern = sparsity(mech)
    except Exception:  # noqa: BLE001 - a constraint that does not trace: no structure (its error shows at solve time)
        return whole
    order = block_order(pattern)
    return whole if order is None else order  # structurally singular: the solve reports it
