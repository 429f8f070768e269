"""The ``rtde_control`` URScript program that ur_rtde uploads, emulated in Python: the register
handshake (the client writes a command id into ``input_int_register_0`` and its arguments into
the other input registers; the script answers 1 ready / 2 done in ``output_int_register_0``,
async progress in ``output_int_register_2``), one control period at a time.
"""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .ur_controller import URControllerEmulator

READY_FOR_CMD, DONE_WITH_CMD = 1, 2
#: commands the control script processes without waiting for the client to clear them
REALTIME_CMDS = {6, 9, 10, 11, 24, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71}


def log_line(cfg, *msg):
    if cfg.log:
        print("ur_controller:", *msg, file=sys.stderr, flush=True)


class ControlScript:
    """The semantics of ur_rtde's ``rtde_control`` URScript program, one control period at a time.

    Holds the registers it reads and writes; the controller calls :meth:`step` once per
    period while the program runs. A blocking command (sync ``moveL``, ``stopL``...) keeps
    the script busy until the motion ends, then it signals "done".
    """

    def __init__(self, ctrl: "URControllerEmulator", reg_offset: int = 0):
        self.ctrl, self.kin, self.off = ctrl, ctrl.kin, reg_offset
        self.executing = False
        self.busy_until = None              # predicate: the blocking command has finished
        self.async_kind = None              # "move" | "stop" while an async operation runs
        self.wr_count = 0
        self.op_id = 0
        self.keep_running = True
        self.speeding = None                # (velocity, accel) while the speed thread runs
        self._async_register(-1)
        self._ready()

    # -- registers -------------------------------------------------------------------
    def _in_int(self, i):
        return self.ctrl.in_int[i + self.off]

    def _in_double(self, i):
        return self.ctrl.in_double[i + self.off]

    def _pose(self, first=0):
        return np.array([self._in_double(first + k) for k in range(6)])

    def _out_int(self, i, v):
        self.ctrl.out_int[i + self.off] = int(v)

    def _ready(self):
        self._out_int(0, READY_FOR_CMD)

    def _done(self):
        self._out_int(0, DONE_WITH_CMD)

    def _async_register(self, value):
        """Progress word: change count bits 16-23, operation id bits 24-30, running bit 15."""
        self.wr_count = (self.wr_count + 1) % 128
        if value == 0:
            self.op_id = (self.op_id + 1) % 128
        reg = self.wr_count * 65536 + self.op_id * 16777216
        if value >= 0:
            reg += min(value, 32767) + 32768
        self._out_int(2, reg)

    def _async_started(self, kind):
        self.async_kind = kind
        self._async_register(0)

    def _async_finished(self):
        if self.async_kind is not None:
            self.async_kind = None
            self._async_register(-1)

    # -- one control period --------------------------------------------------------
    def step(self) -> None:
        if self.async_kind == "move" and self.kin.mode != "linear":
            self._async_finished()
        elif self.async_kind == "stop" and self.kin.mode == "idle":
            self._async_finished()
        if self.speeding is not None and self.kin.mode != "speed":
            self.kin.speed_linear(*self.speeding)        # the script's speed thread re-issues speedl
        if self.busy_until is not None:
            if not self.busy_until():
                return
            self.busy_until = None
            self._done()
            return
        cmd = self._in_int(0)
        if cmd in REALTIME_CMDS:
            self._process(cmd)
            self._ready()
        elif cmd == 0:
            self.executing = False
            self._ready()
        elif not self.executing:
            self.executing = True
            self._process(cmd)
            if cmd != 255 and self.busy_until is None:
                self._done()

    def _block_until_idle(self):
        self.busy_until = lambda: self.kin.mode == "idle"

    def _stop_async_move(self):
        if self.async_kind == "move":
            self._async_finished()

    def _process(self, cmd: int) -> None:
        kin, c = self.kin, self.ctrl
        if cmd in (2, 3):                                   # moveJ_IK, moveL (pose targets)
            pose, speed, accel, asynchronous = self._pose(0), self._in_double(6), self._in_double(7), self._in_int(1)
            self._stop_async_move()
            kin.move_linear(pose, speed, accel)
            if asynchronous == 1:
                self._async_started("move")
            else:
                self.busy_until = lambda: kin.mode != "linear"
        elif cmd == 6:                                      # forceMode
            selection = [self._in_int(2 + i) for i in range(6)]
            kin.force = (self._pose(0), selection, self._pose(6), self._pose(12))
        elif cmd == 7:                                      # forceModeStop: end_force_mode(); stopl(10)
            kin.force = None
            kin.stop(10.0)
            self._block_until_idle()
        elif cmd == 8:                                      # zeroFtSensor
            kin.zero_ft()
        elif cmd == 10:                                     # speedL (a thread repeating speedl)
            self.speeding = (self._pose(0), self._in_double(6))
            kin.speed_linear(*self.speeding)
        elif cmd == 24:                                     # servoL
            kin.servo(self._pose(0), self._in_double(9))
        elif cmd in (15, 16):                               # speedStop, servoStop
            self.speeding = None
            kin.stop(self._in_double(0))
            self._block_until_idle()
        elif cmd == 31:                                     # triggerProtectiveStop
            c.trigger_protective_stop("protective_stop() from the control script")
        elif cmd in (33, 34):                               # stopL, stopJ
            decel, asynchronous = self._in_double(0), self._in_int(1)
            if self.async_kind == "stop":
                self._async_finished()
            else:
                self._stop_async_move()
            kin.stop(decel)
            if asynchronous == 1:
                self._async_started("stop")
            else:
                self._block_until_idle()
        elif cmd == 47:                                     # isSteady
            steady = kin.mode == "idle" and not np.any(np.abs(kin.velocity) > 1e-6)
            self._out_int(1, 1 if steady else 0)
        elif cmd == 255:                                    # stopScript
            self.keep_running = False
        else:                                               # accepted, not emulated
            log_line(c.cfg, f"control script: command {cmd} not emulated (acknowledged)")
