"""Simulated time shared by every simulated device.

Only one thread, the *driver* (the thread that created the clock, or the last one to
call :meth:`SimClock.claim`), advances time: its ``sleep`` steps the world. ``sleep``
from any other thread (e.g. a recorder's acquisition loop) waits until the driver has
moved time past the target, or at most ``max_wait_s`` of wall time, so pollers neither
change the data (determinism) nor hang when the driver stops. With ``realtime`` the
driver's stepping is paced to the wall clock.
"""

from __future__ import annotations

import threading
import time

from .world import SimWorld


class SimClock:
    def __init__(self, world: SimWorld, realtime: bool = False, max_wait_s: float = 0.05):
        self.world = world
        self.realtime = realtime
        self.max_wait_s = max_wait_s
        self._driver = threading.get_ident()
        self._wall0: float | None = None

    def claim(self) -> None:
        """Make the calling thread the one that advances time."""
        self._driver = threading.get_ident()

    @property
    def is_driver(self) -> bool:
        return threading.get_ident() == self._driver

    def now(self) -> float:
        """Simulated time (s)."""
        return self.world.time

    def sleep(self, dt: float) -> None:
        """Wait ``dt`` s of simulated time."""
        if dt > 0:
            self.sleep_until(self.now() + dt)

    def sleep_until(self, t: float, stop_when=None) -> bool:
        """Wait until simulated time ``t``; False if ``stop_when()`` ended the wait early."""
        if self.is_driver:
            return self.world.advance_to(t, stop_when=stop_when, pace=self._pace if self.realtime else None)
        w = self.world
        if stop_when is None:
            w.wait_until_tick(w.tick_at(t), self.max_wait_s)
        else:                                      # look at stop_when after every frame
            deadline = time.monotonic() + self.max_wait_s
            while w.tick < w.tick_at(t) and not stop_when() and time.monotonic() < deadline:
                w.wait_until_tick(None, deadline - time.monotonic())
        return w.time >= t - 1e-12

    def _pace(self, t: float) -> None:
        now = time.monotonic()
        if self._wall0 is None:
            self._wall0 = now - t
        ahead = self._wall0 + t - now
        if ahead > 0:
            time.sleep(ahead)
