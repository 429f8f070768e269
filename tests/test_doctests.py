"""The examples in the docstrings of ``tactile/`` run, and say what they print."""

import doctest
import importlib
import pkgutil

import pytest

from tactile_flow import tactile

MODULES = sorted(m.name for m in pkgutil.iter_modules(tactile.__path__, "tactile_flow.tactile.")
                 if m.name != "tactile_flow.tactile.demo")


@pytest.mark.parametrize("name", MODULES)
def test_docstring_examples(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples failed"


def test_public_names_declared():
    for name in MODULES:
        module = importlib.import_module(name)
        if name.rsplit(".", 1)[1].startswith("_"):
            continue
        assert hasattr(module, "__all__"), f"{name}: no __all__"
        missing = [n for n in module.__all__ if not hasattr(module, n)]
        assert not missing, f"{name}: __all__ names {missing} it does not define"
