"""Pictures of a mechanism: ``drawing`` (a scene's drawing spec, poses and animations),
``plot`` (a stroke's coordinates, outputs and transmission) and ``live`` (a notebook
view with sliders).  Imported by their full names (``jaxmech.viz.plot``, ...)."""
