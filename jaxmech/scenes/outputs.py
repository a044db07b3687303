"""What a scene's outputs are: their names and units, in column order.

A scene declares them: its ``outputs`` is an ``Outputs(fn, {name: unit, ...})``, the units
in the order its table shows them, and ``fn(p, motion)`` returns ``{name: values}`` for
those names.  Called, an ``Outputs`` gives ``{name: (values, unit)}`` in that order, the
form every consumer reads.  A scene whose ``outputs`` is a plain function returning
``{name: (values, unit)}`` (a user's scene written before the declaration existed) still
works: its names and units are found once, here, by tracing it on an abstract one-design
motion (shapes only: nothing is computed or compiled).  Units are strings, which cannot
leave a compiled program: every path that runs the outputs compiled (``run_scene``, the
sweeps, ``jaxmech.design``, the live view) names its output columns from ``output_units``.

Outputs that do not trace (a function converting values to numpy) are evaluated on the
host, design by design; ``run_outputs`` is the one place that tells them apart.
"""

from __future__ import annotations

import dataclasses
import weakref
from collections.abc import Callable, Mapping

import jax
import jax.numpy as jnp

from ..kinematics import Motion
from ..solver.status import Status

__all__ = ["Outputs", "STATUS", "abstract_motion", "output_units", "run_outputs", "sample_status", "merged_status"]

#: The key under which an ``Outputs(..., status=True)`` function returns its samples' status.
STATUS = "status"


@dataclasses.dataclass(frozen=True, eq=False)
class Outputs:
    """A scene's outputs, declared.

    - `fn`: ``fn(p, motion) -> {name: values (N,)}`` for one design (``p`` every parameter
      of the scene, SI; ``motion`` its ``Motion`` over the stroke), in ``jax.numpy`` to run
      inside the compiled programs.
    - `units`: ``{name: unit}`` for every name `fn` returns, in column order.
    - `parts`: optional ``{name: fn(p, motion) -> values (N,)}``: a lighter function for one
      output alone, equal to `fn`'s (e.g. a drive's effort by virtual power, without every
      joint's reaction), used where only some outputs are read (``design.scene_problem``).
    - `status`: whether `fn` also returns, under ``STATUS``, each sample's ``Status``
      ``(N,)`` of its outputs: ``CONVERGED`` where they hold, another code where the
      position converged but the outputs could not be evaluated (a linkage jammed by joint
      friction: ``MAX_STEPS``).  The scene's status is then the motion's where that is not
      ``CONVERGED``, else this (``sample_status``), wherever the outputs are compiled in
      (``run_scene``, the sweeps, ``design_columns``), and its table masks those samples.

    Calling it returns ``{name: (values, unit)}`` in the order of `units`; ``ValueError``
    names an output `fn` returns without declaring it, or a declared one it does not return.
    """

    fn: Callable
    units: Mapping[str, str]
    parts: Mapping[str, Callable] = dataclasses.field(default_factory=dict)
    status: bool = False

    def __post_init__(self):
        if not callable(self.fn):
            raise ValueError(f"Outputs: fn must be a function fn(p, motion) -> {{name: values}}, got {self.fn!r}")
        bad = [k for k, u in dict(self.units).items() if not (isinstance(k, str) and isinstance(u, str))]
        if bad or not self.units:
            raise ValueError(f"Outputs: units must map each output name to its unit string, got {self.units!r}")
        object.__setattr__(self, "units", dict(self.units))
        unknown = [k for k in self.parts if k not in self.units]
        if unknown:
            raise ValueError(f"Outputs: parts {unknown} are not declared in units {list(self.units)}")
        object.__setattr__(self, "parts", dict(self.parts))

    def one(self, name: str, p, motion):
        """Output `name` alone: its part's function where one is given, else `fn`'s value."""
        return self.parts[name](p, motion) if name in self.parts else self.fn(p, motion)[name]

    def evaluate(self, p, motion) -> tuple:
        """``({name: (values, unit)}, status (N,) or None)``: the outputs as a call gives
        them, and their own per-sample status where `status` is declared (else None)."""
        values = dict(self.fn(p, motion))
        own = values.pop(STATUS, None) if self.status else None
        missing = [k for k in self.units if k not in values] + ([STATUS] if self.status and own is None else [])
        extra = [k for k in values if k not in self.units]
        if missing or extra:
            raise ValueError(f"Outputs of {getattr(self.fn, '__name__', self.fn)!r}: declared but not returned {missing}, "
                             f"returned but not declared {extra}")
        return {k: (values[k], unit) for k, unit in self.units.items()}, own

    def __call__(self, p, motion) -> dict:
        return self.evaluate(p, motion)[0]


def sample_status(scene, p, motion) -> tuple:
    """``(outputs {name: (values, unit)}, own status (N,) or None)`` of one design: the
    scene's outputs at its `motion`, and their own per-sample status where they declare
    one (``Outputs.status``), None otherwise (the motion's status stands: nothing is added
    to the program).  ``merged_status`` combines the two."""
    if isinstance(scene.outputs, Outputs):
        return scene.outputs.evaluate(p, motion)
    return scene.outputs(p, motion), None


def merged_status(status, own):
    """The samples' status: `status` (the motion's) where it is not ``CONVERGED``, else
    the outputs' `own` (``sample_status``); `status` itself where `own` is None."""
    if own is None:
        return status
    return jnp.where(status == Status.CONVERGED, jnp.asarray(own, status.dtype), status)


def abstract_motion(scene, points: int = 2) -> Motion:
    """One design's ``Motion`` over ``points`` samples as shapes and dtypes only
    (``jax.ShapeDtypeStruct`` leaves, the default float dtype): what ``outputs`` is traced on."""
    mech = scene.mechanism
    real, cplx = jnp.result_type(float), jnp.result_type(complex)
    m, dof = len(mech.coords), mech.dof

    def spec(*shape, dtype=real):
        return jax.ShapeDtypeStruct((points, *shape), dtype)

    return Motion(
        t=spec(), u=spec(dof), u_dot=spec(dof), u_ddot=spec(dof), q=spec(m), q_dot=spec(m), q_ddot=spec(m),
        dq_du=spec(m, dof), d2q_du2=spec(m, dof, dof),
        points={k: (spec(dtype=cplx),) * 3 for k in mech.points}, status=spec(dtype=jnp.int32),
        coords=mech.coords, inputs=mech.inputs,
    )


def _traced_units(scene) -> dict | None:
    """An undeclared scene's ``{name: unit}``, found by tracing ``scene.outputs`` once on
    ``abstract_motion`` (shapes only); ``None`` where they do not trace."""
    if scene not in _FOUND:
        found = {}

        def one(p, mo):
            outs = scene.outputs(p, mo)
            found.update((k, unit) for k, (_, unit) in outs.items())
            return {k: jnp.asarray(v) for k, (v, _) in outs.items()}

        p = {k: jax.ShapeDtypeStruct((), jnp.result_type(float)) for k in scene.defaults}
        try:
            jax.eval_shape(one, p, abstract_motion(scene))
        except jax.errors.JAXTypeError:  # outputs converting traced values to numpy or Python
            found = None
        _FOUND[scene] = found
    return _FOUND[scene]


# Per scene object (a frozen scene's outputs never change): the units ``_traced_units``
# found, and the scenes whose outputs turned out not to trace (``run_outputs``).
_FOUND: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
_ON_HOST: weakref.WeakSet = weakref.WeakSet()


def output_units(scene) -> dict[str, str]:
    """``{output name: unit}`` in column order: the scene's declaration (``Outputs``), or
    what its plain ``outputs`` function returns, found once by tracing it; ``{}`` without
    outputs.  Raises ``ValueError`` for an undeclared function that does not trace (its
    units are known only where it is evaluated, on the host, with its values)."""
    if scene.outputs is None:
        return {}
    if isinstance(scene.outputs, Outputs):
        return dict(scene.outputs.units)
    units = _traced_units(scene)
    if units is None:
        raise ValueError(f"scene {scene.name!r}: its outputs do not trace and do not declare their units; "
                         f"declare them: outputs=Outputs(fn, {{name: unit, ...}})")
    return dict(units)


def run_outputs(scene, run: Callable):
    """``run(traced)``, the one place where outputs that do not trace are told apart:
    ``run(True)`` compiles the scene's outputs into the programs; where tracing them raises
    ``jax.errors.JAXTypeError`` (outputs converting traced values to numpy or Python),
    ``run(False)`` instead (the caller evaluates them on the host, design by design), and
    the scene is remembered as such.  A scene without outputs: ``run(True)``."""
    if scene.outputs is not None and scene not in _ON_HOST:
        try:
            return run(True)
        except jax.errors.JAXTypeError:
            _ON_HOST.add(scene)
    return run(scene.outputs is None)
