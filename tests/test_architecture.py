"""The dependency direction of docs/architecture.md, checked on the source: every import
(module level or inside a function) of every module of each package goes down the layers,
never up or sideways, and importing a package loads no package above it."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PREFIX = "tactile_flow."     # the one installed import name; the folders are its subpackages

#: package -> the project packages it may import (docs/architecture.md, "Dependency direction")
ALLOWED = {
    "validation": set(),
    "tactile": {"validation"},
    "hardware": {"tactile", "validation"},
    "runstore": {"hardware", "tactile", "validation"},
    "cliapp": {"runstore", "hardware", "tactile", "validation"},
    "importers": {"cliapp", "runstore", "hardware", "tactile", "validation"},
    "protocols": {"importers", "cliapp", "runstore", "hardware", "tactile", "validation"},
    "analysis": {"cliapp", "runstore", "hardware", "tactile", "validation"},
    "viewer": {"analysis", "cliapp", "runstore", "hardware", "tactile", "validation"},
}
#: modules that stand beside the simulator and must not import it
BESIDE_THE_SIMULATOR = {m: set() for m in ("hardware.lab", "hardware.surfaces", "hardware.config",
                                           "hardware.lab_container", "hardware.transforms", "protocols.plan",
                                           "protocols.engine", "protocols.recorder")}
#: kept only so that old imports keep working (they re-export what moved)
RE_EXPORTS = {"protocols.store"}


def modules(package: str):
    for path in sorted((ROOT / package).rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        yield ".".join(parts[:-1] if parts[-1] == "__init__" else parts), path


def imports(module: str, path: Path) -> list[tuple[int, str]]:
    """(line, module) of every import in the file, relative ones resolved, the project's own
    named without their ``tactile_flow.`` prefix (as ``modules`` names them)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            out.append((node.lineno, target))
            out += [(node.lineno, f"{target}.{a.name}") for a in node.names]
    return [(line, t.removeprefix(PREFIX)) for line, t in out]


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_no_upward_or_sideways_import(package):
    bad = []
    for module, path in modules(package):
        if module in RE_EXPORTS:
            continue
        for line, target in imports(module, path):
            top = target.split(".")[0]
            if top in ALLOWED and top != package and top not in ALLOWED[package]:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {target}")
    assert not bad, f"{package} may import only {sorted(ALLOWED[package])}:\n" + "\n".join(bad)


@pytest.mark.parametrize("module", sorted(BESIDE_THE_SIMULATOR))
def test_the_real_lab_and_the_planner_do_not_stand_on_the_simulator(module):
    path = ROOT / (module.replace(".", "/") + ".py")
    found = {t for _, t in imports(module, path) if t.startswith("hardware.sim.") or t == "hardware.sim"}
    extra = {t for t in found if not any(t == ok or t.startswith(ok + ".") for ok in BESIDE_THE_SIMULATOR[module])}
    assert not extra, f"{module} imports from the simulator: {sorted(extra)}"


def test_drivers_do_not_import_the_emulators():
    bad = [f"{module} imports {t}" for module, path in modules("hardware")
           if not module.startswith("hardware.emulators")
           for _, t in imports(module, path) if t.startswith("hardware.emulators")]
    assert not bad, bad


def test_importing_a_package_loads_nothing_above_it():
    """Every module of the package imported in a fresh interpreter (``__main__`` scripts and
    the re-exports aside): only the packages below it may be loaded."""
    code = ("import importlib, json, sys\nfor m in json.loads(sys.argv[1]): importlib.import_module(m)\n"
            "print(json.dumps(sorted({m.split('.')[1] for m in sys.modules if m.startswith('tactile_flow.')}"
            " & set(json.loads(sys.argv[2])))))")
    for package, allowed in ALLOWED.items():
        names = [PREFIX + m for m, path in modules(package) if m not in RE_EXPORTS and not m.endswith("__main__")]
        out = subprocess.run([sys.executable, "-c", code, json.dumps(names), json.dumps(sorted(ALLOWED))],
                             cwd=ROOT, capture_output=True, text=True, check=True).stdout
        loaded = set(json.loads(out)) - {package}
        assert loaded <= allowed, f"import {package} loads {sorted(loaded - allowed)}"


#: SciPy packages the program does without: on import SciPy 1.17's ``scipy.signal`` parses its
#: docstrings and loads ``scipy.stats`` (~0.7 s on one core), ``scipy.spatial`` ~0.25 s; the few
#: functions used are in ``analysis.signal1d`` and ``hardware.transforms``
SCIPY_AVOIDED = ("scipy.signal", "scipy.spatial")


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_no_module_imports_scipy_signal_or_spatial(package):
    bad = [f"{path.relative_to(ROOT)}:{line} imports {t}" for module, path in modules(package)
           for line, t in imports(module, path) if any(t == a or t.startswith(a + ".") for a in SCIPY_AVOIDED)]
    assert not bad, "\n".join(bad)


def test_importing_a_run_and_its_analysis_loads_no_scipy():
    """No SciPy package is loaded but where it is used: the ellipsoid fit's optimiser on a cache
    miss, the pour's median filter (``scipy.ndimage`` alone cost a start ~0.2 s on one core).
    numba imports SciPy's top level (~10 ms), so that and its private modules are allowed."""
    code = ("import sys\nfrom tactile_flow.protocols import cli, entry, run\nfrom tactile_flow.analysis import run, entry\n"
            "from tactile_flow.analysis import figures\nfrom tactile_flow.viewer import draw\n"
            "print(sorted(m for m in sys.modules if m.startswith('scipy.') and not m.split('.')[1].startswith('_')\n"
            "             and m not in ('scipy.version', 'scipy.__config__')))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", f"loaded: {out.strip()}"


def _module_exists(name: str) -> bool:
    path = ROOT / name.replace(".", "/")
    return path.with_suffix(".py").exists() or (path / "__init__.py").exists()


@pytest.mark.parametrize("package", sorted(ALLOWED))
def test_every_import_of_the_project_names_a_module_that_exists(package):
    """Imports inside functions run only on their path (an error, an emulator's option): a
    module that moved must not leave one behind pointing at its old place."""
    bad = []
    for module, path in modules(package):
        base = PREFIX + (module if path.name == "__init__.py" else module.rpartition(".")[0])
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.ImportFrom):
                target = ".".join(base.split(".")[: len(base.split(".")) - node.level + 1] + [node.module or ""]) \
                    .rstrip(".") if node.level else node.module
                names = [target]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            bad += [f"{path.relative_to(ROOT)}:{node.lineno} imports {n}" for n in names
                    if n.startswith(PREFIX) and not _module_exists(n.removeprefix(PREFIX))]
            # the folders are installed as tactile_flow's subpackages only: a bare `import analysis`
            # would find another distribution's package (or a user's analysis.py)
            bad += [f"{path.relative_to(ROOT)}:{node.lineno} imports {n} (expected tactile_flow.{n})"
                    for n in names if n.split(".")[0] in ALLOWED]
    assert not bad, "\n".join(bad)
