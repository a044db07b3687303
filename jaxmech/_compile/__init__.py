"""The library's compiled programs (private): ``xla`` (its ``jit`` and the backend
workarounds), ``stored`` (executables stored on disk and loaded by a later process) and
``cache`` (the folders, and JAX's persistent compilation cache)."""
