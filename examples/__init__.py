"""Worked studies built on jaxmech (not part of the library): the design problems of the
seed scenes, four-bar path synthesis and a tolerance study.  Each is tested in the default
test run (``tests/test_examples_*.py``, ``tests/test_problems.py``) and shown in
``notebooks/design_studies.ipynb``.  Run from the repository root (``import examples``)."""
