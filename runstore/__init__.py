"""The run store: one zarr v3 ``run.zarr`` per run, written by the recorder and the importers
and read by the analysis, so writer and reader share one layout and cannot drift apart.

=====================  ===========================================================
module                 holds
=====================  ===========================================================
:mod:`.layout`         the layout (blocks, variables, dims, dtypes, units), the schema
                       version, the time-coordinate names
:mod:`.writer`         :class:`RunStore`: create, append, commit (the commit protocol)
:mod:`.appender`       the growing arrays' chunks and ``zarr.json`` files, written directly
:mod:`.reader`         :func:`open_run` (xarray), :func:`open_group` (zarr) and the
                       schema-version check: the one opener of every store, either layout
:mod:`.packed`         the packed layout of a finished store: one zip (``run.zarr.zip``)
:mod:`.inmemory`       a run store made in memory and written packed at once (an import)
:mod:`.packedread`     a short packed store read whole without zarr (the analysis's loader)
:mod:`.labelled`       labelled arrays written as xarray writes them, without xarray
                       (``analysis.zarr``)
:mod:`.recover`        ``tactile-recover``: close a store its writer never closed
:mod:`.clockmodel`     device clock → host clock (lower-envelope fit)
:mod:`.provenance`     what ran, from which code, on which machine; ``run.json``
:mod:`.status`         :class:`RunStatus` and the commands' :class:`ExitCode`
:mod:`.jsonvalues`     JSON-clean attribute values, the UTC time stamp
:mod:`.rundir`         one run directory, one writer (a lock); a finished run refused
:mod:`.paths`          paths made from input kept inside their root
:mod:`.files`          the one way a run directory's files are written (no links)
:mod:`.analyses`       every analysis kept in ``analyses/<name>``, one current
:mod:`.checksum`       a store's checksum: every array's values
:mod:`.runinfo`        a run's record as one flat row
:mod:`.catalogue`      the run catalogue (SQLite, WAL) behind ``tactile-runs``
:mod:`.reproduce`      ``tactile-runs reproduce``
:mod:`.runs_cli`       ``tactile-runs list|show|diff|reproduce|index``
=====================  ===========================================================
"""

from .jsonvalues import jsonable, utc_now
from .reader import StoreVersionError, check_version, open_group, open_run, store_url
from .status import ExitCode, RunStatus
from .layout import SCHEMA_VERSION, STATUSES, TIME_COORDS, Block, Var, run_schema
from .writer import RunStore, remove_debris

__all__ = ["RunStore", "open_run", "open_group", "store_url", "check_version", "StoreVersionError", "run_schema", "Block", "Var",
           "SCHEMA_VERSION", "STATUSES", "RunStatus", "ExitCode", "TIME_COORDS", "jsonable", "utc_now", "remove_debris"]
