"""Design studies on whole batches: sensitivities, peaks over a stroke, multi-start fits,
constrained design, tolerance analysis and path synthesis (the design layer, in one place).

A *figure of merit* is any scalar function of one design's parameters, ``f(p)``, for
example the peak motor torque or the final flap angle.  Its derivatives come from the
implicit function theorem through the position solve (``jaxmech.solve``), never from
differentiating Newton iterations, so ``jax.grad`` of a figure is exact to the solver's
tolerance and costs about one extra stroke evaluation whatever the number of parameters.

- ``scene_figure`` builds a figure from a scene and a reduction of its table columns.
- ``sensitivities`` evaluates ``jax.vmap(jax.value_and_grad(figure))`` over a batch of
  designs and reports gradients and elasticities ``(p/f) df/dp``.
- ``peak`` takes a maximum over the stroke in a way whose gradient is right.
- ``fit`` runs optax from a batch of starting designs at once (multi-start) and says which
  start won and why each of the others stopped.
- ``constrained`` (``minimize``, ``program``, ``Stated``): a design problem as an engineer
  states it (least peak over the stroke, equalities, limits, a box), solved by scipy's SLSQP
  fed one compiled program of exact Jacobians; ``minimize_second_order``: the same statement
  by an SQP with exact Hessians (``sqp``, its QPs by ``qp``), every start in one vmapped
  program; a ``StrokeProblem`` (rows of the motion at each stroke sample) gets its
  Lagrangian's Hessian by a second-order adjoint (``stroke_problem``), a program several
  times smaller than nested automatic differentiation through the solver.
- ``refine``: the best designs of a sweep (``best_designs``) refined in one
  ``minimize_second_order`` call under a statement over a scene's table columns
  (``scene_problem``: least peak of a column, limits at every sample).
- ``tolerance`` (``analyse``, ``monte_carlo``): the spread of figures from manufacturing
  tolerances, first order (forward-mode Jacobians, ``batch_jacobian``) and by sampling.
- ``synthesize_path`` finds a four-bar whose coupler curve passes through (or nearest to)
  target points, closed, open or partial, with or without prescribed crank angles;
  ``path_error`` is its error measure (distance from each target to the feasible curve).

Failed designs (a sample that does not converge) are masked with ``jnp.where`` on the
*inputs* of every later computation, so a failure gives a NaN value and a NaN gradient
for that design alone, never a NaN in the gradient of a batch.
"""

from .figures import SceneFigure as SceneFigure
from .figures import peak as peak
from .figures import scene_figure as scene_figure
from .fitting import FitResult as FitResult
from .fitting import fit as fit
from .sensitivities import Sensitivities as Sensitivities
from .sensitivities import sensitivities as sensitivities
from .refine import best_designs as best_designs
from .refine import refine as refine
from .refine import scene_problem as scene_problem
from .second_order import SecondOrderResult as SecondOrderResult
from .second_order import minimize_second_order as minimize_second_order
from .sqp import SQPOptions as SQPOptions
from .stroke_problem import StrokeProblem as StrokeProblem
from .synthesis import PathError as PathError
from .synthesis import PathSynthesis as PathSynthesis
from .synthesis import coupler_curve as coupler_curve
from .synthesis import crank_intervals as crank_intervals
from .synthesis import path_error as path_error
from .synthesis import synthesize_path as synthesize_path

__all__ = [
    "FitResult",
    "SceneFigure",
    "Sensitivities",
    "fit",
    "peak",
    "scene_figure",
    "sensitivities",
    "SQPOptions",
    "SecondOrderResult",
    "StrokeProblem",
    "minimize_second_order",
    "best_designs",
    "refine",
    "scene_problem",
    "PathError",
    "PathSynthesis",
    "coupler_curve",
    "crank_intervals",
    "path_error",
    "synthesize_path",
]


def __getattr__(name):
    """The result codes' retired names (deprecated: ``jaxmech.Status``, ``status.RETIRED``)."""
    from ..solver.status import retired

    return retired(__name__, name)
