"""A ``Linkage`` as a scene: what ``jaxmech run my_linkage.toml`` runs.

The table holds every coordinate (with its rates), the drive's torque or force and every
joint's reaction (``F_<joint>_x``, ``F_<joint>_y``; a slider's moment ``M_<joint>``), from
the per-body Newton-Euler equations at every sample of the stroke.  With joint friction
(``Linkage(friction=...)``, a file's ``[friction]``) the effort and the reactions include
it, by the law and solve of ``Linkage.inverse_dynamics`` (each joint's sign over the
stroke's own speed scale); a sample that friction jams (its Newton does not converge: no
effort drives the linkage that way) has status ``MAX_STEPS``, its row NaN in the table.
The friction parameters (``mu_<key>``, ``rpin_<key>``, ``cv_<key>``) are the scene's, so
``--set mu_B=0.2`` and sweeps over them work.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import re
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from ..dynamics.friction import friction_reactions, friction_status, joint_speeds, stroke_signs
from ..dynamics.joints import Prismatic, joint_name
from ..dynamics.reactions import joint_reactions
from ..dynamics.virtual_power import driving_effort, loaded_state
from ..linkage.files import read_linkage_file
from ..linkage.spec import Linkage
from ..linkage.stroke_file import FileStroke, read_stroke, stroke_samples
from ..solver.status import Status, status_counts
from .base import Scene, SceneResult, run_scene
from .outputs import STATUS, Outputs, merged_status

__all__ = ["parameter_unit", "linkage_scene", "scene_from_file", "run_file_scene", "point_columns"]

#: SI unit of a linkage parameter by its prefix.
PARAMETER_UNITS = {"len_": "m", "x_": "m", "y_": "m", "R_": "m", "ang_": "rad", "m_": "kg", "J_": "kg m^2",
                   "Fx_": "N", "Fy_": "N", "M_": "N m", "g": "m/s^2",
                   # springs and dampers (linkage.elements)
                   "k_": "N/m", "L0_": "m", "F0_": "N", "kt_": "N m/rad", "phi0_": "rad", "Lg_": "m", "n_": "-",
                   "c_": "N s/m", "ct_": "N m s/rad",
                   # joint friction (linkage.friction): a pin's cv_ in N m s/rad, a guide's in N s/m (_unit)
                   "mu_": "-", "rpin_": "m"}


def parameter_unit(name: str, lk: Linkage | None = None) -> str:
    """The SI unit of the linkage parameter `name` (by its prefix, ``PARAMETER_UNITS``; a
    viscous friction ``cv_`` by its joint's kind where `lk` is given); "" if none fits."""
    if name == "g":
        return "m/s^2"
    if name.startswith("cv_") and lk is not None and lk.friction is not None:  # viscous friction: by its joint's kind
        pins = {fj.damping for fj in lk.friction.joints if fj.radius is not None}
        return "N m s/rad" if name in pins else "N s/m"
    for prefix, unit in PARAMETER_UNITS.items():
        if name.startswith(prefix):
            return unit
    return ""


def _column(name: str) -> str:
    return re.sub(r"\W+", "_", name).strip("_")


def _coordinate_unit(lk: Linkage, name: str) -> str:
    return "m" if name in lk.mechanism.lengths else "rad"


def _output_units(lk: Linkage) -> dict[str, str]:
    """The drive effort of each input and every joint's reaction (components, and a
    prismatic joint's moment): their units, in column order."""
    mech = lk.model.mechanism
    out = {f"effort_{_column(name)}": "N" if name in mech.lengths else "N m" for name in mech.inputs}
    for j in lk.model.joints:
        col = _column(joint_name(j))
        out.update({f"F_{col}_x": "N", f"F_{col}_y": "N"})
        if isinstance(j, Prismatic):
            out[f"M_{col}"] = "N m"
    return out


def _outputs(lk: Linkage) -> Outputs:
    model = lk.model
    mech = model.mechanism

    def efforts(p, mo):
        # by virtual power along the motion's tangent: no multipliers, no linear solve
        def one(q, u, ud, udd, qd, qdd, t, d1):
            return driving_effort(model, loaded_state(model, q, u, ud, udd, p, t, q_dot=qd, q_ddot=qdd), d1)

        return jax.vmap(one)(mo.q, mo.u, mo.u_dot, mo.u_ddot, mo.q_dot, mo.q_ddot, mo.t, mo.dq_du)

    def outputs(p, mo):
        def one(q, u, ud, udd, qd, qdd, t):
            return joint_reactions(model, loaded_state(model, q, u, ud, udd, p, t, q_dot=qd, q_ddot=qdd))

        return _columns(model, *jax.vmap(one)(mo.q, mo.u, mo.u_dot, mo.u_ddot, mo.q_dot, mo.q_ddot, mo.t))

    if lk.friction is not None:
        return Outputs(functools.partial(_friction_outputs, lk), _output_units(lk), status=True)
    parts = {f"effort_{_column(name)}": (lambda p, mo, k=k: efforts(p, mo)[:, k]) for k, name in enumerate(mech.inputs)}
    return Outputs(outputs, _output_units(lk), parts)


def _friction_outputs(lk: Linkage, p, mo) -> dict:
    """``_outputs``' columns of a linkage with joint friction, and each sample's status: the
    law and solve of ``dynamics.inverse_dynamics`` along a stroke (``friction.joint_speeds``
    at every sample, their signs over the stroke's own speed scale, ``stroke_signs``, then
    ``friction_reactions`` per sample); ``MAX_STEPS`` where friction's Newton does not
    converge (jammed), its values there finite placeholders (0) for the status to mask."""
    model, fr = lk.model, lk.friction
    ok = mo.status == Status.CONVERGED
    w = jax.vmap(lambda q, u, qd, ud: joint_speeds(model, fr, q, u, p, qd, ud))(mo.q, mo.u, mo.q_dot, mo.u_dot)

    def one(q, u, ud, udd, qd, qdd, t, d1, signs, speeds):
        st = loaded_state(model, q, u, ud, udd, p, t, q_dot=qd, q_ddot=qdd)
        fres = friction_reactions(model, fr, st, signs, speeds)
        return driving_effort(model, st, d1) + fres.efforts, fres.forces, fres.moments, fres.converged

    eff, forces, moments, conv = jax.vmap(one)(mo.q, mo.u, mo.u_dot, mo.u_ddot, mo.q_dot, mo.q_ddot, mo.t, mo.dq_du,
                                               stroke_signs(fr, w, ok), w)
    out = {k: jnp.where(conv, v, 0.0) for k, v in _columns(model, eff, forces, moments).items()}
    out[STATUS] = friction_status(mo.status, conv)
    return out


def _columns(model, eff, forces, moments) -> dict:
    """The output columns ``(N,)`` from the samples' efforts ``(N, dof)`` and the joints'
    ``{joint: F}`` forces and ``{joint: M}`` moments (``joint_reactions``' form)."""
    out = {f"effort_{_column(name)}": eff[:, k] for k, name in enumerate(model.mechanism.inputs)}
    for j in model.joints:
        name = joint_name(j)
        col = _column(name)
        out[f"F_{col}_x"] = jnp.real(forces[name])
        out[f"F_{col}_y"] = jnp.imag(forces[name])
        if isinstance(j, Prismatic):
            out[f"M_{col}"] = moments[name]
    return out


def _drawing(lk: Linkage):
    links, polygons = [], []
    for link, pts in lk.links.items():
        if len(pts) == 2:
            links.append(tuple(pts))
        elif len(pts) > 2:
            polygons.append(tuple(pts))
    acts = [tuple(pts) for _, pts in lk.topology.actuators]
    tracers = [x for x in lk.topology.points if sum(x in pts for pts in lk.links.values()) == 1 and x not in lk.ground
               and not any(x in pts for pts in acts)]
    slots = [{"centre": c, "radius": 0.0, "pin": pin} for pin, _, c in lk.topology.slots if c]

    def drawing(p):
        spec = {"links": links + acts, "polygons": polygons, "ground": list(lk.ground), "trace": tracers}
        if slots:
            spec["slots"] = [dict(s, radius=float(p[f"R_{s['pin']}"])) for s in slots]
        return spec

    return drawing


def _friction_validation(lk: Linkage):
    """The scene's ``validate``: friction's values must not be negative (None without friction)."""
    if lk.friction is None:
        return None
    names = lk.friction.parameters

    def validate(p):
        bad = [k for k in names if float(p[k]) < 0.0]
        if bad:
            raise ValueError(f"{lk.name}: joint friction's {bad[0]} = {float(p[bad[0]]):.6g} must not be negative")

    return validate


def _meaning(name: str, lk: Linkage) -> str:
    """What a linkage parameter is, in the scene's parameter list."""
    if lk.friction is not None and name in lk.friction.parameters:
        return "joint friction"
    return "drawing" if parameter_unit(name) in ("m", "rad") else "mass property or load"


def linkage_scene(lk: Linkage, stroke=None, speed: float = 1.0, summary: str | None = None) -> Scene:
    """The ``Scene`` of a linkage with one driver: its drawing's parameters as defaults, the
    stroke ``(start, end)`` of the input (default: a crank's whole turn from the drawing, an
    actuator's or slider's drawing value to 1.5 times it), at constant `speed`."""
    mech = lk.mechanism
    if mech.dof != 1:
        raise ValueError(f"{lk.name}: a scene has one driven input; this linkage has {mech.dof} ({list(mech.inputs)})")
    u_draw = float(lk.input_at_drawing[0])
    name = mech.inputs[0]
    is_angle = name not in mech.lengths
    if stroke is None:
        stroke = (u_draw, u_draw + 2 * np.pi) if is_angle else (u_draw, 1.5 * u_draw if u_draw else 1.0)
    u0, u1 = (float(x) for x in stroke)
    guess = lk.guess
    if abs(u0 - u_draw) > 1e-12 * (1.0 + abs(u_draw)):
        sol = lk.solve(np.array([u0]))  # the drawing's pose carried to the stroke's start
        if np.all(np.isfinite(np.asarray(sol.q[0]))):
            guess = np.asarray(sol.q[0])
    units = {n: _coordinate_unit(lk, n) for n in mech.coords + mech.inputs}
    params = {k: (parameter_unit(k, lk), _meaning(k, lk)) for k in lk.params}
    return Scene(
        name=lk.name, validate=_friction_validation(lk),
        summary=summary or f"linkage {lk.name}: {len(lk.links)} links, driven by {name} from {u0:.6g} to {u1:.6g}",
        mechanism=mech, defaults=lk.params, guess=lambda p, g=jnp.asarray(guess): g,
        stroke=lambda p: (u0, u1), speed=float(speed), units=units, outputs=_outputs(lk), drawing=_drawing(lk),
        parameters=params)


@dataclasses.dataclass(frozen=True, eq=False)
class FileScene(Scene):
    """The ``Scene`` of a linkage file, keyed by what it was built from: `content` is a
    SHA-256 of the file's bytes, its name, the stroke, the speed and the stroke start's
    coordinates, so that the stored programs of one file serve every later process that
    reads the same file (a registry scene is keyed by its name instead).  `linkage` is the
    file's ``Linkage`` and `drive` its ``[stroke]`` table read (``linkage.stroke_file``):
    ``run_file_scene`` follows a rocking or sampled stroke, the scene's own stroke (what
    sweeps, animations and exports run) is the sweep from its first value to its farthest."""

    content: str = ""
    linkage: Linkage | None = None
    drive: FileStroke | None = None

    @property
    def program_key(self) -> str | None:
        """``"linkage file <content>"`` (see the class); None without a content key."""
        return f"linkage file {self.content}" if self.content else None


def _content_key(data: bytes, scene: Scene) -> str:
    """What determines a file scene's programs besides the package's source (which the
    store's key holds): the file's bytes, the scene's name, its stroke, speed and guess (the
    guess is a constant inside the stroke's program)."""
    p = {k: float(v) for k, v in scene.defaults.items()}
    u0, u1 = (float(x) for x in scene.stroke(p))
    guess = np.asarray(scene.guess(p), np.float64)
    digest = hashlib.sha256(data)
    digest.update(repr((scene.name, u0, u1, float(scene.speed))).encode() + guess.tobytes())
    return digest.hexdigest()


def scene_from_file(path) -> FileScene:
    """The scene of a linkage file (TOML or JSON; its ``[stroke]`` table sets the stroke),
    keyed by the file's content for the store of compiled programs (``FileScene``)."""
    path = Path(path)
    data = path.read_bytes()
    lk, table = read_linkage_file(path)
    name = lk.mechanism.inputs[0] if lk.mechanism.dof == 1 else ""
    try:
        drive = read_stroke(table, "m" if name in lk.mechanism.lengths else "rad", path.parent)
    except ValueError as err:
        raise ValueError(f"{path.name}: {err}") from None
    scene = linkage_scene(lk, drive.range, drive.speed, drive.summary)
    fields = {f.name: getattr(scene, f.name) for f in dataclasses.fields(Scene)}
    return FileScene(**fields, content=_content_key(data, scene), linkage=lk, drive=drive)


def run_file_scene(scene: Scene, points: int = 101, **overrides) -> SceneResult:
    """``run_scene``, except for a linkage file's rocking or sampled stroke: its linkage
    along the stroke's samples (``Linkage.motion``; `points` samples over a rock's cycles, a
    sampled stroke's own), with the scene's outputs (efforts, joint reactions) evaluated on
    that motion.  ``ValueError`` for bad parameters or a stroke that cannot be assembled."""
    samples = stroke_samples(scene.drive, points) if isinstance(scene, FileScene) and scene.drive else None
    if samples is None:
        return run_scene(scene, points, **overrides)
    p = scene.params(**overrides)
    mo = jax.tree_util.tree_map(np.asarray, scene.linkage.motion(samples, p=p))
    status = mo.status
    if np.any(status != Status.CONVERGED):
        bad = np.flatnonzero(status != Status.CONVERGED)
        uname = scene.mechanism.inputs[0]
        raise ValueError(f"{scene.name}: its [stroke] cannot be assembled: {len(bad)} of {status.size} samples fail, "
                         f"first at {uname} = {float(mo.u[bad[0], 0]):.6g} ({status_counts(status)}); "
                         "change the stroke or the link lengths")
    if scene.outputs.status:  # joint friction: its status too, MAX_STEPS where it jams the linkage
        values, own = jax.jit(lambda p_, mo_: _values_and_status(scene.outputs, p_, mo_))(p, mo)
        mo = dataclasses.replace(mo, status=np.asarray(merged_status(mo.status, own)))
    else:
        values = jax.jit(scene.outputs.fn)(p, mo)
    outputs = {k: (np.asarray(values[k]), unit) for k, unit in scene.outputs.units.items()}
    return SceneResult(scene=scene, params=p, motion=mo, outputs=outputs)


def _values_and_status(outputs: Outputs, p, mo):
    """``({name: values}, status)`` of ``Outputs.evaluate`` (no unit strings: a compiled program's result)."""
    outs, own = outputs.evaluate(p, mo)
    return {k: v for k, (v, _) in outs.items()}, own


def point_columns(motion) -> dict:
    """Every named point's position, velocity and acceleration as table columns:
    ``x_P[m]``, ``y_P[m]``, ``vx_P[m/s]``, ``vy_P[m/s]``, ``ax_P[m/s^2]``, ``ay_P[m/s^2]``
    for each point ``P`` of ``motion.points`` (joints, tracers, centres of mass)."""
    out = {}
    for name, triple in motion.points.items():
        col = _column(name)
        for prefix, z, unit in zip(("", "v", "a"), triple, ("m", "m/s", "m/s^2")):
            z = np.asarray(z)
            out[f"{prefix}x_{col}[{unit}]"] = z.real
            out[f"{prefix}y_{col}[{unit}]"] = z.imag
    return out
