"""Tactile flow: dense optical flow between tactile frames.

Two forms (both (T, H, W, 2) float32 arrays of (Δcol, Δrow) per pixel, pixels):

- *dynamic* flow, frame t−1 → t (the method's tactile flow while sliding), in pixels/frame;
  ``flow[0]`` is zero (there is no earlier frame);
- *static* flow, a reference frame → frame t: how far the pressure pattern has drifted
  while the contact itself stays put (the static-friction phase of a pour), in pixels.

Methods: Farnebäck (the method's choice), DIS and Dual TV-L1 (opencv-contrib). Farnebäck on
frames too small for a pyramid level (the analysis's) runs in :mod:`tactile.farneback`, equal
to OpenCV's to the bit and with each frame's expansion shared between its pairs; else OpenCV.
:func:`to_mm_per_s` and :func:`to_mm` convert to physical units on the view plane.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from . import farneback

__all__ = ["DIS_PRESETS", "METHODS", "FlowConfig", "FlowEstimator", "contact_reference", "dynamic_flow",
           "loaded_reference", "static_flow", "to_mm", "to_mm_per_s"]

METHODS = ("farneback", "dis", "tvl1")
DIS_PRESETS = {"ultrafast": 0, "fast": 1, "medium": 2}
"""OpenCV's DIS presets by name (``cv2.DISOPTICAL_FLOW_PRESET_*``); speed and accuracy of each
on the simulated protocols in ``docs/performance.md``."""


@dataclass(frozen=True)
class FlowConfig:
    """Dense flow method and its parameters (names as OpenCV's).

    ``farneback``: pyr_scale, levels, winsize, iterations, poly_n, poly_sigma, flags.
    ``dis``: ``dis_preset`` (``ultrafast``, ``fast`` or ``medium``; OpenCV's 0, 1, 2 also
    accepted), plus optional overrides in ``dis``.
    ``tvl1``: keyword arguments of ``cv2.optflow.DualTVL1OpticalFlow_create``.
    """

    method: str = "farneback"
    pyr_scale: float = 0.5
    levels: int = 3
    winsize: int = 15
    iterations: int = 3
    poly_n: int = 5
    poly_sigma: float = 1.2
    flags: int = 0
    dis_preset: str | int = "medium"
    dis: dict = field(default_factory=dict)
    tvl1: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"flow.method: expected one of {', '.join(METHODS)}, got {self.method!r}")
        if self.dis_preset not in DIS_PRESETS and self.dis_preset not in DIS_PRESETS.values():
            raise ValueError(f"flow.dis_preset: expected one of {', '.join(DIS_PRESETS)}, got {self.dis_preset!r}")
        if not 0 < self.pyr_scale < 1:
            raise ValueError(f"flow.pyr_scale: expected a value in (0, 1), got {self.pyr_scale!r}")
        for name in ("levels", "winsize", "iterations", "poly_n"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"flow.{name}: expected an integer ≥ 1, got {getattr(self, name)!r}")


class FlowEstimator:
    """Computes the dense flow between two 8-bit frames with one configured method.

    OpenCV's DIS and TV-L1 objects are created once and reused (they are costly to build).
    """

    def __init__(self, config: FlowConfig = FlowConfig()):
        import cv2
        self.config = config
        self._algo = None
        self._farneback = cv2.calcOpticalFlowFarneback
        if config.method == "dis":
            self._algo = cv2.DISOpticalFlow_create(DIS_PRESETS.get(config.dis_preset, config.dis_preset))
            for key, value in config.dis.items():
                getattr(self._algo, "set" + key[0].upper() + key[1:])(value)
        elif config.method == "tvl1":
            self._algo = cv2.optflow.DualTVL1OpticalFlow_create(**config.tvl1)

    def __call__(self, prev: np.ndarray, nxt: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Flow (H, W, 2) float32 in pixels that carries ``prev`` (H, W uint8) onto ``nxt``;
        written into ``out`` (a C-contiguous (H, W, 2) float32 array) if given."""
        return self.pair(prev, nxt, out, inked=bool(prev.any() or nxt.any()))

    def pair(self, prev: np.ndarray, nxt: np.ndarray, out: np.ndarray | None, *, inked: bool) -> np.ndarray:
        """As calling the estimator, told whether either frame has a nonzero pixel (``inked``):
        a sequence's callers test every frame at once, not each pair."""
        c = self.config
        if self._algo is not None:                       # a given flow would be their initial one
            flow = self._algo.calc(prev, nxt, None)
        elif inked:
            return self._farneback(prev, nxt, out, c.pyr_scale, c.levels, c.winsize,
                                   c.iterations, c.poly_n, c.poly_sigma, c.flags)
        else:
            # Farnebäck between two empty frames is exactly zero (tested); the stretches
            # before and after a press are mostly empty frames
            flow = np.zeros(prev.shape + (2,), np.float32)
        if out is None:
            return flow
        out[...] = flow
        return out


def _inked(frames: np.ndarray) -> np.ndarray:
    """(T,) bool: which of ``frames`` (T, H, W) have a nonzero pixel (one pass over all)."""
    return frames.reshape(len(frames), -1).any(axis=1)


def _check_frames(frames) -> np.ndarray:
    frames = np.asarray(frames)
    if frames.ndim != 3 or frames.dtype != np.uint8:
        raise ValueError(f"frames: expected a (T, H, W) uint8 array (see frames.to_uint8), "
                         f"got shape {frames.shape} dtype {frames.dtype}")
    if len(frames) == 0:
        raise ValueError("frames: expected at least one frame, got 0")
    return frames


def dynamic_flow(frames, *, config: FlowConfig = FlowConfig()) -> np.ndarray:
    """Flow between consecutive frames: (T, H, W) uint8 → (T, H, W, 2) px/frame, flow[0] = 0.

    >>> import numpy as np
    >>> frames = np.zeros((2, 32, 32), np.uint8); frames[0, 12:20, 10:18] = frames[1, 12:20, 11:19] = 200
    >>> f = dynamic_flow(frames)
    >>> f.shape, bool(f[1, 14:18, 12:16, 0].mean() > 0.3)            # the square moved right
    ((2, 32, 32, 2), True)
    """
    frames = _check_frames(frames)
    out = np.zeros(frames.shape + (2,), np.float32)
    if farneback.supports(frames.shape, config):         # each frame expanded once, not twice
        expanded = farneback.expand(frames, config)
        later = np.arange(1, len(frames))
        farneback.pair_flows(expanded, expanded, np.c_[later - 1, later], config, out=out[1:])
        return out
    estimate = FlowEstimator(config)
    inked = _inked(frames)
    for t in range(1, len(frames)):
        estimate.pair(frames[t - 1], frames[t], out[t], inked=bool(inked[t - 1] or inked[t]))
    return out


def static_flow(frames, reference, *, config: FlowConfig = FlowConfig()) -> np.ndarray:
    """Flow from a reference frame to every frame: → (T, H, W, 2) px.

    ``reference``: an index into ``frames`` or an (H, W) uint8 frame (e.g. the unloaded one).
    """
    frames = _check_frames(frames)
    if np.ndim(reference) == 0:
        index = int(reference)
        if not -len(frames) <= index < len(frames):
            raise ValueError(f"reference: expected a frame index in [0, {len(frames)}), got {reference!r}")
        ref = frames[index]
    else:
        ref = np.asarray(reference)
        if ref.shape != frames.shape[1:] or ref.dtype != np.uint8:
            raise ValueError(f"reference: expected an index or a {frames.shape[1:]} uint8 frame, "
                             f"got shape {ref.shape} dtype {ref.dtype}")
    out = np.empty(frames.shape + (2,), np.float32)
    if farneback.supports(frames.shape, config):         # the reference expanded once
        pairs = np.c_[np.zeros(len(frames), np.int64), np.arange(len(frames))]
        return farneback.pair_flows(farneback.expand(ref, config), farneback.expand(frames, config), pairs,
                                    config, out=out)
    estimate = FlowEstimator(config)
    ref_inked = bool(ref.any())
    for frame, frame_inked, flow_field in zip(frames, _inked(frames), out):
        estimate.pair(ref, frame, flow_field, inked=ref_inked or bool(frame_inked))
    return out


def contact_reference(total_activation, threshold: float, settle: int = 10) -> int:
    """Index of the frame at which the contact became established.

    The first sample from which ``total_activation`` (T,) stays above ``threshold`` for
    ``settle`` consecutive samples; ``ValueError`` if the contact never settles.
    """
    total = np.asarray(total_activation, dtype=np.float64)
    if total.ndim != 1:
        raise ValueError(f"total_activation: expected a 1-D series, got shape {total.shape}")
    settle = int(settle)
    if settle < 1:
        raise ValueError(f"settle: expected an integer ≥ 1, got {settle}")
    above = total > threshold
    if len(above) >= settle:
        run = np.convolve(above.astype(np.int64), np.ones(settle, np.int64), "valid")
        hits = np.flatnonzero(run == settle)
        if hits.size:
            return int(hits[0])
    raise ValueError(f"total_activation: never stays above threshold={threshold} for {settle} "
                     f"samples; no contact to take as the static-flow reference")


def loaded_reference(load, start: int, fraction: float = 0.8) -> int:
    """First index ≥ ``start`` at which ``load`` (T,) reaches ``fraction`` of its median over
    [start, T): the frame where a contact, once settled, has also finished loading. A
    static flow from an earlier frame would mostly see the pattern grow as the finger
    presses in, not where it moves.

    >>> loaded_reference(np.r_[0, 1, 2, 4, 8, 9, 10, 10, 10, 10], start=1)
    4
    """
    x = np.asarray(load, dtype=np.float64)
    if not 0 <= start < len(x):
        raise ValueError(f"start: expected an index in [0, {len(x)}), got {start}")
    level = fraction * float(np.median(x[start:]))
    hits = np.flatnonzero(x[start:] >= level)
    return start + int(hits[0]) if hits.size else start


def to_mm_per_s(flow_px, *, mm_per_px: float, rate_hz: float) -> np.ndarray:
    """Dynamic flow px/frame → mm/s on the view plane.

    >>> float(to_mm_per_s(0.5, mm_per_px=0.74, rate_hz=100.0))
    37.0
    """
    return np.asarray(flow_px) * np.float32(mm_per_px * rate_hz)


def to_mm(flow_px, *, mm_per_px: float) -> np.ndarray:
    """Static flow px → mm on the view plane."""
    return np.asarray(flow_px) * np.float32(mm_per_px)
