"""Typed errors raised by every hardware device, simulated or real.

Catch :class:`DeviceError` for "anything went wrong with a device"; the subclasses say
what, so a run engine can decide between retrying, recovering and aborting:

- :class:`NotConnectedError`: a call before ``connect()`` or after ``close()``.
  :class:`DeviceDisconnectedError` (a subclass): the link was lost while connected.
- :class:`DeviceTimeoutError`: the device did not answer within its deadline.
- :class:`DeviceFaultError`: the device reports a fault. :class:`ProtectiveStopError`
  and :class:`EmergencyStopError` are the arm's safety stops.
- :class:`SafetyError`: a command refused before it was sent because it would break a
  limit; :class:`WorkspaceError` (also a ``ValueError``) for a pose outside the workspace.
- :class:`ConfigError` (a ``ValueError``): bad configuration, naming the config key.
"""

from __future__ import annotations


class DeviceError(Exception):
    """Base class of every device error."""


class NotConnectedError(DeviceError):
    """The device is not connected (``connect()`` not called, or ``close()`` called)."""


class DeviceDisconnectedError(NotConnectedError):
    """The link to the device was lost while it was connected."""


class DeviceTimeoutError(DeviceError):
    """The device did not answer in time."""


class DeviceFaultError(DeviceError):
    """The device reports a fault."""


class ProtectiveStopError(DeviceFaultError):
    """The arm is in a protective stop; motion commands are refused until ``recover()``."""


class EmergencyStopError(DeviceFaultError):
    """The arm's emergency stop is engaged."""


class SafetyError(DeviceError):
    """A command was refused because it would break a safety limit."""


class WorkspaceError(SafetyError, ValueError):
    """A commanded pose lies outside the configured workspace box."""


class ConfigError(ValueError):
    """Invalid configuration. ``key`` is the dotted config key at fault."""

    def __init__(self, key: str, message: str):
        self.key = key
        super().__init__(f"{key}: {message}")


def require_positive(cfg, names, key: str) -> None:
    """Raise :class:`ConfigError` naming ``<key>.<name>`` unless each attribute ``names`` of
    the config dataclass ``cfg`` is a finite number > 0."""
    import math
    for name in names:
        value = getattr(cfg, name)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise ConfigError(f"{key}.{name}", f"expected a number > 0, got {value!r}")
