"""Implicit-derivative gradients of every registered scene against central differences.

For each scene of ``jaxmech.scenes.scene_names()`` one scalar figure of merit is built with
``design.scene_figure`` (the scene run over its stroke exactly as ``run_scene`` does, at
``POINTS`` samples, outputs included) and differentiated with ``jax.value_and_grad``
with respect to **every** parameter of the scene, geometric and physical.  The position
derivatives come from the implicit function theorem in ``jaxmech.solve`` (``implicit_positions``),
never from the Newton iterations.  Every scene's figure is traceable through
``scene_figure`` (the scenes' eager ``validate`` is not called there), so no scene needs a
hand-made path.

``design.sensitivities`` is the same ``value_and_grad`` under ``jax.vmap``; its batching and
masking are tested in test_design.py.  It is not used here because its vmapped kernel
compiles markedly slower for the big scenes (flap_msd: ~70 s against ~35 s on a loaded
2-core machine), and compiling is nearly all of this file's time: each scene compiles one
``jax.jit(jax.value_and_grad(figure, has_aux=True))``, and the base gradient and every
difference evaluation are calls of it.

The reference is ``helpers.central_diff``, a sixth-order central difference of the *same*
figure (the same sampled stroke), with the step ``h_k = REL_STEP * s_k`` scaled to the
parameter: ``s_k = |p_k|``, or for a parameter whose default is zero, the mechanism's length
scale if it is a length and 1 (its SI unit) otherwise.  ``REL_STEP = 3e-4`` balances
truncation (~``(3 h/d)^6``, ``d`` the distance to the nearest singularity: the landing gear
ends 2.4 % short of its toggle, where ``1e-3`` already costs 7e-8) against the difference's
roundoff and the solver's tolerance (~1e-12 relative in the figure, divided by ``REL_STEP``).

Agreement: for every parameter ``k``

    |g_ad,k - g_fd,k| s_k  <=  RTOL * max(|g_fd,k| s_k, FLOOR * max_j |g_fd,j| s_j)

i.e. the relative error of the normalised sensitivity ``s_k df/dp_k`` (the change of the
figure per unit relative change of the parameter), with a floor of ``FLOOR = 1e-4`` times
the scene's largest normalised sensitivity.  Without the floor a parameter that the figure
ignores would compare difference noise with zero.  There are several (the test prints them):
the motor constants ``R_a``, ``K_m`` (and, nearly, ``J_m``) for the flap torque; for the
arc-track peak nut force, which is at the closed flap, everything but ``a2``, ``beta3``,
``x_D`` and the closed-flap load (the flap turns about A0 whatever the slots ``b1``, ``c1``,
``beta1``, ``beta2``, the mounting ``a1``, ``alpha0`` and the screw ``a3``, ``r``, ``l``,
``f``; ``M12_f`` acts on the deployed flap); ``x1`` (the arm is stationary at the design's
right angle), ``AB``, ``beta`` for the gear's force ratio; ``TE_*``, ``E_A`` (at
``xi = 1``), ``F1``, ``force_driven`` and, nearly, ``s1F_x`` for the SMA flap.  Those are
held to ``RTOL * FLOOR = 1e-10`` of the largest normalised sensitivity.

The figures:

- ``fourbar``: transmission angle at the end of the crank turn (rad).
- ``slider_crank``: peak coupler angle ``theta3`` over the turn (rad).
- ``flap_msd``: peak driving torque ``|T_m|`` over the stroke (N m): inverse dynamics with
  inertia (second implicit derivatives), gravity and aerodynamics.
- ``landing_gear``: peak cylinder force ratio over the retraction (-): the implicit
  ``dtheta/dx`` at every sample, and the stroke ends ``x1``, ``x2`` are parameters.
- ``arc_track_flap`` (cruise) and ``arc_track_flap_landing``: peak nut force ``F_input`` (N),
  from the quasi-static multipliers of the four-coordinate slot mechanism.
- ``sma_flap``: equilibrium hinge angle at the end of the SMA strain sweep (rad): the
  "mechanism" is the equilibrium itself, so this differentiates an equilibrium solve.

Peaks use ``design.peak(..., "argmax")``, which is differentiable because the maximising
sample is chosen on ``stop_gradient`` values and is piecewise constant in ``p``: near the
design the figure *is* one smooth sample, and its gradient is that sample's gradient,
exactly.  The difference stencil (at most ``3 h_k``) must not move the argmax; if it did,
the difference would straddle a kink and this test would fail rather than pass silently.
"""

import jax

jax.config.update("jax_enable_x64", True)

import time  # noqa: E402

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

from jaxmech.design import peak, scene_figure  # noqa: E402
from jaxmech.scenes import get_scene, scene_names  # noqa: E402

from helpers import central_diff  # noqa: E402

POINTS = 21  # samples along each stroke (both ends included)
RTOL = 1e-6  # the required agreement with central differences
REL_STEP = 3e-4  # difference step relative to the parameter's scale
FLOOR = 1e-4  # relative errors are taken against at least FLOOR x the largest sensitivity


def _final_transmission(cols, p):
    return cols["transmission_angle[rad]"][-1]


def _peak_coupler(cols, p):
    return peak(cols["theta3[rad]"], "argmax")


def _peak_torque(cols, p):
    return peak(jnp.abs(cols["torque[N m]"]), "argmax")


def _peak_force_ratio(cols, p):
    return peak(cols["force_ratio[-]"], "argmax")


def _peak_nut_force(cols, p):
    return peak(cols["F_input[N]"], "argmax")


def _final_hinge_angle(cols, p):
    return cols["theta1[rad]"][-1]


FIGURES = {
    "fourbar": _final_transmission,
    "slider_crank": _peak_coupler,
    "flap_msd": _peak_torque,
    "landing_gear": _peak_force_ratio,
    "arc_track_flap": _peak_nut_force,
    "arc_track_flap_landing": _peak_nut_force,  # the same mechanism under the landing air moment
    "sma_flap": _final_hinge_angle,
}


def test_every_registered_scene_has_a_figure():
    assert set(FIGURES) == set(scene_names()), "add a figure of merit for the new scene to FIGURES"


def _scales(scene, p0):
    lscale = float(scene.mechanism.length_scale(scene.defaults))
    lengths = set(scene.mechanism.lengths)
    return np.array([
        abs(v) if v != 0 else (lscale if k in lengths else 1.0) for k, v in zip(scene.defaults, p0)
    ])


@pytest.mark.parametrize("name", scene_names())
def test_gradient_of_every_parameter_matches_central_differences(name):
    t0 = time.perf_counter()
    scene = get_scene(name)
    fig = scene_figure(scene, FIGURES[name], points=POINTS, name=FIGURES[name].__name__)
    names = list(scene.defaults)
    p0 = np.array([float(scene.defaults[k]) for k in names])
    n = len(names)

    value_and_grad = jax.jit(jax.value_and_grad(fig, has_aux=True))  # fig(p) -> (value, ok)

    def evaluate(x):
        (v, ok), g = value_and_grad({k: jnp.asarray(xk) for k, xk in zip(names, x)})
        assert bool(ok), f"{name}: the design {dict(zip(names, x))} failed to solve"
        return float(v), g

    value, g = evaluate(p0)
    grad = np.array([float(g[k]) for k in names])
    assert np.isfinite(value) and np.all(np.isfinite(grad))

    def perturbed(x):
        """Figure values, design i being the defaults with parameter i set to x[i]."""
        return np.array([evaluate(np.where(np.arange(n) == i, x, p0))[0] for i in range(n)])

    scale = _scales(scene, p0)
    fd = central_diff(perturbed, p0, REL_STEP * scale)

    sens_ad, sens_fd = grad * scale, fd * scale
    denom = np.maximum(np.abs(sens_fd), FLOOR * np.max(np.abs(sens_fd)))
    rel = np.abs(sens_ad - sens_fd) / denom
    worst = int(np.argmax(rel))
    print(
        f"\n{name}: {fig.name} = {value:.10g}; {n} parameters; max relative difference "
        f"{rel[worst]:.2e} (at {names[worst]}); {time.perf_counter() - t0:.1f} s"
        f"\n  compared at the floor (|s df/dp| < {FLOOR:g} x max): "
        f"{[k for k, e in zip(names, sens_fd) if abs(e) < FLOOR * np.max(np.abs(sens_fd))]}"
    )
    bad = {k: (g, f, r) for k, g, f, r in zip(names, grad, fd, rel) if not r <= RTOL}
    assert not bad, f"{name}: implicit gradient vs central difference (grad, fd, rel): {bad}"
    # The figure really depends on the geometry: a gradient test of a constant proves nothing.
    assert np.max(np.abs(sens_fd)) > 0
