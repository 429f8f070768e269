"""Computational tactile flow for BioTac fingertips and other taxel arrays: pure computation on arrays.

Modules, in the order the method uses them:

- :mod:`tactile.sensor`    a sensor described as data (taxels, surface, views, channels, limits)
- :mod:`tactile.signals`   raw counts → impedance (kΩ) → activation; Kalman filter + RTS smoother
- :mod:`tactile.geometry`  taxel positions, half-ellipsoid fit, geodesic distances (cached)
- :mod:`tactile.surface`   surface mesh, kernel interpolation, the displaced *tactile surface*
- :mod:`tactile.frames`    views and the z-buffered *tactile frames*
- :mod:`tactile.flow`      dense optical flow between frames (*tactile flow*)
- :mod:`tactile.aggregate` per-frame and per-window summaries of a flow field
- :mod:`tactile.pipeline`  the whole chain for a record, with its configuration
- :mod:`tactile.online`    the same chain one frame at a time, for a live stream
- :mod:`tactile.warmup`    a first run's numba kernels compiled in child processes, one per core

This package imports nothing else of the project.
"""

FINGERS = ("ff", "mf", "rf", "lf", "th")
N_TAXELS = 24
"""Taxels of the default sensor model (the BioTac SP); code that handles a record reads the
count from its :class:`tactile.sensor.SensorModel` instead."""
