"""JSON values for the run store's attributes and ``run.json``: :func:`jsonable` turns numpy
values into plain Python and non-finite floats into ``None`` (JSON has no NaN); :func:`utc_now`
is the one time stamp format of the store (ISO 8601 UTC with microseconds and ``Z``)."""

from __future__ import annotations

import json
import math
from datetime import datetime, timezone
from pathlib import Path

import numpy as np


def utc_now() -> str:
    """Current UTC time, ISO 8601 with microseconds and ``Z``."""
    return datetime.now(timezone.utc).isoformat(timespec="microseconds").replace("+00:00", "Z")


def jsonable(obj, fallback=None):
    """``obj`` with numpy values turned into plain Python and non-finite floats into None,
    so that it is valid JSON (zarr attributes, run.json). Any other type is a ``TypeError``,
    or, with ``fallback`` (e.g. ``str``), ``fallback(value)``."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v, fallback) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v, fallback) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist(), fallback)
    if isinstance(obj, np.generic):
        return jsonable(obj.item(), fallback)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, (str, int, float, bool)) or obj is None:
        return obj
    if isinstance(obj, Path):
        return str(obj)
    if fallback is not None:
        return fallback(obj)
    raise TypeError(f"not JSON-serialisable: {type(obj).__name__} {obj!r:.80}")


def read_object(path) -> dict:
    """The JSON object in the file ``path``; ``{}`` if it is missing, unreadable, not JSON or
    not an object (a summary or score a killed process never finished)."""
    try:
        doc = json.loads(Path(path).read_text())
        return doc if isinstance(doc, dict) else {}
    except (OSError, ValueError):
        return {}
