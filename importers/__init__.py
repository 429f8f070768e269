"""Importers: bring recordings from elsewhere (ROS bags, CSV files) into the project's run store.

    from tactile_flow.importers import ImportSettings, import_source
    results = import_source("lab/session.bag", "imported", ImportSettings(baseline="estimate"))
    results[0].store       # imported/session/run.zarr.zip, ready for tactile-analyze

Files are streamed: read twice in chunks of :data:`.recording.CHUNK_FRAMES` frames (a
checking pass, a writing pass), so memory does not grow with their length.

Modules: :mod:`.recording` (the format-neutral :class:`Recording` chunk, unconnected-finger
detection, exact medians of long data), :mod:`.bag` (on :mod:`.ros1`, a ROS1 record reader) and :mod:`.csv` (chunk readers
:class:`BagFile`, :class:`CsvFile`; truncated bags, garbage rows), :mod:`.baseline`
(calibration files and import-wide estimates), :mod:`.sources` (what a path holds,
checksums), :mod:`.writer` (run store + run.json, streamed; staging and atomic rename),
:mod:`.importer` (the whole import), :mod:`.cli` (``tactile-import``). See ``docs/import.md``.
"""

from __future__ import annotations

import importlib

_HOMES = {"Baseline": "baseline", "estimate_baseline": "baseline", "load_calibration": "baseline",
          "BagFile": "bag", "read_bag": "bag", "CsvFile": "csv", "read_csv": "csv",
          "ImportResult": "importer", "ImportSettings": "importer", "import_source": "importer",
          "ImportInputError": "recording", "Recording": "recording", "select_fingers": "recording",
          "unconnected_fingers": "recording"}
__all__ = sorted(_HOMES)


def __getattr__(name: str):
    """The names above, imported on first use (numpy, numba and zarr come with them), so that
    the ``tactile-import`` entry (:mod:`.entry`) can take Ctrl-C before they load."""
    if name not in _HOMES:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f".{_HOMES[name]}", __name__), name)
    globals()[name] = value
    return value
