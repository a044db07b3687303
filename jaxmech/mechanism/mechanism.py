"""A planar mechanism as named coordinates, parameters and loop-closure equations.

A mechanism is nothing more than

* ``coords``: the dependent coordinates ``q`` (joint angles, slider travels),
* ``inputs``: the driven coordinates ``u``, one per degree of freedom,
* ``params``: the named parameters ``p`` (lengths, masses, coefficients),
* ``constraints(q, u, p)``: the loop-closure equations, written the way the
  engineering reports write them.  Each entry of the returned sequence is either
  a *complex* vector loop ``sum_k l_k e^{i theta_k} = 0`` (two real equations:
  real and imaginary part) or a *real* scalar equation (a pin on a circular slot,
  a point on a line).

``q``, ``u`` and ``p`` arrive as namespaces, so equations read like the paper::

    fourbar = Mechanism(
        coords=("theta3", "theta4"),
        inputs=("theta2",),
        params=("a", "b", "c", "d"),
        constraints=lambda q, u, p: [
            p.a * cis(u.theta2) + p.b * cis(q.theta3) - p.c * cis(q.theta4) - p.d
        ],
    )

Units: SI throughout.  Which coordinates and parameters are lengths is declared
(``lengths``) so that tolerances scale with the design (millimetres and metres
give the same angles and statuses) and so that a negative length is caught early.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
from collections.abc import Callable, Mapping, Sequence
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..solver.linalg import parts
from ..solver.xla import unfused

__all__ = ["Mechanism", "cis", "Vars", "equation_entries"]


@jax.custom_jvp
def _cos_sin(angle):
    """``(cos angle, sin angle)``, each evaluated once however many derivatives use them.

    XLA's CPU fusion copies an elementwise producer into every consumer fusion, so in a
    Newton step plus its Jacobian, tangents and second derivatives the same ``sin`` was
    evaluated 3-4 times per sample (measured: 17 sines where 5 are needed for the four-bar
    fast path).  An identity product is not fused, so it makes the pair one materialised
    array; the custom JVP reuses that pair (d cis = i cis d angle) instead of calling
    ``sin``/``cos`` again.  Exact: ``1 x + 0 y`` is ``x`` for finite values, and cos and sin
    of one angle are finite or NaN together.  Measured on the four-bar fast path: 271 ->
    160 ns per position (benchmarks/kinematics.py).
    """
    angle = jnp.asarray(angle)
    c, s = parts(unfused(jnp.stack([jnp.cos(angle), jnp.sin(angle)])), 0)
    return c, s


@_cos_sin.defjvp
def _cos_sin_jvp(primals, tangents):
    (angle,), (dangle,) = primals, tangents
    c, s = _cos_sin(angle)
    return (c, s), (-s * dangle, c * dangle)


def cis(angle):
    """``e^{i angle}`` as a complex number: the unit vector at ``angle`` (rad, CCW from +x).

    Differentiable to any order; cos and sin are computed once per angle (see ``_cos_sin``).
    """
    c, s = _cos_sin(angle)
    return jax.lax.complex(c, s)


class Vars(Mapping):
    """Read-only name -> value view, with attribute access (``q.theta3``).

    Used to hand coordinates, inputs and parameters to user equations by name.
    """

    __slots__ = ("_data",)

    def __init__(self, data: Mapping[str, Any]):
        object.__setattr__(self, "_data", dict(data))

    def __getattr__(self, name):
        try:
            return self._data[name]
        except KeyError:
            known = ", ".join(self._data) or "(none)"
            raise AttributeError(f"unknown name {name!r}; known names: {known}") from None

    def __getitem__(self, name):
        return self._data[name]

    def __iter__(self):
        return iter(self._data)

    def __len__(self):
        return len(self._data)

    def __repr__(self):
        return f"Vars({self._data!r})"


def show_value(v) -> str:
    """A parameter value as a person writes it: ``-1.0``, ``[1.0, nan]``, never ``np.float64(-1.0)``."""
    arr = np.asarray(v)
    if arr.ndim == 0:
        return repr(arr.item())
    if arr.size <= 6:
        return repr(arr.tolist())
    return f"array of shape {arr.shape}"


def equation_entries(eqs) -> list:
    """The real equations of a constraint function's value (a sequence, a mapping
    ``{loop name: equation}`` or one equation), as scalars: a complex loop gives its real
    and imaginary parts, a real equation itself."""
    if isinstance(eqs, Mapping):
        eqs = list(eqs.values())
    if not isinstance(eqs, (list, tuple)):
        eqs = [eqs]
    out = []
    for e in eqs:
        e = jnp.asarray(e)
        out += [jnp.real(e), jnp.imag(e)] if jnp.iscomplexobj(e) else [e]
    return [jnp.reshape(x, ()) for x in out]


def _names(value, what: str) -> tuple[str, ...]:
    if isinstance(value, str):
        value = (value,)
    names = tuple(value)
    for n in names:
        if not isinstance(n, str) or not n.isidentifier():
            raise ValueError(f"{what}: {n!r} is not a valid name (use Python identifiers)")
    if len(set(names)) != len(names):
        raise ValueError(f"{what}: duplicate names in {names}")
    return names


class Identity(NamedTuple):
    """The names a mechanism's equality and hash start from (``Mechanism._identity``): equal
    mechanisms have equal identities (then their traced functions are compared)."""

    name: str
    coords: tuple
    inputs: tuple
    params: tuple
    lengths: Any
    signed: Any
    points: tuple


@dataclasses.dataclass(frozen=True, eq=False)
class Mechanism:
    """Static description of a planar mechanism (hashable, safe as a jit static argument).

    Two mechanisms are equal when their names and the programs their functions trace to
    (constraints, points, branch indicator, residual scale: the jaxprs and their captured
    constants) are equal, so an identical mechanism rebuilt in a notebook cell reuses
    everything already compiled for the first.

    **Arguments**

    - `coords`: names of the dependent coordinates ``q`` (``m`` of them).
    - `inputs`: names of the driven coordinates ``u`` (one per degree of freedom).
    - `params`: names of every parameter the scene uses (kinematic and physical).
    - `constraints`: ``fn(q, u, p) -> sequence`` of complex loops and real scalars (or a
      mapping ``{name: equation}``, which names each loop for messages and reactions);
      must give exactly ``m`` real equations.  ``None`` (or ``[]``) when there are no
      dependent coordinates: a mechanism of inputs only (a hinged flap, a rotating disc)
      is solved trivially and its dynamics and statics work like any other's.
    - `lengths`: names (of coords, inputs or params) measured in metres; required when
      the mechanism has parameters (``()`` when none is a length), so that a mass, an
      angle or ``g`` never enters the length scale by default.  The largest length
      parameter sets the residual scale, and length parameters must be positive (unless
      `signed`); other parameters (angles, masses, coefficients) may take any finite value.
    - `signed`: length parameters that may be zero or negative (offsets).  Every other
      length parameter must be positive and finite.
    - `points`: optional ``{name: fn(q, u, p) -> complex}`` points of interest (m).
    - `branch`: optional ``fn(q, u, p)`` whose sign identifies the assembly mode (for
      example a cross product): one real number, or one per assembly choice (a sequence,
      or a mapping ``{loop name: value}``), each checked on its own.  A solve reports
      ``BRANCH`` when a sign changed and names the loop (``Solution.message``).
    - `residual_scale`: optional ``fn(p) -> scalar or (m,)`` in the residual's own units.
      Loop closures are in metres and need none (the length scale is used); equations in
      other units (a moment balance in N m) give theirs here so that the residual tolerance
      means the same relative accuracy.
    - `name`: for messages.
    """

    coords: Sequence[str]
    inputs: Sequence[str]
    params: Sequence[str]
    constraints: Callable | None = None
    lengths: Sequence[str] | None = None
    signed: Sequence[str] = ()
    points: Mapping[str, Callable] = dataclasses.field(default_factory=dict)
    branch: Callable | None = None
    residual_scale: Callable | None = None
    name: str = "mechanism"

    def __post_init__(self):
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 (frozen dataclass)
        set_("coords", _names(self.coords, "coords"))
        set_("inputs", _names(self.inputs, "inputs"))
        set_("params", _names(self.params, "params"))
        every = self.coords + self.inputs + self.params
        if len(set(every)) != len(every):
            raise ValueError("coords, inputs and params must not share a name")
        if self.lengths is None and self.params:
            raise ValueError(
                f"{self.name}: say which parameters are lengths: lengths=(names in metres, of params, coords or "
                f"inputs; () if none); the parameters are {list(self.params)}")
        lengths = () if self.lengths is None else _names(self.lengths, "lengths")
        for n in lengths:
            if n not in every:
                raise ValueError(f"lengths: {n!r} is not a coordinate, input or parameter")
        set_("lengths", tuple(lengths))
        signed = _names(self.signed, "signed")
        for n in signed:
            if n not in self.params:
                raise ValueError(f"signed: {n!r} is not a parameter")
        set_("signed", signed)
        set_("points", dict(self.points))
        if self.constraints is None and self.coords:
            raise ValueError(f"constraints: {len(self.coords)} dependent coordinates {self.coords} need "
                             f"constraints=fn(q, u, p) -> sequence of equations")
        if self.constraints is not None and not callable(self.constraints):
            raise ValueError("constraints must be a function fn(q, u, p) -> sequence of equations")

    # ------------------------------------------------------------------ identity
    @functools.cached_property
    def _key(self):
        """What a compiled program depends on: names and the traced programs of every function."""
        static = self._identity
        dtype = jnp.zeros(()).dtype
        q = jax.ShapeDtypeStruct((self.m,), dtype)
        u = jax.ShapeDtypeStruct((self.dof,), dtype)
        p = {n: jax.ShapeDtypeStruct((), dtype) for n in self.params}
        fns = {"residual": self.residual}
        if self.branch is not None:
            fns["branch"] = self.branch_value
        for name in self.points:
            fns[f"point {name}"] = functools.partial(self.point, name)
        digest = hashlib.sha256(repr((tuple(static), str(dtype))).encode())
        try:
            for label, fn in fns.items():
                closed = jax.make_jaxpr(fn)(q, u, p)
                digest.update(label.encode() + str(closed.jaxpr).encode())
                for c in closed.consts:
                    c = np.asarray(c)
                    digest.update(repr((c.shape, str(c.dtype))).encode() + c.tobytes())
            if self.residual_scale is not None:
                closed = jax.make_jaxpr(lambda p_: self.residual_scale(self.vars_p(p_)))(p)
                digest.update(b"scale" + str(closed.jaxpr).encode())
                for c in closed.consts:
                    digest.update(np.asarray(c).tobytes())
        except Exception:  # a function that does not trace: identity (its error shows at solve time)
            return ("id", id(self))
        return ("jaxpr", digest.hexdigest())

    @property
    def program_key(self) -> str | None:
        """A fingerprint of what a compiled program depends on (names and the traced programs
        of every function), equal for identical mechanisms in any process; None when a
        function does not trace (then the mechanism is identified by the object alone)."""
        kind, value = self._key
        return value if kind == "jaxpr" else None

    @functools.cached_property
    def _identity(self) -> Identity:
        return Identity(self.name, self.coords, self.inputs, self.params, self.lengths, self.signed, tuple(self.points))

    def __eq__(self, other):
        if self is other:
            return True
        return isinstance(other, Mechanism) and self._identity == other._identity and self._key == other._key

    def __hash__(self):
        # The names only: equal mechanisms have equal names, and a mechanism's first compiled
        # call (hashed as a static argument) need not trace its functions to fingerprint
        # them (0.09 s for flap_msd's 14 points); they are traced only to compare two
        # distinct mechanisms of the same names.
        return hash(self._identity)

    # ------------------------------------------------------------------ structure
    @property
    def m(self) -> int:
        """Number of dependent coordinates (and of scalar equations)."""
        return len(self.coords)

    @property
    def dof(self) -> int:
        """Number of driven inputs (degrees of freedom)."""
        return len(self.inputs)

    def coord_is_length(self) -> np.ndarray:
        """Boolean mask over ``coords``: which dependent coordinates are lengths."""
        return np.array([n in self.lengths for n in self.coords], dtype=bool)

    # ------------------------------------------------------------------ evaluation
    def vars_q(self, q) -> Vars:
        return Vars(dict(zip(self.coords, parts(q, -1)))) if self.coords else Vars({})

    def vars_u(self, u) -> Vars:
        return Vars(dict(zip(self.inputs, parts(u, -1)))) if self.inputs else Vars({})

    def vars_p(self, p: Mapping) -> Vars:
        return p if isinstance(p, Vars) else Vars(p)

    def residual(self, q, u, p):
        """``Phi(q, u, p)``: the constraint residuals as a real vector of length ``m`` (m or -).

        Complex loops contribute (real, imaginary); real equations contribute one entry.
        """
        eqs = [] if self.constraints is None else self.constraints(self.vars_q(q), self.vars_u(u), self.vars_p(p))
        parts = equation_entries(eqs)
        if parts:
            r = jnp.stack(parts)
        else:  # no equations: an empty residual of the arguments' dtype
            r = jnp.zeros((0,), jnp.result_type(q, u, float))
        if r.shape[0] != self.m:
            raise ValueError(
                f"{self.name}: constraints give {r.shape[0]} real equations for "
                f"{self.m} coordinates {self.coords}; a complex loop counts twice"
            )
        return r

    def point(self, name: str, q, u, p):
        """Position of a named point as a complex number ``x + i y`` (m)."""
        try:
            fn = self.points[name]
        except KeyError:
            raise ValueError(
                f"{self.name}: unknown point {name!r}; defined points: {', '.join(self.points) or '(none)'}"
            ) from None
        return jnp.asarray(fn(self.vars_q(q), self.vars_u(u), self.vars_p(p)))

    def branch_value(self, q, u, p):
        """The branch indicator: ``()`` for one value, ``(n_branches,)`` for one per assembly
        choice (their signs name the assembly mode), or NaN if none is defined."""
        if self.branch is None:
            return jnp.asarray(jnp.nan, dtype=jnp.result_type(q))
        b = self.branch(self.vars_q(q), self.vars_u(u), self.vars_p(p))
        if isinstance(b, Mapping):
            b = list(b.values())
        if isinstance(b, (list, tuple)):
            return jnp.stack([jnp.reshape(jnp.asarray(x), ()) for x in b])
        return jnp.asarray(b)

    @functools.cached_property
    def branches(self) -> tuple[str, ...]:
        """Names of the branch indicator's entries (its loops): the mapping's keys, ``"loop 1"``,
        ``"loop 2"``, ... for a sequence, ``("branch",)`` for one value, ``()`` for none."""
        if self.branch is None:
            return ()
        dtype = jnp.zeros(()).dtype
        args = (jax.ShapeDtypeStruct((self.m,), dtype), jax.ShapeDtypeStruct((self.dof,), dtype), {n: jax.ShapeDtypeStruct((), dtype) for n in self.params})
        out = jax.eval_shape(lambda q, u, p: self.branch(self.vars_q(q), self.vars_u(u), self.vars_p(p)), *args)
        if isinstance(out, Mapping):
            return tuple(str(k) for k in out)
        if isinstance(out, (list, tuple)):
            return tuple(f"loop {i + 1}" for i in range(len(out)))
        if len(out.shape) == 1:
            return tuple(f"loop {i + 1}" for i in range(out.shape[0]))
        return ("branch",)

    @functools.cached_property
    def equations(self) -> tuple[tuple[str, tuple[int, ...]], ...]:
        """The constraint entries by name, with the rows of the residual each gives:
        ``((name, rows), ...)``.  Names are a mapping's keys (``constraints`` returning
        ``{"loop B": ..., "slot": ...}``), else ``"loop k"`` for the k-th entry when it is a
        complex loop (two rows) and ``"equation k"`` when it is real (one row)."""
        if self.constraints is None or self.m == 0:
            return ()
        dtype = jnp.zeros(()).dtype
        args = (jax.ShapeDtypeStruct((self.m,), dtype), jax.ShapeDtypeStruct((self.dof,), dtype),
                {n: jax.ShapeDtypeStruct((), dtype) for n in self.params})
        out = jax.eval_shape(lambda q, u, p: self.constraints(self.vars_q(q), self.vars_u(u), self.vars_p(p)), *args)
        named = isinstance(out, Mapping)
        items = list(out.items()) if named else list(enumerate(out if isinstance(out, (list, tuple)) else [out]))
        rows, k = [], 0
        for key, e in items:
            n = 2 if jnp.issubdtype(e.dtype, jnp.complexfloating) else 1
            name = str(key) if named else f"{'loop' if n == 2 else 'equation'} {key + 1}"
            rows.append((name, tuple(range(k, k + n))))
            k += n
        return tuple(rows)

    def length_scale(self, p: Mapping):
        """Characteristic length of a design (m): the largest magnitude among length parameters.

        Residual tolerances are relative to it, which makes statuses independent of units.
        """
        vals = [jnp.abs(jnp.asarray(p[n])) for n in self.lengths if n in self.params]
        if not vals:
            return jnp.asarray(1.0)
        scale = vals[0]
        for v in vals[1:]:
            scale = jnp.maximum(scale, v)
        return jnp.where(scale > 0, scale, 1.0)

    def residual_scales(self, p: Mapping, dtype):
        """Per-equation residual scale ``(m,)``: ``residual_scale(p)`` or the length scale."""
        if self.residual_scale is None:
            scale = self.length_scale(p)
        else:
            scale = jnp.abs(jnp.asarray(self.residual_scale(self.vars_p(p))))
            scale = jnp.where(scale > 0, scale, 1.0)
        return jnp.broadcast_to(jnp.asarray(scale, dtype), (self.m,))

    # ------------------------------------------------------------------ checking
    def check_params(self, p: Mapping) -> None:
        """Eager checks of a parameter mapping; raises ``ValueError`` naming the parameter.

        Checks names (no missing, no unknown) always, and values (finite; positive
        lengths) where they are concrete numbers rather than traced values.
        """
        check_parameters(self.name, p, self.params, self.lengths, self.signed, whose="this mechanism's")


def check_parameters(owner: str, p: Mapping, names: Sequence[str], lengths: Sequence[str] = (),
                     signed: Sequence[str] = (), *, whose: str = "the") -> None:
    """Eager checks of a parameter mapping ``p`` against the declared `names` of `owner`
    (a mechanism's or a model's name, for messages); raises ``ValueError`` naming the
    parameter.  Names: none unknown, none missing.  Concrete values (traced ones are
    skipped): numbers, finite, and positive for `lengths` not in `signed`."""
    if not isinstance(p, Mapping):
        raise ValueError(f"{owner}: parameters must be a mapping name -> value, got {type(p).__name__}")
    missing = [n for n in names if n not in p]
    unknown = [n for n in p if n not in names]
    if unknown:
        raise ValueError(f"{owner}: unknown parameter(s) {unknown}; {whose} parameters are {list(names)}")
    if missing:
        raise ValueError(f"{owner}: missing parameter(s) {missing}")
    for n in names:
        v = p[n]
        if isinstance(v, jax.core.Tracer):
            continue
        arr = np.asarray(v)
        if not np.issubdtype(arr.dtype, np.number):
            raise ValueError(f"{owner}: parameter {n!r} must be a number, got {arr.dtype}")
        if not np.all(np.isfinite(arr)):
            raise ValueError(f"{owner}: parameter {n!r} must be finite, got {show_value(v)}")
        if n in lengths and n not in signed and np.any(arr <= 0):
            raise ValueError(f"{owner}: length {n!r} must be positive, got {show_value(v)}; give a positive length in metres")
