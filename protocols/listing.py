"""``tactile-run --list``: the protocols, surfaces, hardware and experiments this project
ships (``conf/``) and those of the command line's ``hydra.searchpath`` folders, one line each:
the first sentence of each file's header comment, a search path's files marked with where
they are. Hydra looks in ``conf/`` first, so a search-path file named as a packaged one is
never used: it is listed as hidden.

Reads the files' text only (no Hydra, no YAML parsing), so it answers at once.
"""

from __future__ import annotations

import re
from pathlib import Path

from tactile_flow.cliapp.quick_help import searchpath_folder

GROUPS = (("protocol", "protocols", "tactile-run protocol=NAME"),
          ("surface", "surfaces", "tactile-run surface=NAME (a protocol chooses its own)"),
          ("hardware", "hardware", "tactile-run hardware=NAME"),
          ("experiment", "experiments (sweeps)", "tactile-run -m +experiment=NAME"))
WIDTH = 110


def summary(path: Path) -> str:
    """The first sentence of the comment block at the top of a config file."""
    lines = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        text = line.lstrip("#").strip()
        if text and not text.startswith("@package"):
            lines.append(text)
    text = " ".join(lines)
    text = re.sub(r"^(hardware=\w+|tactile-run [^:]*?)\s*:\s*", "", text)   # the file names itself
    text = re.sub(r"\s*\((schema|see) [^)]*\)", "", text)                   # pointers for developers
    sentence = re.split(r"(?<=[.!?])\s", text, maxsplit=1)[0] if text else "(no description)"
    return sentence if len(sentence) <= WIDTH else sentence[:WIDTH - 3].rstrip() + "..."


def listing(conf_dir: Path, searchpath=()) -> str:
    """Every group's options with their one-line summaries: ``conf_dir``'s, then those of each
    ``searchpath`` entry (``file://`` folders; ``pkg://`` packages), in Hydra's order."""
    folders = [(None, Path(conf_dir))] + [(entry, folder) for entry in searchpath
                                          for folder in [searchpath_folder(entry)] if folder is not None]
    out = []
    for group, title, usage in GROUPS:
        options: dict[str, tuple[Path, str | None]] = {}
        hidden = []
        for entry, folder in folders:
            for f in sorted((folder / group).glob("*.yaml")) if (folder / group).is_dir() else []:
                if f.stem in options:
                    hidden.append(f"  ({f.stem} in {entry} is hidden by the one before it in the search path)")
                else:
                    options[f.stem] = (f, entry)
        out.append(f"{title} ({usage}):")
        width = max((len(name) for name in options), default=0)
        for name in sorted(options):
            path, entry = options[name]
            out.append(f"  {name:<{width}}  {summary(path)}" + (f"  [{entry}]" if entry else ""))
        out += hidden
        out.append("")
    return "\n".join(out).rstrip()


