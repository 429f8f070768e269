"""Who owns Ctrl-C (SIGINT) and SIGTERM during a run: the run, from its start to the last byte written.

A signal that lands in the wrong place leaves damage: a half-made store, a half-written
``truth`` group, a store left ``running`` without ``run.json``. :class:`Interrupts` is
installed for the whole job and decides by the phase the run is in:

==============  =====================================================================
``setup``       planning, building the model, connecting the lab — nothing written
                yet: the signal raises ``KeyboardInterrupt`` (the run never starts)
``writing``     files being written (the store created or closed, ``run.json``, an
                earlier attempt set aside): noted only, the write finishes; a run whose
                engine has not started yet then stops before the first step (``aborted``)
``motion``      the engine runs the plan: the first signal asks for a safe stop (finish
                the motion, retract), the second raises ``KeyboardInterrupt`` in the
                engine (stop at once); later ones are noted only
``analysis``    the hand-off to the analysis: raises ``KeyboardInterrupt``; the analysis
                writes nothing partial (its staging is removed), the recording is complete
==============  =====================================================================

SIGTERM counts as Ctrl-C. Handlers can only be installed on the main thread; elsewhere
(tests driving a run from a thread) :meth:`Interrupts.installed` does nothing.

A signal handler runs wherever the main thread is, and Python drops an exception raised in
a finaliser (a weakref callback, ``__del__``) after printing "Exception ignored" and a
traceback. So :meth:`Interrupts.install` also hooks :data:`sys.unraisablehook`: a dropped
``KeyboardInterrupt`` of the ``motion`` phase is noted silently as :attr:`Interrupts.deferred`
and the engine raises it at its next tick (:meth:`Interrupts.raise_deferred`), one poll
period late; in the other phases the signal is delivered again
(:func:`cliapp.runner.redeliver_dropped_interrupt`).
"""

from __future__ import annotations

import signal
import sys
import threading
from contextlib import contextmanager

from tactile_flow.cliapp.runner import note_signal, redeliver_dropped_interrupt

SIGNALS = (signal.SIGINT, signal.SIGTERM)
RAISING = ("setup", "analysis")
PHASES = ("setup", "writing", "motion", "analysis")


class Interrupts:
    """The signal state of one job (see the module docstring).

    Attributes:
        count: signals received so far (SIGINT and SIGTERM).
        motion_signals: signals received in the current ``motion`` phase.
        phase: one of :data:`PHASES`.
    """

    def __init__(self, log=print):
        self.log = log
        self.count = 0
        self.phase = "setup"
        self._on_stop = None                # the engine's safe-stop request, in the motion phase
        self.motion_signals = 0
        self.deferred = False               # a raised KeyboardInterrupt that a finaliser dropped
        self._unraisable_before = None

    def install(self) -> dict:
        """Handle SIGINT and SIGTERM with :meth:`handle` from now on, and catch the
        interrupts a finaliser drops (main thread only: else nothing); returns the previous
        handlers."""
        if threading.current_thread() is not threading.main_thread():
            return {}
        if sys.unraisablehook != self._unraisable:
            self._unraisable_before = sys.unraisablehook
            sys.unraisablehook = self._unraisable
        return {s: signal.signal(s, self.handle) for s in SIGNALS}

    @contextmanager
    def installed(self):
        """:meth:`install` for the ``with`` block, then the previous handlers again."""
        old = self.install()
        try:
            yield self
        finally:
            for s, handler in old.items():
                signal.signal(s, handler)
            if old and sys.unraisablehook == self._unraisable:
                sys.unraisablehook = self._unraisable_before

    def raise_deferred(self) -> None:
        """Raise the ``KeyboardInterrupt`` a finaliser dropped, if any (once)."""
        if self.deferred:
            self.deferred = False
            raise KeyboardInterrupt

    def _unraisable(self, unraisable) -> None:
        if issubclass(unraisable.exc_type, KeyboardInterrupt) and self.phase == "motion":
            self.deferred = True            # the second Ctrl-C: the engine raises it at its next tick
        elif not redeliver_dropped_interrupt(unraisable):
            (self._unraisable_before or sys.__unraisablehook__)(unraisable)

    @contextmanager
    def during(self, phase: str, on_stop=None):
        """Be in ``phase`` for the ``with`` block (``on_stop``: the safe-stop request of the
        ``motion`` phase), then go back to the previous phase."""
        if phase not in PHASES:
            raise ValueError(f"phase {phase!r}: expected one of {PHASES}")
        before, self.phase, self._on_stop = self.phase, phase, on_stop
        self.motion_signals = 0
        try:
            yield self
        finally:
            self.phase, self._on_stop = before, None

    def handle(self, signum=signal.SIGINT, frame=None) -> None:
        """The signal handler (also callable directly, as a test of the phase logic)."""
        self.count += 1
        note_signal()
        name = "SIGTERM" if signum == signal.SIGTERM else "Ctrl-C"
        if self.phase == "motion":
            self.motion_signals += 1
            if self.motion_signals == 1:
                if self._on_stop is not None:
                    self._on_stop()
                self._say(f"\n{name}: stopping safely: finishing the current motion, retracting "
                          f"(Ctrl-C again to stop at once)")
                return
            if self.motion_signals == 2:
                raise KeyboardInterrupt
            return
        if self.phase in RAISING:
            raise KeyboardInterrupt
        if self.count == 1:
            self._say(f"\n{name}: stopping once the files being written are complete")

    def _say(self, message: str) -> None:
        try:
            self.log(message)
        except RuntimeError:             # the signal cut a print to the same stream: say nothing
            pass
