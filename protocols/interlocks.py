"""Safety interlocks watched continuously while a protocol runs.

Every engine period (one BioTac frame, 10 ms at 100 Hz) :meth:`Interlocks.check` reads the
newest sensor frame and the arm's state and raises :class:`InterlockTripped` when a limit
is breached; the engine then stops the motion, retracts along the approach direction and
closes the run as ``aborted`` with the interlock named (``interlock`` event).

Limits (``safety`` in the run config, :class:`SafetyConfig`):

- BioTac saturation: PDC above ``pdc_max`` counts, or any electrode below
  ``electrode_min`` counts (electrode counts fall under pressure and bottom out);
- TCP force above ``force_max`` N, TCP speed above ``speed_max`` m/s (as the controller
  reports it), the TCP outside the workspace envelope;
- contact held longer than ``contact_time_max`` s (PDC more than ``contact_threshold``
  counts above its tare on any finger);
- a stale stream: no new BioTac frame for ``stale_periods`` frame periods — no motion
  continues blind; named ``malformed_biotac`` when frames kept arriving but the driver
  refused them (:mod:`hardware.wire`), with how many and the last reason;
- a lost link, of any device: each device's own verdict (:meth:`hardware.device.Device.check_link`:
  a closed socket or port, a killed bridge, a stream silent beyond its stale timeout) is asked
  every period, first, so the safe stop begins one period after the driver knows (the
  benchmark ``benchmarks/bench_link_loss.py`` measures it on the emulated lab); the run then
  fails with the device's error.
- recording failed: the run store could not be committed for ``recording_stall_s`` of wall
  time (full disk...) — no motion continues unrecorded.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile_flow.hardware.errors import DeviceError
from tactile_flow.validation import spec


@dataclass
class SafetyConfig:
    """Interlock limits. ``None`` takes the hardware's own limit (``hardware.arm.*``). Every
    limit is a finite number within its bounds (:func:`validation.spec`): a NaN limit would
    never trip, a negative one would trip at once."""

    pdc_max: float = spec(3900.0, gt=0, units="counts")
    electrode_min: float = spec(100.0, ge=0, lt=4095, units="counts")
    force_max: float | None = spec(None, gt=0, units="N")
    speed_max: float | None = spec(None, gt=0, units="m/s")
    contact_time_max: float = spec(180.0, gt=0, units="s")
    contact_threshold: float = spec(30.0, gt=0, units="counts of PDC above the tare")
    stale_periods: int = spec(30, ge=1, units="BioTac frame periods")   # host stalls of ~0.2 s seen under load
    recording_stall_s: float = spec(2.0, gt=0, units="s of wall time without a successful commit")
    max_duration_s: float = spec(7200.0, gt=0, units="s")   # the longest a protocol may be planned to run (the plan)
    on_protective_stop: str = spec("abort", choices=("abort", "recover"))   # "abort": fail the run; "recover": unlock, redo the step once


class LinkLost(Exception):
    """A device's link is down (the driver's typed error is ``__cause__``); ``device`` names it."""

    def __init__(self, device: str, error: Exception):
        self.device = device
        super().__init__(str(error))


class InterlockTripped(Exception):
    """A safety limit was breached; ``name`` says which, ``detail`` the values."""

    def __init__(self, name: str, detail: dict):
        self.name, self.detail = name, detail
        super().__init__(f"interlock {name}: " + ", ".join(f"{k}={v}" for k, v in detail.items()))


class Interlocks:
    """Checks one lab against :class:`SafetyConfig` limits, keeping what it needs between
    checks (contact start times, the newest frame seen)."""

    def __init__(self, cfg: SafetyConfig, limits, fingers: list[str], rate_hz: float, clock):
        self.cfg, self.limits, self.fingers, self.clock = cfg, limits, fingers, clock
        self.force_max = limits.max_force if cfg.force_max is None else cfg.force_max
        self.speed_max = limits.max_speed if cfg.speed_max is None else cfg.speed_max
        self.stale_s = cfg.stale_periods / rate_hz
        self.tare_pdc = np.zeros(len(fingers))
        self._contact_since = np.full(len(fingers), np.nan)
        self._last_seq = None
        self._last_new_frame = clock.now()
        self._refused_before = 0                 # frames the BioTac driver had refused at the last new frame

    def check(self, lab, recorder) -> None:
        """Raise :class:`LinkLost` if a device's link is down, :class:`InterlockTripped` if any
        limit is breached now."""
        for name, device in lab.devices.items():
            try:
                device.check_link()
            except DeviceError as exc:
                raise LinkLost(name, exc) from exc
        now = self.clock.now()
        self._check_biotac(lab.biotac, now)
        self._check_arm(lab.arm)
        failure = recorder.write_failure(self.cfg.recording_stall_s)
        if failure:
            raise InterlockTripped("recording_failed", {"error": failure})

    def _check_biotac(self, biotac, now: float) -> None:
        frame = biotac.latest()
        if frame is None or frame.seq == self._last_seq:
            if now - self._last_new_frame > self.stale_s:
                refused = biotac.malformed - self._refused_before
                if refused:                          # frames arrive, but none the driver could accept
                    report = biotac.wire_report() or {}
                    raise InterlockTripped("malformed_biotac", {"refused_frames": refused,
                                                                "no_valid_frame_for_s": round(now - self._last_new_frame, 3),
                                                                "limit_s": self.stale_s, "last": report.get("last")})
                raise InterlockTripped("stale_biotac", {"no_frame_for_s": round(now - self._last_new_frame, 3),
                                                        "limit_s": self.stale_s})
            return
        self._last_seq, self._last_new_frame = frame.seq, now
        self._refused_before = biotac.malformed
        if not frame.is_valid():
            return                                   # corrupt frames are counted by the recorder
        cfg = self.cfg
        pdc = frame.pdc.astype(float)
        if pdc.max() > cfg.pdc_max:
            i = int(np.argmax(pdc))
            raise InterlockTripped("pdc_saturation", {"finger": self.fingers[i], "pdc": int(pdc[i]),
                                                      "limit": cfg.pdc_max})
        low = frame.electrodes.min(axis=1)
        if low.min() < cfg.electrode_min:
            i = int(np.argmin(low))
            raise InterlockTripped("electrode_saturation", {"finger": self.fingers[i], "counts": int(low[i]),
                                                            "limit": cfg.electrode_min})
        # contact start times (s, clock), NaN while a finger does not touch
        since = self._contact_since
        touching = pdc - self.tare_pdc > cfg.contact_threshold
        since[~touching] = np.nan
        since[touching & np.isnan(since)] = now
        held = now - since                            # s; NaN where not touching, never above the limit
        if (held > cfg.contact_time_max).any():
            i = int(np.nanargmax(held))
            raise InterlockTripped("contact_time", {"finger": self.fingers[i], "held_s": round(float(held[i]), 2),
                                                    "limit_s": cfg.contact_time_max})

    def _check_arm(self, arm) -> None:
        pose = np.asarray(arm.tcp_pose(), float)
        force = float(np.linalg.norm(np.asarray(arm.tcp_wrench(), float)[:3]))
        if force > self.force_max:
            raise InterlockTripped("tcp_force", {"force_n": round(force, 2), "limit_n": self.force_max})
        lo, hi = self.limits.workspace_min, self.limits.workspace_max
        if np.any(pose[:3] < lo) or np.any(pose[:3] > hi):
            raise InterlockTripped("workspace", {"position_m": np.round(pose[:3], 4).tolist()})
        speed = float(np.linalg.norm(np.asarray(arm.tcp_speed(), float)[:3]))
        if speed > self.speed_max * 1.05:            # 5 %: the controller's own overshoot
            raise InterlockTripped("tcp_speed", {"speed_m_s": round(speed, 4), "limit_m_s": self.speed_max})
