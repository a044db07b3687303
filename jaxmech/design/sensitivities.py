"""Sensitivities of a figure of merit over a batch of designs: ``jax.vmap`` of
``jax.value_and_grad`` through the implicit position solve, gradients and elasticities."""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..solver.xla import jit
from .figures import as_batch, figure_value

__all__ = ["Sensitivities", "batch_jacobian", "sensitivities"]


# =========================================================================== sensitivities
@dataclasses.dataclass(frozen=True)
class Sensitivities:
    """Gradients of a figure of merit for a batch of designs.

    - `figure`: the figure's name.
    - `params`: ``{name: (D,)}`` the designs.
    - `value`: ``(D,)`` the figure (NaN where the design failed).
    - `grad`: ``{name: (D,)}`` ``df/dp`` in figure units per parameter unit (NaN where
      the design failed).
    - `ok`: ``(D,)`` designs whose figure is defined (every sample converged).
    """

    figure: str
    params: dict
    value: np.ndarray
    grad: dict
    ok: np.ndarray

    @property
    def elasticity(self) -> dict[str, np.ndarray]:
        """Normalised sensitivities ``(p / f) df/dp`` (dimensionless: % change of f per %
        change of p); NaN where ``f == 0`` or the design failed."""
        with np.errstate(divide="ignore", invalid="ignore"):
            f = np.where(self.value != 0, self.value, np.nan)
            return {k: self.params[k] * g / f for k, g in self.grad.items()}

    def table(self, kind: str = "elasticity", max_rows: int = 20) -> str:
        """Readable text table, one row per design (at most `max_rows`).

        `kind`: ``"elasticity"`` (``(p/f) df/dp``) or ``"gradient"`` (``df/dp``).
        """
        if kind not in ("elasticity", "gradient"):
            raise ValueError(f"table: kind must be 'elasticity' or 'gradient', got {kind!r}")
        data = self.elasticity if kind == "elasticity" else self.grad
        title = "(p/f) df/dp" if kind == "elasticity" else "df/dp"
        names = list(data)
        width = max(12, *(len(n) + 2 for n in names))
        lines = [f"{kind} {title} of {self.figure}", f"{'design':>6}  {self.figure:>14}" + "".join(f"{n:>{width}}" for n in names)]
        d = len(self.value)
        for i in range(min(d, max_rows)):
            if not self.ok[i]:
                lines.append(f"{i:>6}  {'failed':>14}  (a sample did not converge: no figure, no gradient)")
                continue
            lines.append(f"{i:>6}  {self.value[i]:>14.6g}" + "".join(f"{data[n][i]:>{width}.4g}" for n in names))
        if d > max_rows:
            lines.append(f"... {d - max_rows} more designs")
        return "\n".join(lines)


@functools.partial(jit, static_argnums=(0, 1))
def batch_jacobian(fn: Callable, forward: bool, p_wrt, p_rest):
    """Values and exact first derivatives of ``fn`` over a batch of designs, one compiled call.

    `fn` maps one design ``{name: scalar}`` to ``(values, aux)``: `values` any pytree of
    float scalars (figure units), `aux` anything carried along undifferentiated.  `p_wrt`
    ``{name: (D,)}`` are differentiated, `p_rest` ``{name: (D,)}`` held.  `forward`:
    ``jax.jacfwd`` (one tangent per name in `p_wrt`: cheap for few parameters and many
    values, ``tolerance.analyse``) or ``jax.jacrev`` (one cotangent per value: a scalar
    figure's gradient, ``sensitivities``).  The positions' derivatives come from the implicit
    function theorem in either mode.

    **Returns** ``(values, aux, jacobian)`` with ``(D,)`` in front of every leaf;
    ``jacobian`` has `values`' structure with ``{name: d value / d name}`` at each leaf
    (figure units per parameter unit).
    """

    def one(pw, pr):
        def split(w):
            values, aux = fn({**pr, **w})
            return values, (values, aux)

        jac, (values, aux) = (jax.jacfwd if forward else jax.jacrev)(split, has_aux=True)(pw)
        return values, aux, jac

    return jax.vmap(one)(p_wrt, p_rest)


@dataclasses.dataclass(frozen=True)
class _Masked:
    """A figure as ``batch_jacobian`` takes it: ``p -> (masked value, (value, ok))``;
    hashable as its figure is (one compiled program per figure)."""

    figure: Callable

    def __call__(self, p):
        # Differentiate the masked value: a failed design contributes a zero cotangent.
        value, ok = figure_value(self.figure(p))
        return jnp.where(ok, value, 0.0), (value, ok)


def sensitivities(figure: Callable, params: Mapping, *, wrt: Sequence[str] | None = None) -> Sensitivities:
    """Gradient of a scalar figure of merit w.r.t. every parameter, for a batch of designs.

    Computed as ``jax.vmap(jax.value_and_grad(figure))`` in one compiled call; the
    derivatives of the positions come from the implicit function theorem.

    **Arguments**

    - `figure`: ``f(p) -> value`` or ``-> (value, ok)`` for one design, ``p`` a mapping
      of scalars, written in ``jax.numpy`` (for a scene: ``scene_figure``).  A value that
      is not finite, or ``ok`` False, marks the design failed.  A figure must mask the
      inputs of its own computations where it fails (``scene_figure`` does).
    - `params`: ``{name: (D,) or scalar}`` the designs (SI units); scalars broadcast.
    - `wrt`: names to differentiate with respect to (default: every name in `params`).

    **Returns** a ``Sensitivities`` (values, gradients, elasticities, a text table).
    """
    batch, _ = as_batch(params, "sensitivities")
    wrt = tuple(batch) if wrt is None else tuple(wrt)
    unknown = [k for k in wrt if k not in batch]
    if unknown:
        raise ValueError(f"sensitivities: wrt names {unknown} are not in params {list(batch)}")
    p_wrt = {k: batch[k] for k in wrt}
    p_rest = {k: v for k, v in batch.items() if k not in wrt}
    _, (value, ok), grad = batch_jacobian(_Masked(figure), False, p_wrt, p_rest)
    ok = np.asarray(ok)
    value = np.where(ok, np.asarray(value), np.nan)
    grad = {k: np.where(ok, np.asarray(grad[k]), np.nan) for k in wrt}
    return Sensitivities(
        figure=getattr(figure, "name", getattr(figure, "__name__", "f")),
        params={k: np.asarray(v) for k, v in batch.items()},
        value=value,
        grad=grad,
        ok=ok,
    )
