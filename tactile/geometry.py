"""The fingertip's geometry, in one place for those who import it from here.

The pieces live in modules of one idea each:

- :mod:`tactile.taxels`: the 24 taxel positions (:func:`load_taxels`);
- :mod:`tactile.ellipsoid`: the half-ellipsoid fitted to them, its frame and parameterisation,
  surface maps and closest points (:func:`fit_ellipsoid`, :class:`EllipsoidFit`, ...);
- :mod:`tactile.geodesic`: geodesic distances on it, the method's (θ, φ) path and the accurate
  discrete geodesic (its numba kernels in ``tactile._geodesic_kernels``);
- :mod:`tactile.disk_cache`: those distances and the fit, computed once and kept on disk;
- :mod:`tactile.surface`: the kernel of the geodesic distance (:func:`kernel_weights`) and the
  interpolation over the surface mesh.

>>> from tactile_flow.tactile.geometry import fit_ellipsoid, load_taxels
>>> fit_ellipsoid(load_taxels()).axes.round(1).tolist()         # semi-axes (mm)
[12.0, 7.8, 7.0]
"""

from __future__ import annotations

from .ellipsoid import (SURFACE_TOL, EllipsoidFit, ellipsoid_angles, ellipsoid_normals, ellipsoid_points,
                        fit_ellipsoid, project_to_ellipsoid, taxel_angles)
from .geodesic import ALGORITHM_VERSION, GEODESIC_METHODS, geodesic_distances, geodesic_path
from .disk_cache import cached_fit_ellipsoid, cached_geodesic_distances, default_cache_dir
from .surface import KERNEL_FORMS, kernel_weights
from .taxels import load_taxels

__all__ = ["ALGORITHM_VERSION", "GEODESIC_METHODS", "KERNEL_FORMS", "SURFACE_TOL", "EllipsoidFit",
           "cached_fit_ellipsoid", "cached_geodesic_distances", "default_cache_dir", "ellipsoid_angles", "ellipsoid_normals",
           "ellipsoid_points", "fit_ellipsoid", "geodesic_distances", "geodesic_path", "kernel_weights",
           "load_taxels", "project_to_ellipsoid", "taxel_angles"]
