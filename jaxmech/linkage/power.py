"""Where a ``Linkage``'s drive power goes (``linkage_power``, which is ``Linkage.power``): its
inverse dynamics along a drive, then ``dynamics.power.power_balance`` told which of its
elements store energy (springs), which dissipate it (dampers) and which joints have
friction (``Linkage(friction=...)``)."""

from __future__ import annotations

from collections.abc import Mapping

from ..dynamics.power import PowerBalance, power_balance
from ..solver.options import SolverOptions
from .elements import DISSIPATING, STORING, load_name

__all__ = ["linkage_power"]


def linkage_power(lk, drive, t=None, p: Mapping | None = None, *, options: SolverOptions = SolverOptions()) -> PowerBalance:
    """Where the power goes along a drive law at times `t` (or ``Samples``): per sample
    (W) the drive's input power, the rates of kinetic and potential energy (gravity and
    springs), the power dissipated by the dampers and the joints' friction (``joints``:
    each friction joint's, by its name in ``Linkage.joints``), the power delivered to the
    other loads and the balance's residual; ``.work()`` each over the samples' times and
    ``.efficiency`` the stroke's (a ``Samples`` drive needs its times ``t`` for them; see
    ``dynamics.power``)."""
    res = lk.inverse_dynamics(drive, t, p, options=options)
    names = lambda kinds: tuple(load_name(e) for e in lk.elements.specs if e.kind in kinds)  # noqa: E731
    out = power_balance(lk.model, res, lk._p(p), stored=names(STORING), dissipated=names(DISSIPATING), friction=lk.friction)
    return out._replace(elements={e.name: out.elements[load_name(e)] for e in lk.elements.specs})
