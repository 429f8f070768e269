"""Importers: bring recordings from elsewhere (ROS bags, CSV files) into the project's run store.

    from protocols.importers import ImportSettings, import_source
    results = import_source("lab/session.bag", "imported", ImportSettings(baseline="estimate"))
    results[0].store       # imported/session/run.zarr, ready for tactile-analyze

Modules: :mod:`.recording` (the format-neutral :class:`Recording`, unconnected-finger
detection), :mod:`.bag` and :mod:`.csv` (readers), :mod:`.baseline` (calibration files and
import-wide estimates), :mod:`.sources` (what a path holds, checksums), :mod:`.writer`
(run store + run.json, staging and atomic rename), :mod:`.importer` (the whole import),
:mod:`.cli` (``tactile-import``). See ``docs/import.md``.
"""

from .baseline import Baseline, estimate_baseline, load_calibration
from .bag import read_bag
from .csv import read_csv
from .importer import ImportResult, ImportSettings, import_source
from .recording import ImportInputError, Recording, select_fingers, unconnected_fingers

__all__ = ["Baseline", "ImportInputError", "ImportResult", "ImportSettings", "Recording", "estimate_baseline",
           "import_source", "load_calibration", "read_bag", "read_csv", "select_fingers", "unconnected_fingers"]
