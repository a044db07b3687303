"""The position solver: options and statuses, the batched Newton solve of the loop-closure
equations, its implicit derivatives, and the small dense linear algebra under them.

``positions.solve`` / ``solve_one`` (one batch of independent samples) return a
``solution.Solution``; ``options.SolverOptions`` holds the static settings; ``implicit``
attaches every derivative by the implicit function theorem.  The library's face
(``jaxmech.solve``, ...) hands these names on; this package's modules are imported by
their full names.
"""
