"""One family of result codes (``jaxmech.Status``) for positions, statics, dynamics and
design, one message table, and the retired enums as deprecated views onto it."""

import enum
import importlib
import pkgutil
import warnings

import pytest

import jaxmech as jm
from jaxmech.solver import status as status_module


def test_one_enum_in_the_package():
    """No module of the package defines a result-code enum of its own."""
    found = []
    for info in pkgutil.walk_packages(jm.__path__, "jaxmech."):
        if info.name.startswith("jaxmech.cli") or info.name == "jaxmech.__main__":
            continue
        with warnings.catch_warnings():  # the old module paths kept one release (jaxmech.constrained, ...)
            warnings.simplefilter("ignore", DeprecationWarning)
            mod = importlib.import_module(info.name)
        for value in vars(mod).values():
            if isinstance(value, type) and issubclass(value, enum.Enum) and value.__module__ == mod.__name__:
                found.append(f"{mod.__name__}.{value.__name__}")
    assert found == ["jaxmech.solver.status.Status"]


def test_every_code_has_one_message():
    assert set(status_module._MESSAGES) == set(jm.Status)
    assert len({m for m in status_module._MESSAGES.values()}) == len(jm.Status)
    for code in jm.Status:
        assert jm.status_message(int(code)) == jm.status_message(code)
    assert jm.Status.CONVERGED == 0  # success is 0 for every kind of result (files, exit rows)


@pytest.mark.parametrize(
    "get, old, new",
    [
        (lambda: jm.DynStatus, {"OK": "CONVERGED", "POSITION": "POSITION", "STROKE_END": "STROKE_END",
                                 "NOT_CONVERGED": "NOT_CONVERGED", "NONFINITE": "NONFINITE",
                                 "NO_EQUILIBRIUM": "NO_EQUILIBRIUM", "FRICTION": "FRICTION"}, "jaxmech.Status"),
        (lambda: jm.dynamics.DynStatus, {"OK": "CONVERGED", "FRICTION": "FRICTION"}, "jaxmech.Status"),
        (lambda: jm.design.StopReason, {"CONVERGED": "CONVERGED", "MAX_STEPS": "MAX_STEPS", "INFEASIBLE": "INFEASIBLE",
                                        "DIVERGED": "DIVERGED"}, "jaxmech.Status"),
        (lambda: __import__("jaxmech.design.nlp", fromlist=["Status"]).Status,
         {"MAX_ITERATIONS": "MAX_STEPS", "SMALL_STEP": "SMALL_STEP", "START_NOT_EVALUATED": "INFEASIBLE"}, "jaxmech.Status"),
    ],
)
def test_retired_enums_are_views_with_a_warning(get, old, new):
    with pytest.warns(DeprecationWarning, match=new):
        view = get()
    for name, now in old.items():
        assert getattr(view, name) is jm.Status[now]
        assert view(int(jm.Status[now])) is jm.Status[now]
    with pytest.raises(AttributeError, match="no member"):
        view.NO_SUCH_CODE


def test_retired_message_function_warns():
    with pytest.warns(DeprecationWarning, match="status_message"):
        msg = jm.dyn_status_message
    assert msg(jm.Status.NO_EQUILIBRIUM) == jm.status_message(9) and "no equilibrium" in msg(9)
