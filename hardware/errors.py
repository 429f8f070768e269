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

import math

#: the range of every configured sample or poll rate (Hz): far beyond any device of the lab
#: on both sides, short of a rate that makes a run crawl or a buffer unbounded
RATE_RANGE_HZ = (0.1, 10_000.0)
#: the range of every buffer length (s of data a device keeps unread)
BUFFER_RANGE_S = (0.1, 3600.0)


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


# one error and one message format for every config node (the validation layer)
from tactile_flow.validation import ConfigError, brief  # noqa: E402,F401


def require_positive(cfg, names, key: str) -> None:
    """Raise :class:`ConfigError` naming ``<key>.<name>`` unless each attribute ``names`` of
    the config dataclass ``cfg`` is a finite number > 0."""
    for name in names:
        value = getattr(cfg, name)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
            raise ConfigError(f"{key}.{name}", f"expected a number > 0, got {brief(value)}")


def require_within(cfg, names, bounds: tuple[float, float], units: str, key: str) -> None:
    """Raise :class:`ConfigError` naming ``<key>.<name>`` unless each attribute ``names`` of
    ``cfg`` is a number within ``bounds`` (inclusive), in ``units``."""
    lo, hi = bounds
    for name in names:
        value = getattr(cfg, name)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
            raise ConfigError(f"{key}.{name}", f"expected a number of {units} in [{lo:g}, {hi:g}], got {brief(value)}")
