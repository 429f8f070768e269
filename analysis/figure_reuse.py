"""Figures addressed by their content: a re-analysis links the figures whose inputs it shares
with an earlier analysis of the run instead of drawing them again.

A figure's key (:func:`figure_key`) is a hash of what its drawing reads (the values that
``figures.READS`` lists for its builder: arrays, segments, events, the sensor model's mesh...),
of the drawing code (``figures.py``, ``agg_canvas.py``, this module), matplotlib's version and
its ``rcParams``. Two figures with one key are the same PNG, to the byte: the drawing is
deterministic (``tests/test_analysis_runs.py`` draws them here and in forked workers and
compares the files). Each analysis records its figures' keys in ``analysis.json``
(``figure_keys``); :func:`earlier_figures` collects the figure files of a run's kept analyses
by key, the current analysis's first, and :func:`link` puts one into a new analysis (a hard
link: no second copy on disk; a copy where links are not possible).

A figure whose builder lists no inputs gets no key and is always drawn.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import shutil
from functools import lru_cache
from pathlib import Path

import numpy as np

from tactile_flow.runstore import analyses, files

KEY_FIELD = "figure_keys"
"""``analysis.json``'s field: figure file name → its key."""
_CODE = ("figures.py", "agg_canvas.py", "figure_reuse.py")


@lru_cache(maxsize=1)
def _code() -> bytes:
    import matplotlib as mpl
    h = hashlib.sha256()
    here = Path(__file__).resolve().parent
    for name in _CODE:
        h.update((here / name).read_bytes())
    h.update(f"{mpl.__version__} {np.__version__}".encode())
    return h.digest()


def code_digest() -> str:
    """What every figure key includes besides its inputs: the drawing code's bytes,
    matplotlib's and numpy's versions and matplotlib's ``rcParams`` as they are now (a style
    changes the pictures)."""
    import matplotlib as mpl
    h = hashlib.sha256(_code())
    h.update(repr(sorted((k, repr(v)) for k, v in mpl.rcParams.items())).encode())
    return h.hexdigest()


_PLAIN = (type(None), bool, int, float, str)


def _plain(values) -> bool:
    return all(type(v) in _PLAIN for v in values)


def _feed(h, obj) -> None:
    """Feed ``obj`` to the hash ``h`` unambiguously (type tags, lengths, array dtypes and shapes;
    a container of plain Python scalars as its ``repr``, which tells their types apart)."""
    if obj is None or isinstance(obj, (bool, int, float, str, np.generic)):
        h.update(f"{type(obj).__name__}:{obj!r};".encode())
    elif isinstance(obj, np.ndarray):
        a = np.ascontiguousarray(obj)
        h.update(f"nd:{a.dtype.str}:{a.shape};".encode())
        h.update(a.view(np.uint8).reshape(-1) if a.dtype != object else repr(a.tolist()).encode())
    elif isinstance(obj, dict):
        keys = sorted(obj, key=repr)
        if _plain(keys) and _plain(obj.values()):
            h.update(f"pdict:{[(k, obj[k]) for k in keys]!r};".encode())
            return
        h.update(f"dict:{len(obj)};".encode())
        for k in keys:
            _feed(h, k)
            _feed(h, obj[k])
    elif isinstance(obj, (list, tuple)):
        if _plain(obj):
            h.update(f"pseq:{list(obj)!r};".encode())
            return
        h.update(f"seq:{len(obj)};".encode())
        for x in obj:
            _feed(h, x)
    elif dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        h.update(f"dc:{type(obj).__qualname__};".encode())
        for f in dataclasses.fields(obj):
            _feed(h, f.name)
            _feed(h, getattr(obj, f.name))
    else:
        raise TypeError(f"figure inputs: cannot hash a {type(obj).__name__}")


def figure_key(name: str, inputs, code: str | None = None) -> str:
    """The key (32 hex digits) of the figure file ``name`` drawn from ``inputs``; ``code``:
    :func:`code_digest` if computed already (once for a run's figures)."""
    h = hashlib.sha256((code or code_digest()).encode())
    _feed(h, name)
    _feed(h, inputs)
    return h.hexdigest()[:32]


def earlier_figures(run_dir) -> dict[str, Path]:
    """Figure key → the file of an earlier analysis of the run drawn with that key (a plain
    file in ``analyses/<name>/figures/``; the current analysis's when several have it)."""
    run_dir = Path(run_dir)
    inside = Path(os.path.realpath(run_dir))
    current = analyses.current_dir(run_dir)
    found: dict[str, Path] = {}
    kept = analyses.listing(run_dir, legacy=False)
    kept.sort(key=lambda a: current is not None and Path(a["path"]) == current)     # the current one last: it wins
    for a in kept:
        keys = a.get(KEY_FIELD)
        if not isinstance(keys, dict):
            continue
        for name, key in keys.items():
            path = Path(a["path"]) / "figures" / str(name)
            if (isinstance(key, str) and Path(name).name == name and files.is_plain_file(path)
                    and inside in Path(os.path.realpath(path)).parents):      # no link out of the run
                found[key] = path
    return found


def link(src: Path, dst: Path) -> None:
    """``dst`` as ``src``'s hard link (a copy across file systems or where links fail)."""
    try:
        os.link(src, dst, follow_symlinks=False)
    except OSError:
        shutil.copyfile(src, dst, follow_symlinks=False)
