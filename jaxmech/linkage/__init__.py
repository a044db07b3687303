"""Linkages from their drawings: joints at coordinates, links through them, sliders, slots
and actuators; the loop equations written for you (``Linkage.equations()``), every joint's
reaction from the per-body Newton-Euler equations, and a plain file format
(``load_linkage``, ``jaxmech run my_linkage.toml``).  A drawing from link lengths, plate
angles, ground pivots and an input value: ``drawing_from_lengths``."""

from .files import load_linkage as load_linkage
from .files import read_linkage_file as read_linkage_file
from .lengths import drawing_from_lengths as drawing_from_lengths
from .spec import Linkage as Linkage

__all__ = ["Linkage", "load_linkage", "read_linkage_file", "drawing_from_lengths"]
