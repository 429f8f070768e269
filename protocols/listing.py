"""``tactile-run --list``: the protocols, surfaces, hardware, sensors and experiments this project
ships (``conf/``), one line each: the first sentence of each file's header comment.

Reads the files' text only (no Hydra, no YAML parsing), so it answers at once.
"""

from __future__ import annotations

import re
from pathlib import Path

GROUPS = (("protocol", "protocols", "tactile-run protocol=NAME"),
          ("surface", "surfaces", "tactile-run surface=NAME (a protocol chooses its own)"),
          ("hardware", "hardware", "tactile-run hardware=NAME"),
          ("sensor", "sensors", "tactile-run sensor=NAME; docs/sensors.md"),
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
    text = re.sub(r"^(hardware=\w+|sensor=\w+|tactile-run [^:]*?)\s*:\s*", "", text)   # the file names itself
    text = re.sub(r"\s*\((schema|see) [^)]*\)", "", text)                   # pointers for developers
    sentence = re.split(r"(?<=[.!?])\s", text, maxsplit=1)[0] if text else "(no description)"
    return sentence if len(sentence) <= WIDTH else sentence[:WIDTH - 3].rstrip() + "..."


def listing(conf_dir: Path) -> str:
    """Every group's options with their one-line summaries."""
    out = []
    for group, title, usage in GROUPS:
        files = sorted((conf_dir / group).glob("*.yaml"))
        out.append(f"{title} ({usage}):")
        width = max((len(f.stem) for f in files), default=0)
        out += [f"  {f.stem:<{width}}  {summary(f)}" for f in files]
        out.append("")
    return "\n".join(out).rstrip()
