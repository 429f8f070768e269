"""Build hooks only (the metadata is in pyproject.toml): the commit a wheel or sdist was built
from is written into it as ``tactile_flow/_build.json``, so that an installed copy, which has
no git checkout, can still say which code it is (``tactile-run --version``, run provenance)."""

import json
import subprocess
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py
from setuptools.command.sdist import sdist

BUILD_INFO = Path("tactile_flow") / "_build.json"


def _git(*args: str) -> str | None:
    try:
        return subprocess.run(["git", *args], capture_output=True, text=True, check=True, timeout=20).stdout
    except (OSError, subprocess.SubprocessError):
        return None


def build_info() -> dict:
    """The commit and whether tracked files differed from it; from the sdist's own record when
    there is no checkout (a wheel built from an sdist)."""
    if Path(".git").exists() and (commit := _git("rev-parse", "HEAD")):
        dirty = bool(_git("status", "--porcelain", "--untracked-files=no"))
        return {"commit": commit.strip(), "dirty": dirty}
    if BUILD_INFO.exists():
        return json.loads(BUILD_INFO.read_text())
    return {"commit": "unknown", "dirty": "unknown"}


class BuildPy(build_py):
    def run(self):
        super().run()
        if not self.editable_mode:           # an editable install asks git at run time instead
            target = Path(self.build_lib) / BUILD_INFO
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_text(json.dumps(build_info()) + "\n")


class Sdist(sdist):
    def make_release_tree(self, base_dir, files):
        super().make_release_tree(base_dir, files)
        (Path(base_dir) / BUILD_INFO).write_text(json.dumps(build_info()) + "\n")


setup(cmdclass={"build_py": BuildPy, "sdist": Sdist})
