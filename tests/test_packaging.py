"""The distribution as a user installs it: one wheel, one top-level import name, its configs and
data inside, every command working from an empty directory with the checkout's results.

The slow test builds the sdist, the wheel from that sdist (``python -m build``: what a package
index would get), installs the wheel into a new virtual environment outside the checkout and
runs the commands there."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tomllib
import venv
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text())
SETUPTOOLS = PYPROJECT["tool"]["setuptools"]
BAG = ROOT / "tests" / "data" / "biotac_rest_untouched.bag"


SHIPPED = (".py", ".yaml", ".csv", ".json", ".md")     # what the package's folders hold that a command reads


def test_every_folder_with_code_or_data_is_a_listed_package():
    """A folder left out of ``[tool.setuptools] packages`` works in a checkout and is missing
    from the wheel (or is shipped with a warning that a later setuptools drops it): every folder
    directly holding code or data under a mapped folder is listed, and only those."""
    listed = set(SETUPTOOLS["packages"])
    found = set()
    for top, folder in SETUPTOOLS["package-dir"].items():
        for f in (ROOT / folder).rglob("*"):
            rel = f.parent.relative_to(ROOT / folder)
            if f.is_file() and f.suffix in SHIPPED and "__pycache__" not in rel.parts:
                found.add(".".join([top, *rel.parts]))
    assert found == listed, f"not listed: {sorted(found - listed)}; listed, but no code or data: {sorted(listed - found)}"


def test_one_top_level_name_and_every_script_under_it():
    assert {p.split(".")[0] for p in SETUPTOOLS["packages"]} == {"tactile_flow"}
    targets = [*PYPROJECT["project"]["scripts"].values(),
               *(t for group in PYPROJECT["project"]["entry-points"].values() for t in group.values())]
    assert targets and all(t.startswith("tactile_flow.") for t in targets), targets


# ----------------------------------------------------------------------------- the built wheel
def _run(cmd, cwd, env=None, timeout=900) -> subprocess.CompletedProcess:
    proc = subprocess.run([str(c) for c in cmd], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, f"{' '.join(map(str, cmd))}: exit {proc.returncode}\n{proc.stdout}\n{proc.stderr}"
    return proc


def _run_dir(stdout: str, cwd: Path) -> Path:
    [line] = [ln for ln in stdout.splitlines() if ln.startswith("run ") and ln.endswith(": success")]
    path = Path(line.removeprefix("run ").removesuffix(": success"))
    return path if path.is_absolute() else cwd / path


@pytest.fixture(scope="module")
def dist(tmp_path_factory) -> Path:
    """``dist/`` with the sdist and the wheel built from it."""
    out = tmp_path_factory.mktemp("dist")
    _run([sys.executable, "-m", "build", "--outdir", out, ROOT], cwd=out)
    return out


@pytest.fixture(scope="module")
def installed(dist, tmp_path_factory) -> Path:
    """A new virtual environment, outside the checkout, with the wheel installed; its bin/."""
    env_dir = tmp_path_factory.mktemp("venv")
    venv.create(env_dir, with_pip=True)
    [wheel] = dist.glob("*.whl")
    _run([env_dir / "bin" / "python", "-m", "pip", "install", "--quiet", wheel], cwd=env_dir)
    return env_dir / "bin"


def _clean_env(bin_dir: Path) -> dict:
    """The installed environment alone: nothing of the checkout's virtual environment on the path."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    return env


@pytest.mark.slow
def test_the_wheel_holds_one_top_level_name_its_configs_data_and_licence(dist):
    [wheel] = dist.glob("*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    version = PYPROJECT["project"]["version"]
    assert {n.split("/")[0] for n in names} == {"tactile_flow", f"tactile_flow-{version}.dist-info"}
    shipped = set(names)
    # every config, every data file the commands read, every module of the checkout
    for top, folder in SETUPTOOLS["package-dir"].items():
        base = top.replace(".", "/")
        for f in (ROOT / folder).rglob("*"):
            if f.is_file() and "__pycache__" not in f.parts and f.suffix in SHIPPED:
                assert f"{base}/{f.relative_to(ROOT / folder).as_posix()}" in shipped, f"{f} is not in the wheel"
    assert f"tactile_flow-{version}.dist-info/licenses/LICENSE" in shipped
    built = json.loads(zipfile.ZipFile(wheel).read("tactile_flow/_build.json"))
    head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    if head:
        assert built["commit"] == head          # the wheel was built from the sdist: the commit went through it
    [sdist] = dist.glob("*.tar.gz")
    assert sdist.name == f"tactile_flow-{version}.tar.gz"


@pytest.mark.slow
def test_every_command_runs_from_an_empty_directory_with_the_checkouts_results(installed, tmp_path):
    env = _clean_env(installed)
    here = tmp_path / "empty"
    here.mkdir()
    version = _run([installed / "python", "-m", "tactile_flow", "--version"], here, env).stdout
    assert version.startswith(f"tactile-flow {PYPROJECT['project']['version']} (commit ")
    out = _run([installed / "tactile-run", "progress=false"], here, env).stdout
    run_dir = _run_dir(out, here)
    assert run_dir.is_relative_to(here / "outputs")
    # the same run from the checkout
    there = tmp_path / "checkout"
    there.mkdir()
    ref_dir = _run_dir(_run([Path(sys.executable).parent / "tactile-run", "progress=false"], there).stdout, there)
    headline = json.loads((run_dir / "summary.json").read_text())["headline"]
    assert headline == json.loads((ref_dir / "summary.json").read_text())["headline"]
    assert headline["score_all_targets_met"] is True
    # the other commands, from the same directory
    _run([installed / "tactile-analyze", f"run={run_dir / 'run.zarr'}", "analysis.figures=false",
          "analysis.progress=false"], here, env)
    imported = _run([installed / "tactile-import", f"source={BAG}", "out=imported"], here, env)
    assert list((here / "imported").rglob("run.zarr.zip")), imported.stdout
    _run([installed / "tactile-recover", "--help"], here, env)
    for command in ("tactile-emulate", "tactile-view", "tactile-demo"):
        assert "usage" in _run([installed / command, "--help"], here, env).stdout.lower()
    # nothing of the checkout was used: the modules came from the new environment
    where = _run([installed / "python", "-c", "import tactile_flow.protocols.cli as m; print(m.__file__)"],
                 here, env).stdout
    assert not Path(where.strip()).is_relative_to(ROOT)


@pytest.mark.slow
def test_a_broken_install_is_one_line_naming_the_file(installed, tmp_path):
    env = _clean_env(installed)
    site = Path(_run([installed / "python", "-c", "import tactile_flow.conf as c; print(c.DIR)"], tmp_path,
                     env).stdout.strip())
    protocol = site / "protocol" / "straws_sweep.yaml"
    text = protocol.read_text()
    try:
        protocol.write_text("name: [broken\n")
        proc = subprocess.run([installed / "tactile-run", "plan_only=true"], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=300)
    finally:
        protocol.write_text(text)
    assert proc.returncode == 2
    assert proc.stderr.count("\n") == 1 and str(protocol) in proc.stderr
    assert "pip install --force-reinstall tactile-flow" in proc.stderr
