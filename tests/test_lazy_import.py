"""``tactile._lazy.lazy_import``: a module imported on first use behaves as a plain import
would when that first use goes wrong (a Ctrl-C, an error) or comes from several threads."""

from __future__ import annotations

import sys
import threading

import pytest

from tactile_flow.tactile._lazy import lazy_import


@pytest.fixture
def package(tmp_path, monkeypatch):
    """A package ``lazypkg`` on the path, writing its modules' sources; forgotten afterwards."""
    root = tmp_path / "lazypkg"
    root.mkdir()
    (root / "__init__.py").write_text("")
    monkeypatch.syspath_prepend(str(tmp_path))
    yield lambda name, source: (root / f"{name}.py").write_text(source)
    for name in [n for n in sys.modules if n == "lazypkg" or n.startswith("lazypkg.")]:
        del sys.modules[name]


def test_a_ctrl_c_during_the_first_import_reaches_the_import_statement_and_leaves_no_half_module(package):
    """Where a lazily bound module is then imported by an import statement, CPython reads its
    ``__spec__`` and drops any error that raises: with the standard ``LazyLoader`` the Ctrl-C
    vanished there and a half-executed module stayed (seen in ``tactile-analyze``)."""
    package("interrupted", "BEFORE = 1\nraise KeyboardInterrupt\nAFTER = 2\n")
    lazy_import("lazypkg.interrupted")

    def import_statement():
        from lazypkg import interrupted
        return interrupted

    with pytest.raises(KeyboardInterrupt):
        import_statement()
    assert "lazypkg.interrupted" not in sys.modules
    with pytest.raises(KeyboardInterrupt):                    # asked again, it runs again
        import_statement()


def test_an_error_in_the_module_surfaces_at_its_first_use_each_time(package):
    package("broken", "import no_such_module_here\nVALUE = 1\n")
    broken = lazy_import("lazypkg.broken")
    for _ in range(2):
        with pytest.raises(ModuleNotFoundError, match="no_such_module_here"):
            broken.VALUE


def test_nothing_is_imported_before_first_use_and_then_it_is_the_module_itself(package):
    package("light", "VALUE = 42\n")
    light = lazy_import("lazypkg.light")
    assert "lazypkg.light" not in sys.modules
    assert "not imported yet" in repr(light)
    assert light.VALUE == 42
    assert sys.modules["lazypkg.light"].VALUE == 42
    assert lazy_import("lazypkg.light") is sys.modules["lazypkg.light"]


def test_threads_that_first_use_it_at_once_all_see_the_whole_module(package):
    """The flow jobs' threads may be the first users; none may see the module half-run."""
    package("slow", "import time\ntime.sleep(0.3)\nVALUE = 7\n")
    slow = lazy_import("lazypkg.slow")
    seen, start = [], threading.Barrier(4)

    def use():
        start.wait()
        try:
            seen.append(slow.VALUE)
        except Exception as exc:              # noqa: BLE001 - what a half-run module shows
            seen.append(repr(exc))

    threads = [threading.Thread(target=use) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert seen == [7, 7, 7, 7]
