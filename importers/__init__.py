"""Importers: bring recordings from elsewhere (ROS bags, CSV files) into the project's run store.

    from importers import ImportSettings, import_source
    results = import_source("lab/session.bag", "imported", ImportSettings(baseline="estimate"))
    results[0].store       # imported/session/run.zarr, ready for tactile-analyze

Files are streamed: read twice in chunks of :data:`.recording.CHUNK_FRAMES` frames (a
checking pass, a writing pass), so memory does not grow with their length.

Modules: :mod:`.recording` (the format-neutral :class:`Recording` chunk, unconnected-finger
detection, exact medians of long data), :mod:`.bag` (on :mod:`.ros1`, a ROS1 record reader) and :mod:`.csv` (chunk readers
:class:`BagFile`, :class:`CsvFile`; truncated bags, garbage rows), :mod:`.baseline`
(calibration files and import-wide estimates), :mod:`.sources` (what a path holds,
checksums), :mod:`.writer` (run store + run.json, streamed; staging and atomic rename),
:mod:`.importer` (the whole import), :mod:`.cli` (``tactile-import``). See ``docs/import.md``.
"""

from .baseline import Baseline, estimate_baseline, load_calibration
from .bag import BagFile, read_bag
from .csv import CsvFile, read_csv
from .importer import ImportResult, ImportSettings, import_source
from .recording import ImportInputError, Recording, select_fingers, unconnected_fingers

__all__ = ["BagFile", "Baseline", "CsvFile", "ImportInputError", "ImportResult", "ImportSettings", "Recording",
           "estimate_baseline", "import_source", "load_calibration", "read_bag", "read_csv", "select_fingers",
           "unconnected_fingers"]
