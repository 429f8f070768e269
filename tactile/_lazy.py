"""A module bound now and executed on first use (the standard library's ``LazyLoader`` recipe).

Lets the light parts of the package (configs, dataclasses) be imported without compiling
numba kernels or loading SciPy, so that ``--help`` of the commands stays fast.
"""

from __future__ import annotations

import importlib.util
import sys
from types import ModuleType


def lazy_import(name: str) -> ModuleType:
    """The module ``name``, executed when one of its attributes is first read.

    >>> signals = lazy_import("tactile.signals")
    >>> signals.N_TAXELS
    24
    """
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    loader = importlib.util.LazyLoader(spec.loader)
    spec.loader = loader
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    loader.exec_module(module)
    return module
