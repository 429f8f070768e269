"""What a run keeps of its inputs, so that it can be done again from its directory alone.

When a run starts (:func:`record_inputs`, called by :func:`protocols.run.run_protocol` inside a
``tactile-run`` job) its directory receives, beside Hydra's ``.hydra/``:

- ``config/<source>/...``: a copy of every config file Hydra composed — the primary
  ``config.yaml`` and each group's option (``protocol/straws_sweep.yaml``,
  ``surface/straws.yaml``, ``hardware/sim.yaml``, ``analysis/default.yaml``, an
  ``experiment``, ``hydra/job_logging/tactile.yaml``...) — under the config source it came
  from: ``main`` (the package's ``conf/``), or ``1``, ``2``... for the folders of
  ``hydra.searchpath``, in their order;
- ``config/files/<key>/<name>``: files a config value names (``hardware.biotac_calibration``);
- ``code.diff``: the uncommitted changes of the code (tracked files, and untracked files of
  the code's folders as new files) when the tree is not clean (:func:`runstore.provenance.code_state`).

and ``run.json`` gets ``inputs``: the working directory, the config name, the sources,
every copied file with its SHA-256, the job's overrides (task and Hydra's own, the search
path among them). ``tactile-runs reproduce`` composes the run again from those copies
(:mod:`runstore.reproduce`).
"""

from __future__ import annotations

import hashlib
import os
from importlib import resources
from pathlib import Path

from omegaconf import OmegaConf

from tactile_flow.runstore import files, provenance

CONFIG_DIR = "config"
#: config keys whose value is a file the run reads (copied with the run)
INPUT_FILE_KEYS = ("hardware.biotac_calibration",)
SKIPPED_PROVIDERS = ("hydra", "schema")          # Hydra's own defaults; the structured schema (code)


def _source_root(source, cwd: str):
    """The directory (or package resource) a Hydra config source reads, or None."""
    path = str(source.path)
    if source.schema == "file":
        root = Path(path)
        return root if root.is_absolute() else Path(cwd) / root
    if source.schema == "pkg":
        try:
            return resources.files(path.replace("/", "."))
        except (ModuleNotFoundError, TypeError):
            return None
    return None


def _choices(hc) -> list[tuple[str, str]]:
    out = []
    for group, option in OmegaConf.to_container(hc.runtime.choices).items():
        for opt in (option if isinstance(option, list) else [option]):
            if opt is not None:
                out.append((str(group), str(opt)))
    return out


def composed_files(hc) -> tuple[list[dict], list[dict]]:
    """The config sources Hydra searched (Hydra's own and the schema left out), and every
    file it composed: ``{"group", "option", "source": index, "file": Traversable}``, the primary
    config first. A group option is taken from the first source that has it, as Hydra does."""
    cwd = os.getcwd()
    sources = []
    for s in hc.runtime.config_sources:
        if s.provider in SKIPPED_PROVIDERS:
            continue
        sources.append({"provider": str(s.provider), "schema": str(s.schema), "path": str(s.path),
                        "root": _source_root(s, cwd)})
    found = []

    def look(rel: str, group: str, option: str) -> None:
        for i, s in enumerate(sources):
            if s["root"] is None:
                continue
            candidate = s["root"].joinpath(*rel.split("/"))
            if candidate.is_file():
                found.append({"group": group, "option": option, "source": i, "rel": rel, "file": candidate})
                return
    look(f"{hc.job.config_name}.yaml", "", str(hc.job.config_name))
    for group, option in _choices(hc):
        look(f"{group}/{option}.yaml", group, option)
    return sources, found


def record_inputs(run_dir: Path, cfg) -> dict | None:
    """Copy the run's config files, the files its values name and the code's diff into
    ``run_dir`` (:mod:`runstore.files`, as its record); returns the ``inputs`` entry of
    ``run.json`` (None outside a Hydra job, e.g. a test calling ``run_protocol``)."""
    from hydra.core.hydra_config import HydraConfig
    if not HydraConfig.initialized():
        return None
    hc = HydraConfig.get()
    sources, found = composed_files(hc)
    names = ["main" if s["provider"] == "main" else str(i) for i, s in enumerate(sources)]
    copied = []
    for f in found:
        data = f["file"].read_bytes()
        rel = f"{CONFIG_DIR}/{names[f['source']]}/{f['rel']}"
        files.write_bytes(run_dir, rel, data, record=True, fsync=False)
        copied.append({"group": f["group"], "option": f["option"], "source": names[f["source"]], "copy": rel,
                       "sha256": hashlib.sha256(data).hexdigest()})
    named = []
    for key in INPUT_FILE_KEYS:
        value = _value(cfg, key)
        if isinstance(value, str) and Path(value).expanduser().is_file():
            data = Path(value).expanduser().read_bytes()
            rel = f"{CONFIG_DIR}/files/{key}/{Path(value).name}"
            files.write_bytes(run_dir, rel, data, record=True, fsync=False)
            named.append({"key": key, "value": value, "copy": rel, "sha256": hashlib.sha256(data).hexdigest()})
    return {"cwd": os.getcwd(), "config_name": str(hc.job.config_name),
            "sources": [{"name": n, "provider": s["provider"], "schema": s["schema"], "path": s["path"]}
                        for n, s in zip(names, sources)],
            "files": copied, "value_files": named,
            "task_overrides": list(OmegaConf.to_container(hc.overrides.task)),
            "hydra_overrides": list(OmegaConf.to_container(hc.overrides.hydra))}


def _value(settings, key: str):
    """The value of dotted ``key`` in the run's typed settings (:class:`~protocols.settings.RunSettings`),
    or None where it has none (a backend without that key)."""
    value = settings
    for name in key.split("."):
        value = getattr(value, name, None)
    return value


def record_code(run_dir: Path) -> dict:
    """The code's state (:func:`runstore.provenance.code_state`); its uncommitted changes, if any,
    written to ``run_dir/code.diff`` (the file named in the result)."""
    state, diff = provenance.code_state()
    if diff:
        files.write_bytes(run_dir, provenance.CODE_DIFF, diff, record=True)
        state["diff_file"] = provenance.CODE_DIFF
    return state
