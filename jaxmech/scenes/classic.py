"""The classic four-bar and offset slider-crank, as scenes (and as the engine's test bed)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ..mechanism.mechanism import Mechanism, cis
from .base import Scene
from .outputs import Outputs

__all__ = ["FOURBAR", "SLIDER_CRANK", "fourbar_mechanism", "slider_crank_mechanism"]

#: Four-bar: crank a at O2 (angle theta2), coupler b (theta3), rocker c at O4 (theta4),
#: ground d along +x.  Loop: a e^{i theta2} + b e^{i theta3} - c e^{i theta4} - d = 0.
#: Branch indicator sin(theta4 - theta3): positive is the "open" assembly.  Written as
#: Im(conj(e^{i theta3}) e^{i theta4}) it reuses the loop's own cos/sin (no extra sine).
fourbar_mechanism = Mechanism(
    name="fourbar",
    coords=("theta3", "theta4"),
    inputs=("theta2",),
    params=("a", "b", "c", "d"),
    lengths=("a", "b", "c", "d"),
    constraints=lambda q, u, p: [p.a * cis(u.theta2) + p.b * cis(q.theta3) - p.c * cis(q.theta4) - p.d],
    points={
        "O2": lambda q, u, p: 0.0 * p.a + 0j,
        "O4": lambda q, u, p: p.d + 0j,
        "A": lambda q, u, p: p.a * cis(u.theta2),
        "B": lambda q, u, p: p.d + p.c * cis(q.theta4),
        "P": lambda q, u, p: p.a * cis(u.theta2) + 0.5 * p.b * cis(q.theta3),
    },
    branch=lambda q, u, p: jnp.imag(jnp.conj(cis(q.theta3)) * cis(q.theta4)),
)

#: Offset slider-crank: crank a (theta2), rod b (theta3), slider at x + i e on a line
#: parallel to x.  Loop: a e^{i theta2} + b e^{i theta3} - x - i e = 0.
slider_crank_mechanism = Mechanism(
    name="slider_crank",
    coords=("theta3", "x"),
    inputs=("theta2",),
    params=("a", "b", "e"),
    lengths=("a", "b", "e", "x"),
    signed=("e",),
    constraints=lambda q, u, p: [p.a * cis(u.theta2) + p.b * cis(q.theta3) - q.x - 1j * p.e],
    points={
        "O2": lambda q, u, p: 0.0 * p.a + 0j,
        "A": lambda q, u, p: p.a * cis(u.theta2),
        "B": lambda q, u, p: q.x + 1j * p.e,
    },
    branch=lambda q, u, p: jnp.real(cis(q.theta3)),
)


def _fourbar_drawing(p):
    # Crank O2-A, coupler A-B (its midpoint P traced), rocker O4-B; transmission angle at B
    # between coupler and rocker; the rocker angle is the output.
    return {
        "links": [("O2", "A"), ("A", "B"), ("O4", "B")],
        "ground": ["O2", "O4"],
        "trace": ["P"],
        "transmission": ("A", "B", "O4"),
        "output": "theta4",
    }


def _slider_crank_drawing(p):
    # The slider B runs on the line y = e between its dead-centre positions (both dyads
    # stretched or folded), drawn with a margin of one crank length either side.
    a, b, e = float(p["a"]), float(p["b"]), float(p["e"])
    x_in = float(np.sqrt(max((b - a) ** 2 - e * e, 0.0)))
    x_out = float(np.sqrt((a + b) ** 2 - e * e))
    return {
        "links": [("O2", "A"), ("A", "B")],
        "ground": ["O2"],
        "slots": [{"line": (complex(x_in - a, e), complex(x_out + a, e))}],
        "points": ["B"],
        "trace": ["A"],
        "output": "x",
    }


def _transmission(p, mo):
    th3, th4 = mo.q[:, 0], mo.q[:, 1]
    mu = jnp.arccos(jnp.abs(jnp.cos(th4 - th3)))
    return {"transmission_angle": mu}


#: Parameters of the four-bar scene: (SI unit, meaning).
FOURBAR_PARAMETERS = {
    "a": ("m", "crank O2-A (input link)"),
    "b": ("m", "coupler A-B"),
    "c": ("m", "rocker O4-B (output link)"),
    "d": ("m", "ground O2-O4"),
}

#: Parameters of the slider-crank scene: (SI unit, meaning).
SLIDER_CRANK_PARAMETERS = {
    "a": ("m", "crank O2-A"),
    "b": ("m", "connecting rod A-B"),
    "e": ("m", "offset of the slider line above O2"),
}

FOURBAR = Scene(
    name="fourbar",
    summary="classic crank-rocker four-bar (a=1, b=3, c=2.5, d=3.5 m), one crank turn at 1 rad/s",
    mechanism=fourbar_mechanism,
    defaults={"a": 1.0, "b": 3.0, "c": 2.5, "d": 3.5},
    guess=lambda p: jnp.array([0.2, 1.2]),
    stroke=lambda p: (0.0, 2 * jnp.pi),
    speed=1.0,
    units={"theta2": "rad", "theta3": "rad", "theta4": "rad"},
    outputs=Outputs(_transmission, {"transmission_angle": "rad"}),
    drawing=_fourbar_drawing,
    parameters=FOURBAR_PARAMETERS,
)

SLIDER_CRANK = Scene(
    name="slider_crank",
    summary="offset slider-crank (a=0.1, b=0.35, e=0.03 m), one crank turn at 1 rad/s",
    mechanism=slider_crank_mechanism,
    defaults={"a": 0.1, "b": 0.35, "e": 0.03},
    guess=lambda p: jnp.array([0.1, 0.44]),
    stroke=lambda p: (0.0, 2 * jnp.pi),
    speed=1.0,
    units={"theta2": "rad", "theta3": "rad", "x": "m"},
    drawing=_slider_crank_drawing,
    parameters=SLIDER_CRANK_PARAMETERS,
)
