"""A module imported on first use, so that the light parts of the package (configs,
dataclasses) can be imported without compiling numba kernels or loading SciPy, and the
commands' ``--help`` stays fast.

Not the standard library's ``LazyLoader``: it puts a half-made module in ``sys.modules``
and runs the module's code inside whatever first reads one of its attributes, and CPython's
import statement reads ``__spec__`` there and drops any error it raises (3.11,
``import_ensure_initialized``). A Ctrl-C landing during that first read was lost and left
the module half-executed (seen: ``module 'numba' has no attribute 'core'``, exit 1, where
the analysis should have said ``interrupted``), and threads that asked at once could see the
half-executed module. Here nothing enters ``sys.modules`` before a plain import, which
raises what it raises and makes other threads wait until the module is complete.
"""

from __future__ import annotations

import importlib
import sys
from types import ModuleType


class _OnFirstUse:
    """Stands for the module ``name``; the first attribute read imports it."""

    __slots__ = ("_name", "_module")

    def __init__(self, name: str):
        object.__setattr__(self, "_name", name)
        object.__setattr__(self, "_module", None)

    def __getattribute__(self, attr: str):
        # every read goes here (not __getattr__, which Python reaches only after a failed
        # lookup has built an AttributeError: ~2.5 µs a read instead of ~0.2 µs)
        module = object.__getattribute__(self, "_module")
        if module is None:
            name = object.__getattribute__(self, "_name")
            module = importlib.import_module(name)
            object.__setattr__(self, "_module", module)
        return getattr(module, attr)

    def __repr__(self) -> str:
        module = object.__getattribute__(self, "_module")
        return f"<module {object.__getattribute__(self, '_name')!r}, {'imported' if module else 'not imported yet'}>"


def lazy_import(name: str) -> ModuleType:   # a stand-in until then, read like the module
    """The module ``name``, imported when one of its attributes is first read (the module
    itself if it is imported already).

    >>> signals = lazy_import("tactile_flow.tactile.signals")
    >>> signals.COUNTS_MAX
    4095
    """
    if name in sys.modules:
        return sys.modules[name]
    return _OnFirstUse(name)
