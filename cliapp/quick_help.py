"""``--help`` / ``-h`` (and ``--version``) answered before Hydra is imported (Hydra composing the whole config
costs ~0.45 s): the same text as Hydra's help, read from the app's ``hydra.help.template``
with ``$APP_CONFIG_GROUPS`` filled from the config directory's groups and those of the
command line's ``hydra.searchpath`` folders, as Hydra lists them (a search-path entry that
does not exist is one line and exit status 2, as when composing: :func:`searchpath_problem`)."""

from __future__ import annotations

import os
import sys
from pathlib import Path
from string import Template


def config_groups(conf_dir: Path, searchpath=()) -> str:
    """``group: option, option`` lines, sorted, Hydra's own groups left out; ``searchpath``:
    the command line's ``hydra.searchpath`` entries, whose groups' options are added."""
    groups: dict[str, set[str]] = {}
    for folder in [conf_dir, *(searchpath_folder(e) for e in searchpath)]:
        if folder is None or not folder.is_dir():
            continue
        for group in (p for p in folder.iterdir() if p.is_dir() and p.name != "hydra"):
            options = {f.stem for f in group.glob("*.yaml")}
            if options:
                groups.setdefault(group.name, set()).update(options)
    return "\n".join(f"{name}: {', '.join(sorted(options))}" for name, options in sorted(groups.items())) + "\n"


def help_text(conf_dir: Path, config_name: str, searchpath=()) -> str:
    """The help Hydra would print for ``config_name`` in ``conf_dir`` (and ``searchpath``)."""
    import yaml
    template = yaml.safe_load((conf_dir / f"{config_name}.yaml").read_text())["hydra"]["help"]["template"]
    return Template(template).safe_substitute(APP_CONFIG_GROUPS=config_groups(conf_dir, searchpath))


def searchpath_entries(argv) -> list[str]:
    """The entries of a ``hydra.searchpath=[a,b]`` override in ``argv`` (none: []), read without
    Hydra: a list of plain or quoted strings."""
    for arg in argv:
        key, sep, value = arg.partition("=")
        if key == "hydra.searchpath" and sep:
            value = value.strip()
            if value.startswith("[") and value.endswith("]"):
                value = value[1:-1]
            return [v.strip().strip("'\"") for v in value.split(",") if v.strip()]
    return []


def searchpath_folder(entry: str) -> Path | None:
    """The folder a search-path entry names (``file://path``, a bare path, ``pkg://package``),
    or None if it names none."""
    scheme, sep, path = entry.partition("://")
    if not sep:
        scheme, path = "file", entry
    if scheme == "file":
        return Path(path) if os.path.isdir(path) else None
    if scheme == "pkg":
        import importlib.util
        try:
            spec = importlib.util.find_spec(path)
        except (ImportError, ValueError):
            return None
        locations = list(spec.submodule_search_locations or []) if spec is not None else []
        return Path(locations[0]) if locations else None
    return None


def searchpath_problem(entries) -> str | None:
    """The one line for the first search-path entry that names no folder or package (Hydra
    would skip it with a warning, and a protocol in it would then be "no such protocol"), or None."""
    for entry in entries:
        if searchpath_folder(entry) is None:
            scheme = entry.partition("://")[0] if "://" in entry else "file"
            expected = {"file": "no such folder; expected file://<a folder holding config groups: protocol/, "
                                "surface/, ...>",
                        "pkg": "no such package; expected pkg://<an importable package holding config groups>"}
            return f"hydra.searchpath: {entry}: " + expected.get(scheme, f"unknown scheme {scheme!r}; expected "
                                                                          f"file:// or pkg://")
    return None


def bad_input_and_exit(line: str) -> None:
    """``error: <line>`` on stderr and exit status 2 (bad input), as the apps do."""
    print(f"error: {line}", file=sys.stderr)
    sys.exit(2)


def wants_help(argv: list[str]) -> bool:
    return "--help" in argv or "-h" in argv


def answer_version(argv: list[str], prog: str) -> None:
    """``--version``: print the version and the commit it was built from, and exit 0."""
    if argv == ["--version"]:
        from tactile_flow import version_line
        print_and_exit(version_line(prog))


def print_and_exit(text: str) -> None:
    """Print ``text`` and exit 0. A reader that stops early (``tactile-run --help | head``) is
    not an error: no traceback, as for any command-line tool."""
    try:
        print(text, flush=True)
    except BrokenPipeError:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())   # the exit's flush goes nowhere
    sys.exit(0)
