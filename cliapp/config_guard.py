"""Every config file Hydra reads is checked first: protocols are data, never code or Hydra settings.

A protocol (and a surface, hardware, analysis or experiment file) is shared between labs as
data. Hydra composes them with its own settings, and a file that writes under ``hydra`` —
``hydra.callbacks``, ``hydra.job_logging`` — makes Hydra instantiate objects or open files
*before* the run's own checks ever see the config. So the check happens where Hydra reads a
file: :func:`install` replaces Hydra's ``file://`` and ``pkg://`` config sources by the
guarded ones below, which refuse, naming the file and the key:

- in any file: YAML nested deeper than :data:`MAX_DEPTH` levels, aliases that expand to
  more than :data:`MAX_NODES` nodes (an "alias bomb"), files above :data:`MAX_BYTES`;
- in a file of a data group (every group but ``hydra/...``, whose files Hydra and the
  command line choose): any key under ``hydra`` (an experiment may set only
  ``hydra.sweeper.params``, and not for ``hydra`` keys), any ``_target_``, and defaults
  entries that select a ``hydra`` group or move a config to ``hydra`` or ``_global_``.

The primary config (``conf/config.yaml``...) and ``hydra/...`` files are the project's own
settings or chosen by name on the command line: only the size checks apply to them.

The guarded sources also note where every key of a data file was written (:data:`ORIGINS`,
file and line), so that an error about a key set in a file names the file and the line
(:func:`origin`; :func:`cliapp.runner.error_line`) as an error about a key set on the command
line names the key; a data file whose top-level key is its own group (``protocol:`` in a
protocol file) without ``# @package _global_`` is refused naming that file. On the command line,
``hydra.searchpath`` must name folders (``file://``) or packages (``pkg://``) that exist.
"""

from __future__ import annotations

import os
import re
import sys

import yaml
from hydra._internal.core_plugins.file_config_source import FileConfigSource as _File
from hydra._internal.core_plugins.importlib_resources_config_source import (
    ImportlibResourcesConfigSource as _Package, resources)
from hydra._internal.sources_registry import SourcesRegistry
from hydra.core.plugins import Plugins
from hydra.plugins.config_source import ConfigResult
from omegaconf import DictConfig, ListConfig, OmegaConf

from .packaged import repair_hint
from .quick_help import searchpath_entries, searchpath_problem

MAX_BYTES = 1 << 20          # a config file is a few kB
MAX_DEPTH = 48               # nested mappings/lists: 8 nested repeats of a protocol need ~30
MAX_NODES = 100_000          # YAML nodes once aliases are expanded
SWEEP_KEY = "hydra.sweeper.params"


class ConfigFileError(ValueError):
    """A config file that must not be composed; the message names the file and the key."""


#: where each key of the data files read so far was written: dotted key → (file, line, the key
#: its value interpolates when it is exactly ``${other.key}``, else None)
ORIGINS: dict[str, tuple[str, int, str | None]] = {}
#: the keys the command line sets (an error about one of them is the command line's)
COMMAND_LINE: set[str] = set()


def install(argv=None) -> None:
    """Make Hydra read config files through the guarded sources (call before ``@hydra.main``),
    after checking the command line's overrides (``argv``, default ``sys.argv[1:]``)."""
    argv = sys.argv[1:] if argv is None else argv
    check_overrides(argv)
    ORIGINS.clear()
    COMMAND_LINE.clear()
    COMMAND_LINE.update(override_keys(argv))
    Plugins.instance()                   # Hydra registers its own sources on first use; then ours replace them
    registry = SourcesRegistry.instance()
    registry.types["file"] = FileConfigSource
    registry.types["pkg"] = ImportlibResourcesConfigSource


def origin(key: str, _hops: int = 0) -> tuple[str, int] | None:
    """``(file, line)`` where the value of dotted ``key`` (or of the nearest node above it)
    was written in a data file, or None: not from a file, or set on the command line. A value
    written as ``${other.key}`` came from where ``other.key`` did (the command line, another
    line), if it was written anywhere."""
    if _set_on_command_line(key):
        return None
    exact = key
    while key:
        if key in ORIGINS:
            where, line, ref = ORIGINS[key]
            if ref and key == exact and _hops < 8:
                if _set_on_command_line(ref):
                    return None
                return origin(ref, _hops + 1) or (where, line)
            return where, line
        parent = re.sub(r"(\.[^.\[\]]+|\[\d+\])$", "", key)
        key = "" if parent == key else parent
    return None


def _set_on_command_line(key: str) -> bool:
    return any(key == k or key.startswith((k + ".", k + "[")) for k in COMMAND_LINE | _job_override_keys())


def _job_override_keys() -> set[str]:
    """The keys the running Hydra job's overrides set (a sweep's job in a worker process, where
    :func:`install` did not see the command line)."""
    from hydra.core.hydra_config import HydraConfig
    if not HydraConfig.initialized():
        return set()
    try:
        return override_keys(list(HydraConfig.get().overrides.task))
    except Exception:                               # noqa: BLE001 - a partial config: no keys
        return set()


def override_keys(args) -> set[str]:
    """The dotted keys the command line's overrides set (``a.b=1``, ``+a.b=1``, ``~a.b``); a
    group choice (``protocol=x``) chooses a file and sets no key."""
    keys = set()
    for arg in args:
        if arg.startswith("-") or "=" not in arg and not arg.startswith("~"):
            continue
        key = arg.split("=", 1)[0].lstrip("+~")
        if "." in key or "[" in key:
            keys.add(key)
    return keys


# ----------------------------------------------------------------------------- the text
def check_overrides(args) -> None:
    """Refuse a command-line value nested deeper than :data:`MAX_DEPTH` (``[``/``{`` outside
    quotes): Hydra's override parser would exhaust Python's recursion on it; and a
    ``hydra.searchpath`` entry that does not exist (:func:`cliapp.quick_help.searchpath_problem`)."""
    _check_depth(args)
    problem = searchpath_problem(searchpath_entries(args))
    if problem:
        raise ConfigFileError(problem)


def _check_depth(args) -> None:
    for arg in args:
        depth, quote = 0, None
        for ch in arg:
            if quote:
                quote = None if ch == quote else quote
            elif ch in "'\"":
                quote = ch
            elif ch in "[{":
                depth += 1
                if depth > MAX_DEPTH:
                    key = arg.split("=", 1)[0]
                    raise ConfigFileError(f"{key}: the value is nested more than {MAX_DEPTH} levels deep")
            elif ch in "]}":
                depth -= 1


def check_text(text: str, where: str):
    """Refuse YAML too large, too deep or whose aliases expand too far (before it is built);
    returns the YAML's node graph (with each key's line)."""
    if len(text) > MAX_BYTES:
        raise ConfigFileError(f"{where}: {len(text)} bytes, more than {MAX_BYTES}; a config file is a few kB")
    depth = 0
    try:
        for event in yaml.parse(text, Loader=yaml.SafeLoader):        # a stream of events: no recursion
            if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                depth += 1
                if depth > MAX_DEPTH:
                    line = event.start_mark.line + 1
                    raise ConfigFileError(f"{where} line {line}: nested more than {MAX_DEPTH} levels deep")
            elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                depth -= 1
        node = yaml.compose(text, Loader=yaml.SafeLoader)
    except yaml.YAMLError as exc:
        raise ConfigFileError(f"{where}: not valid YAML ({' '.join(str(exc).split())})") from None
    if node is not None and expanded_size(node) > MAX_NODES:
        raise ConfigFileError(f"{where}: its YAML aliases (*name) expand to more than {MAX_NODES} values; "
                              f"refusing to build it (write the values out, or use ${{...}} interpolation)")
    return node


def expanded_size(node, memo: dict | None = None) -> int:
    """Nodes of a composed YAML graph once every alias is expanded (shared nodes counted each
    time they are used), counted without expanding: the graph is a DAG, sizes are memoised."""
    memo = {} if memo is None else memo
    key = id(node)
    if key not in memo:
        memo[key] = 0                                # a (refused) cycle counts once
        if isinstance(node, yaml.MappingNode):
            children = [n for pair in node.value for n in pair]
        elif isinstance(node, yaml.SequenceNode):
            children = node.value
        else:
            children = []
        total = 1
        for child in children:
            total += expanded_size(child, memo)
            if total > MAX_NODES:
                break
        memo[key] = total
    return memo[key]


# ----------------------------------------------------------------------------- the content
def _data_group(config_path: str) -> str | None:
    """The group of a data file (``protocol`` for ``protocol/x``); None for the primary config
    and Hydra's own groups."""
    group = config_path.rsplit("/", 1)[0] if "/" in config_path else ""
    return None if group == "" or group == "hydra" or group.startswith("hydra/") else group


def _package(result: ConfigResult, group: str) -> str:
    package = result.header.get("package") or group.replace("/", ".")
    return group.replace("/", ".") if package == "_group_" else package


def check_result(result: ConfigResult, config_path: str, where: str, node=None) -> None:
    """Refuse a data-group file that reaches Hydra's settings or names a ``_target_``, or that
    lacks its ``# @package _global_`` line; note where each of its keys was written
    (:data:`ORIGINS`, from ``node``, the file's YAML graph)."""
    group = _data_group(config_path)
    if group is None:
        return                                       # the primary config and Hydra's own groups
    cfg = result.config
    if not isinstance(cfg, DictConfig):
        return
    package = _package(result, group)
    _check_package(cfg, group, package, where, node)
    _check_defaults(cfg, where)
    for key, value in _leaves(cfg, ""):
        key = key if package == "_global_" else f"{package}.{key}"
        if key.split(".")[-1] == "_target_":
            raise ConfigFileError(f"{where}: {key}: a config file is data; it may not name code to run "
                                  f"(_target_ {_brief(value)})")
        if key == "hydra" or key.startswith("hydra."):
            if group == "experiment" and key.startswith(SWEEP_KEY + "."):
                _check_sweep_param(key[len(SWEEP_KEY) + 1:], where)
                continue
            raise ConfigFileError(f"{where}: {key}: a {group} file is data; it may not change Hydra's settings "
                                  f"(hydra.*){' other than ' + SWEEP_KEY if group == 'experiment' else ''}")


def _check_package(cfg: DictConfig, group: str, package: str, where: str, node) -> None:
    """A data file whose top-level key is its own group (``protocol:`` in ``protocol/x.yaml``)
    but that lacks ``# @package _global_`` would put everything under ``protocol.protocol``
    (and its defaults under ``protocol``): refused here, naming this file, not later naming
    another."""
    name = group.split("/")[-1]
    if package != group.replace("/", ".") or name not in cfg:
        return
    line = _key_lines(node, "").get(name, (None,))[0]
    at = f" line {line}" if line else ""
    raise ConfigFileError(f"{where}{at}: `{name}:` at the top of a {name} file without `# @package _global_` would "
                          f"become {package}.{name}; expected the file's first line to be `# @package _global_` "
                          f"(as in conf/{group}/ files)")


def note_origins(node, package: str, where: str) -> None:
    """Note in :data:`ORIGINS` where each key of a data file's YAML graph ``node`` is written,
    under ``package`` (``_global_``: the keys as they are)."""
    prefix = "" if package in ("", "_global_") else package
    for key, (line, value) in _key_lines(node, prefix).items():
        if key != "defaults" and not key.startswith(("defaults.", "defaults[")):
            ref = re.fullmatch(r"\$\{([\w.\[\]]+)\}", value) if isinstance(value, str) else None
            ORIGINS[key] = (where, line, ref.group(1) if ref else None)


def _key_lines(node, prefix: str, out: dict | None = None) -> dict[str, tuple[int, object]]:
    """Dotted key (``a.b[2].c``) → (line (1-based), the scalar value written there or None) of
    every key and list item under ``node``."""
    out = {} if out is None else out
    if isinstance(node, yaml.MappingNode):
        pairs = [(f"{prefix}.{k.value}" if prefix else str(k.value), k, v) for k, v in node.value
                 if isinstance(k, yaml.ScalarNode)]
    elif isinstance(node, yaml.SequenceNode):
        pairs = [(f"{prefix}[{i}]", item, item) for i, item in enumerate(node.value)]
    else:
        return out
    for key, mark, value in pairs:
        out.setdefault(key, (mark.start_mark.line + 1, value.value if isinstance(value, yaml.ScalarNode) else None))
        _key_lines(value, key, out)
    return out


def _check_defaults(cfg: DictConfig, where: str) -> None:
    entries = cfg.get("defaults")
    if not isinstance(entries, ListConfig):
        return
    for i, entry in enumerate(entries):
        text = entry if isinstance(entry, str) else " ".join(str(k) for k in entry.keys()) \
            if isinstance(entry, DictConfig) else str(entry)
        words = [w for w in re.split(r"[\s/]+", text) if w and w not in ("override", "optional")]
        group, _, package = (words[0] if words else "").partition("@")
        if group.startswith("hydra") or package.startswith("hydra") or package == "_global_":
            raise ConfigFileError(f"{where}: defaults[{i}] ({_brief(text)}): a data file may only select data "
                                  f"groups (protocol, surface, hardware, ...): not hydra/..., not @hydra or "
                                  f"@_global_")


def _check_sweep_param(name: str, where: str) -> None:
    bare = name.lstrip("+~")
    if bare.startswith("hydra") or bare.split(".")[-1] == "_target_":
        raise ConfigFileError(f"{where}: {SWEEP_KEY}.{name}: a sweep may only vary the run's own keys, "
                              f"not Hydra's or a _target_")


def _leaves(node, key: str):
    """(dotted key, value) of every leaf under ``node`` (unresolved), through mappings and
    lists; the file's own ``defaults`` list is skipped (see :func:`_check_defaults`)."""
    if isinstance(node, (DictConfig, ListConfig)) and (node._is_none() or node._is_missing()):
        yield key, None
        return
    if isinstance(node, DictConfig):
        items = [(str(k), node._get_node(k)) for k in node.keys() if not (key == "" and k == "defaults")]
    elif isinstance(node, ListConfig):
        items = [(f"[{i}]", n) for i, n in enumerate(node._iter_ex(resolve=False))]
    else:
        yield key, node._value() if hasattr(node, "_value") else node
        return
    if not items and key:
        yield key, None
    for name, child in items:
        yield from _leaves(child, (f"{key}{name}" if name.startswith("[") else f"{key}.{name}") if key else name)


def _brief(value, limit: int = 60) -> str:
    text = repr(OmegaConf.to_container(value) if isinstance(value, (DictConfig, ListConfig)) else value)
    return text if len(text) <= limit else text[:limit] + "..."


# ----------------------------------------------------------------------------- the sources
# Named as Hydra's own classes: Hydra's registry keeps a source of the same name (see install).
class FileConfigSource(_File):
    """Hydra's ``file://`` source, reading through :func:`check_text` and :func:`check_result`."""

    def load_config(self, config_path: str) -> ConfigResult:
        full = os.path.realpath(os.path.join(self.path, self._normalize_file_name(config_path)))
        node = None
        try:
            if os.path.isfile(full):
                with open(full, encoding="utf-8", errors="replace") as f:
                    node = check_text(f.read(MAX_BYTES + 1), full)
            result = super().load_config(config_path)
            _checked(result, config_path, full, node)
        except ConfigFileError as exc:
            hint = repair_hint(full)             # one of the files we ship: a broken install
            raise ConfigFileError(f"{exc}; {hint}" if hint else str(exc)) from None
        return result


class ImportlibResourcesConfigSource(_Package):
    """Hydra's ``pkg://`` source, guarded like :class:`FileConfigSource`."""

    def load_config(self, config_path: str) -> ConfigResult:
        name = self._normalize_file_name(config_path)
        res = resources.files(self.path).joinpath(name)
        where = str(res) if os.path.isfile(str(res)) else f"pkg://{self.path}/{name}"   # a file's path where it has one
        node = None
        if res.is_file():
            node = check_text(res.read_bytes()[:MAX_BYTES + 1].decode("utf-8", "replace"), where)
        result = super().load_config(config_path)
        _checked(result, config_path, where, node)
        return result


def _checked(result: ConfigResult, config_path: str, where: str, node) -> None:
    check_result(result, config_path, where, node)
    group = _data_group(config_path)
    if group is not None and node is not None:
        note_origins(node, _package(result, group), where)
