"""How a run ended (:class:`RunStatus`, the store's ``status`` attribute and ``run.json``'s) and
the exit status of every command (:class:`ExitCode`), in one place.

>>> RunStatus("aborted").exit_code
<ExitCode.INTERRUPTED: 3>
>>> RunStatus.SUCCESS == "success"
True
"""

from __future__ import annotations

from enum import IntEnum, StrEnum


class ExitCode(IntEnum):
    """Exit status of ``tactile-run``, ``tactile-analyze``, ``tactile-import``, ``tactile-recover``."""

    OK = 0
    FAILED = 1              # the work could not be done (a device failed, a full disk)
    BAD_INPUT = 2           # a config, protocol, file or wire datum was refused: one line says which
    INTERRUPTED = 3         # Ctrl-C / SIGTERM: the run stopped safely


class RunStatus(StrEnum):
    """The state of a run: ``running`` while it records, then one of the others. A string, so
    it compares equal to (and is stored as) its value."""

    RUNNING = "running"
    SUCCESS = "success"
    ABORTED = "aborted"     # stopped by the operator or an interlock, the robot left safe
    FAILED = "failed"       # a step, a device or the recording failed
    CRASHED = "crashed"     # the process died; closed afterwards by tactile-recover
    PLANNED = "planned"     # plan_only: checked, nothing ran (never a store's status)

    @property
    def exit_code(self) -> ExitCode:
        return _EXIT[self]


_EXIT = {RunStatus.RUNNING: ExitCode.FAILED, RunStatus.SUCCESS: ExitCode.OK, RunStatus.ABORTED: ExitCode.INTERRUPTED,
         RunStatus.FAILED: ExitCode.FAILED, RunStatus.CRASHED: ExitCode.FAILED, RunStatus.PLANNED: ExitCode.OK}

#: the statuses a run store may carry
STORE_STATUSES = tuple(s.value for s in RunStatus if s is not RunStatus.PLANNED)
