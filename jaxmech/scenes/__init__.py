"""Scene registry: ``get_scene(name)``, ``scene_names()``.

Each scene lives in its own module, imported on first use, and declares its outputs' units
and column order (``Outputs``).
"""

from __future__ import annotations

import importlib

from .base import Scene as Scene
from .outputs import Outputs as Outputs
from .base import SceneResult as SceneResult
from .base import run_scene as run_scene

# name -> (module, attribute)
_REGISTRY = {
    "fourbar": ("classic", "FOURBAR"),
    "slider_crank": ("classic", "SLIDER_CRANK"),
    "flap_msd": ("flap_msd", "SCENE"),
    "landing_gear": ("landing_gear", "SCENE"),
    "arc_track_flap": ("arc_track_flap", "SCENE"),
    "arc_track_flap_landing": ("arc_track_flap", "LANDING_SCENE"),
    "sma_flap": ("sma_flap", "SCENE"),
}


def _available() -> list[str]:
    out = []
    for name, (mod, _) in _REGISTRY.items():
        if importlib.util.find_spec(f"{__name__}.{mod}") is not None:
            out.append(name)
    return out


def scene_names() -> list[str]:
    """Names of the scenes in this installation."""
    return _available()


def get_scene(name: str) -> Scene:
    """The scene called ``name``; ``ValueError`` listing the known scenes otherwise."""
    if name not in _available():
        raise ValueError(f"unknown scene {name!r}; known scenes: {', '.join(_available())}")
    mod, attr = _REGISTRY[name]
    return getattr(importlib.import_module(f"{__name__}.{mod}"), attr)
