"""Computational tactile flow for BioTac SP fingertips: pure computation on arrays.

Modules, in the order the method uses them:

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
