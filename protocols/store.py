"""Kept for existing imports: the run store is the :mod:`runstore` package."""

from tactile_flow.runstore import RunStore, jsonable, open_run, remove_debris, run_schema, utc_now  # noqa: F401
from tactile_flow.runstore.layout import AXIS6, SCHEMA_VERSION, STATUSES, Block, Var  # noqa: F401
