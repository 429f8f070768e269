"""Slip detection on the online tactile-flow aggregates, one frame at a time.

A held object that starts to slip shows in three ways on a fingertip, and
:class:`SlipDetector` watches for each (per finger, only while the finger has been in
steady contact for ``settle_s``):

``release``
    the stick-slip release when the object first gives: the skin's stored stretch and part
    of the normal load are let go *at once*, so the total activation (the sum of the 24
    filtered taxel activations, a PDC proxy) falls over ``release_frames`` frames by more
    than its drift before them explains (the trend, an EMA of the per-frame relative change
    with ``trend_tau_s``, as it was before the window: :func:`release_fall`), by more than
    ``release_drop`` of its value *and* by more than ``release_noise`` times that same
    n-frame fall's own usual size on this finger (an EMA, ``noise_tau_s``, of its absolute
    value, as it was before the window, like the trend: a give spread over its first frames
    must not raise its own reference; :func:`release_ratio`. The filtered activation's noise
    is correlated from frame to frame, so it is measured over the window, not scaled from one
    frame: a light contact is noisier, relatively, than a firm one, and its give is judged
    against its own noise),
    while the footprint moves in one of those frames, in some view: at least
    ``release_confidence`` of it above the flow's noise level (the flow confidence), *or*
    its mean flow at least ``release_motion`` times the finger's own usual mean-flow
    magnitude (an EMA with ``noise_tau_s``, taken before the frame). The second form is
    relative to the finger's own flow, so it does not depend on how strongly the skin's
    stretch shows in the electrodes: with a weak shear response (a real BioTac SP shows
    about a quarter of the simulator's default; ``docs/simulator.md``) a release moves
    every pixel by less than the analysis's absolute noise level (0.05 px/frame) and the
    confidence stays 0, while the mean flow still jumps 3-5× above its own level. The trend
    term is what keeps a finger that is sliding off a feature, or being lifted, from firing:
    its pressure falls too, but steadily.
``creep``
    persistent sliding: the mean flow vector, smoothed with ``creep_tau_s``, exceeds
    ``creep_px`` px/frame and keeps its direction (persistence, |EMA of the vector| / EMA
    of its length, at least ``creep_persistence``; 1 is a constant direction), in any view.
``rotation``
    the object turning in the grasp: the mean curl, smoothed with ``creep_tau_s``, exceeds
    ``curl_min`` (1/frame) in magnitude in any view.

``creep`` and ``rotation`` are flow the robot's own motion also makes (a finger swept on
purpose across a surface slides and creeps): they only count while the robot is still
(the ``still`` argument of :meth:`SlipDetector.update`). ``release`` only waits while the
hand itself moves by command (``hand_still``: opening the grasp lets the load go by command);
the arm's motion does not gate it.

A finger whose stream pauses for more than ``max_gap_s`` (skipped, corrupt or missing
frames) starts again from scratch: it must settle in contact anew before it can fire, so a
finger coming back from a dropout never looks like a sudden change.

The thresholds are chosen from simulated pours and sweeps (``benchmarks/bench_slip.py``
reports the detection latency and the false alarms they give); every one is configurable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["SlipConfig", "SlipDetector", "SlipState", "release_fall", "release_motion", "release_ratio"]

CAUSES = ("", "release", "creep", "rotation")
"""Codes of :attr:`SlipState.cause`: 0 none, 1 release, 2 creep, 3 rotation."""


@dataclass
class SlipConfig:
    """Thresholds of :class:`SlipDetector` (see the module docstring). Units in brackets.
    (Not frozen: it is also the schema of the ``live.slip`` config node, which Hydra
    overrides key by key.)"""

    contact_kohm: float = 0.5          # total activation that begins a contact, Σ |activation| that keeps it [kΩ]
    settle_s: float = 0.5              # contact held this long before a slip can be declared [s]
    release_drop: float = 0.1          # smallest fall over release_frames beyond the trend [1]
    release_frames: int = 4            # frames over which the fall is measured [1]
    release_confidence: float = 0.2    # fraction of the footprint moving in one of them [1]
    release_noise: float = 7.0         # ... and that many times that fall's own noise [1]
    release_motion: float = 2.5        # ... or mean flow this many times its own usual level [1]
    trend_tau_s: float = 0.1           # time constant of the pressure trend [s]
    noise_tau_s: float = 1.0           # time constant of the noise estimate [s]
    creep_px: float = 0.01             # smoothed mean-flow magnitude [px/frame]
    creep_persistence: float = 0.7     # direction persistence of the smoothed flow [1]
    creep_tau_s: float = 0.1           # time constant of the flow and curl smoothing [s]
    curl_min: float = 0.001            # smoothed |curl| [1/frame]
    max_gap_s: float = 0.05            # longer pauses of a finger's stream reset it [s]

    def __post_init__(self):
        for name, value in self.__dict__.items():
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"slip.{name}: expected a number > 0, got {value!r}")
        if self.release_frames != int(self.release_frames):
            raise ValueError(f"slip.release_frames: expected a whole number of frames, got {self.release_frames}")
        if not self.creep_persistence <= 1:
            raise ValueError(f"slip.creep_persistence: expected a value in (0, 1], got {self.creep_persistence}")


@dataclass
class SlipState:
    """The detector's verdict after a frame. Arrays are per finger (F,).

    Attributes:
        t: time of the frame [s].
        fired: the finger detected slip in this frame.
        cause: code into :data:`CAUSES` of what fired (0 if nothing).
        in_contact: the finger is in settled contact (the detector is armed for it).
        ratios: (F, 3) each criterion's statistic over its threshold in this frame (release,
            creep, rotation; ≥ 1 fires when armed, creep and rotation only while still): how
            close a finger came.
        first: ``(t, finger index, cause code)`` of the first detection since the last
            :meth:`SlipDetector.rearm`, or ``None``.
    """

    t: float
    fired: np.ndarray
    cause: np.ndarray
    in_contact: np.ndarray
    ratios: np.ndarray
    first: tuple[float, int, int] | None = None

    @property
    def detected(self) -> bool:
        return self.first is not None


def release_motion(magnitude, level, factor: float) -> float:
    """How far the mean flow stands out of its own usual level, over the threshold.

    Args:
        magnitude: (V,) this frame's mean-flow magnitude per view [px/frame].
        level: (V,) the finger's usual magnitude before this frame (an EMA) [px/frame];
            NaN where there is none yet.
        factor: ``release_motion``, the multiple of the level that counts as moving [1].

    Returns:
        max over views of magnitude / (factor × level); ≥ 1: the footprint moves. 0 where
        there is no level yet (a finger's first frame) or the level is 0 (nothing to be
        relative to: a noiseless, still stream never moves by this criterion).
    """
    ok = np.isfinite(level) & (level > 0)
    if not ok.any():
        return 0.0
    return float((magnitude[ok] / (factor * level[ok])).max())


def release_fall(before: float, total: float, trend_before: float, frames: int, contact_kohm: float) -> float:
    """The total activation's fall over ``frames`` frames beyond the trend it had before them.

    Args:
        before: the total activation ``frames`` frames ago [kΩ] (NaN: not yet seen).
        total: this frame's [kΩ].
        trend_before: the per-frame relative fall's trend (an EMA) as it was before the
            window [1/frame]; a rising trend (negative) counts as 0.
        frames: n, the window [frames].
        contact_kohm: the floor of the reference (a fall is relative to at least this) [kΩ].

    Returns:
        (before − total) / max(before, contact_kohm) − n × max(trend_before, 0) [1]: how much
        more than its drift the contact let go in the window; NaN before the window is full.
    """
    if not math.isfinite(before):
        return math.nan
    return (before - total) / max(before, contact_kohm) - frames * max(trend_before, 0.0)


def release_ratio(excess: float, noise: float, drop: float, factor: float) -> float:
    """The release statistic over its threshold: ≥ 1 fires.

    Args:
        excess: :func:`release_fall` of this frame [1].
        noise: the same quantity's own usual size before the window (an EMA of its absolute
            value, ``noise_tau_s``, as it was ``release_frames`` frames ago) [1].
        drop: ``release_drop``, the smallest relative fall that counts [1].
        factor: ``release_noise``, the multiple of the noise that counts [1].

    Returns:
        excess / max(drop, factor × noise). The noise is that of the n-frame fall itself,
        measured on the finger's own signal, not the one-frame noise scaled by √n: the filtered
        activation's noise is correlated from frame to frame, so its n-frame falls are not
        √n times its one-frame ones.
    """
    return excess / max(drop, factor * noise)


class SlipDetector:
    """Per-finger slip detector over a stream of online flow aggregates.

    Args:
        n_fingers: F, the fingers of the stream (axis 0 of every input).
        config: the thresholds.
        watch: (F,) bool, the fingers to watch (default all); the others never fire.
    """

    def __init__(self, n_fingers: int, config: SlipConfig = SlipConfig(), watch=None):
        self.config = config
        F = int(n_fingers)
        self.watch = np.ones(F, bool) if watch is None else np.asarray(watch, bool).copy()
        if self.watch.shape != (F,):
            raise ValueError(f"watch: expected ({F},) booleans, got shape {self.watch.shape}")
        self._last_t = np.full(F, -np.inf)
        self._prev_total = np.full(F, np.nan)
        self._trend = np.zeros(F)
        n = int(config.release_frames)
        self._ring_total = np.full((F, n), np.nan)  # the last n totals [kΩ] (slot k: the frame n ago, once full)
        self._ring_trend = np.zeros((F, n))         # the trend taken before each of them [1/frame]
        self._ring_noise = np.zeros((F, n))         # the n-frame fall's noise taken before each of them [1]
        self._noise_n = np.zeros(F)                 # EMA of |n-frame fall beyond the trend|: its own noise [1]
        self._samples = np.zeros(F, np.int64)       # n-frame falls seen (starts the noise EMA as a mean)
        self._moved = np.zeros((F, n))              # how much it moved in those frames (≥ 1: moving)
        self._level = None                        # (F, V) EMA of the mean flow's magnitude (NaN: none yet)
        self._slot = np.zeros(F, np.int64)
        self._contact_since = np.full(F, np.nan)
        self._flow = None                         # (F, V, 2) EMA of the mean flow vector
        self._length = None                       # (F, V) EMA of its length
        self._curl = None                         # (F, V) EMA of the curl
        self.state = SlipState(-np.inf, np.zeros(F, bool), np.zeros(F, np.int8), np.zeros(F, bool), np.zeros((F, 3)))

    def rearm(self) -> None:
        """Forget the first detection (the per-finger state is kept)."""
        self.state.first = None

    def reset(self, finger: int) -> None:
        """Start finger ``finger`` from scratch (as after a pause in its stream)."""
        self._prev_total[finger] = np.nan
        self._trend[finger] = 0.0
        self._ring_total[finger] = np.nan
        self._ring_trend[finger] = 0.0
        self._ring_noise[finger] = 0.0
        self._noise_n[finger] = 0.0
        self._samples[finger] = 0
        self._moved[finger] = 0.0
        self._contact_since[finger] = np.nan
        if self._flow is not None:
            self._level[finger] = np.nan
            self._flow[finger] = 0.0
            self._length[finger] = 0.0
            self._curl[finger] = 0.0

    def update(self, t: float, processed, total, mean, curl, confidence, still: bool = True,
               contact=None, hand_still: bool = True) -> SlipState:
        """Take one frame's aggregates; return the (reused) :class:`SlipState`.

        Args:
            t: frame time [s].
            processed: (F,) bool, the fingers with a valid sample in this frame; the others
                are left as they were (their values are ignored).
            total: (F,) total filtered activation [kΩ].
            mean: (F, V, 2) mean flow (col, row) per view [px/frame].
            curl: (F, V) mean curl per view [1/frame].
            confidence: (F, V) fraction of the footprint moving per view [1].
            still: the robot is not moving the fingers (arms ``creep`` and ``rotation``).
            contact: (F,) what keeps a contact [kΩ]:
                :attr:`tactile.online.OnlineStep.activation_contact` (Σ |activation|), which
                the shear does not cancel; a contact begins when ``total`` reaches
                ``contact_kohm`` and, while ``still``, lasts while ``contact`` stays at or
                above it (while the robot moves, while ``total`` does). Default ``total``
                (recordings without it).
            hand_still: the hand is not moving by command. While it moves (opening or closing
                the grasp) the fingertips' load changes by command: a fall then is the robot's
                own release, and ``release`` does not fire (the arm's motion does not gate it).
        """
        c = self.config
        contact = total if contact is None else contact
        mean = np.asarray(mean, float)
        if self._flow is None:
            self._flow = np.zeros(mean.shape)
            self._length = np.zeros(mean.shape[:2])
            self._curl = np.zeros(mean.shape[:2])
            self._level = np.full(mean.shape[:2], np.nan)
        s = self.state
        s.t = float(t)
        s.fired[:] = False
        s.cause[:] = 0
        ok = np.asarray(processed, bool) & np.isfinite(total) & np.isfinite(contact)
        ok &= np.isfinite(mean).all(axis=(1, 2)) & np.isfinite(curl).all(axis=1) & np.isfinite(confidence).all(axis=1)
        for f in np.flatnonzero(ok):
            gap = t - self._last_t[f]
            if not gap > 0:                                      # out of order: ignore
                continue
            if gap > c.max_gap_s:
                self.reset(f)
            self._last_t[f] = t
            cause = self._finger(f, t, gap, float(total[f]), float(contact[f]), mean[f], curl[f], confidence[f],
                                 still, hand_still)
            s.in_contact[f] = t - self._contact_since[f] >= c.settle_s
            if cause and self.watch[f]:
                s.fired[f] = True
                s.cause[f] = cause
                if s.first is None:
                    s.first = (s.t, int(f), cause)
        return s

    def _finger(self, f, t, dt, total, contact, mean, curl, confidence, still, hand_still=True) -> int:
        c = self.config
        prev = self._prev_total[f]
        self._prev_total[f] = total
        a_trend = 1.0 - math.exp(-dt / c.trend_tau_s)
        a_flow = 1.0 - math.exp(-dt / c.creep_tau_s)
        self._flow[f] += a_flow * (mean - self._flow[f])
        self._length[f] += a_flow * (np.hypot(mean[:, 0], mean[:, 1]) - self._length[f])
        self._curl[f] += a_flow * (curl - self._curl[f])
        a_noise = 1.0 - math.exp(-dt / c.noise_tau_s)
        magnitude = np.hypot(mean[:, 0], mean[:, 1])
        level = self._level[f]
        motion = release_motion(magnitude, level, c.release_motion)   # against the level before this frame
        self._level[f] = np.where(np.isnan(level), magnitude, level + a_noise * (magnitude - level))
        settled = t - self._contact_since[f] >= c.settle_s            # NaN (no contact) compares False
        # contact begins with a press (the signed total: the real sensors' resting Σ |activation|
        # reaches 1.2 kΩ without a touch) and, while the robot is still, lasts while Σ |activation|
        # stays (a growing shear cancels the signed sum of a finger that still holds); while the
        # robot moves (the hand opening its grasp) it ends with the signed total, as it began
        holding = not math.isnan(self._contact_since[f])
        if (contact if holding and still else total) < c.contact_kohm:
            self._contact_since[f] = np.nan
        elif math.isnan(self._contact_since[f]):
            self._contact_since[f] = t
        ratios = self.state.ratios[f]
        ratios[:] = 0.0
        if math.isnan(prev):
            return 0
        drop = (prev - total) / max(prev, c.contact_kohm)           # relative fall this frame
        trend = self._trend[f]
        self._trend[f] += a_trend * (drop - trend)
        k = self._slot[f] = (self._slot[f] + 1) % self._ring_total.shape[1]
        before, trend_before = self._ring_total[f, k], self._ring_trend[f, k]   # n frames ago
        noise = self._ring_noise[f, k]                              # the noise as it was then
        self._ring_total[f, k], self._ring_trend[f, k] = total, trend
        self._ring_noise[f, k] = self._noise_n[f]
        self._moved[f, k] = max(confidence.max() / c.release_confidence, motion)
        excess = release_fall(before, total, trend_before, self._ring_total.shape[1], c.contact_kohm)
        if math.isfinite(excess):
            self._samples[f] += 1
            self._noise_n[f] += max(a_noise, 1.0 / self._samples[f]) * (abs(excess) - self._noise_n[f])
        # each criterion's statistic over its threshold: ≥ 1 fires (see the module docstring)
        if self._moved[f].max() >= 1.0 and math.isfinite(excess) and self._samples[f] > self._ring_total.shape[1] + 1:
            ratios[0] = release_ratio(excess, noise, c.release_drop, c.release_noise)
        speed = np.hypot(self._flow[f, :, 0], self._flow[f, :, 1])
        persistent = speed >= c.creep_persistence * np.maximum(self._length[f], 1e-12)
        if persistent.any():
            ratios[1] = speed[persistent].max() / c.creep_px
        ratios[2] = np.abs(self._curl[f]).max() / c.curl_min
        if not settled:
            return 0
        for cause in (1, 2, 3) if still else (1,) if hand_still else ():
            if ratios[cause - 1] >= 1.0:
                return cause
        return 0
