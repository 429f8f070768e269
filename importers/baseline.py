"""Unloaded baselines for recordings that begin in contact.

A record that starts with the finger already pressed has no rest stretch to take its zero
from. The importer then stores a baseline from elsewhere (per finger, 24 electrode counts):

- ``calibration_file``: a stored per-sensor calibration, JSON — either one
  :meth:`tactile.signals.SensorCalibration.to_dict` (``sensor_id``, ``source``,
  ``baseline_counts[24]``; only for a one-finger import) or ``{finger: that dict, ...}``;
- ``estimated``: across every file of one import, a high percentile (default 95) of each
  electrode's samples in the first ``early_s`` (default 1 s) of each file, pooled. Pressing
  the skin raises the impedance over an electrode and its count *falls*, so the upper end
  of the early samples is the least-loaded reading the import has. The import keeps only
  those early frames of each file (:class:`EarlyWindow`, at most
  :data:`.recording.CHUNK_FRAMES` frames), never the whole file.

Pure functions; :class:`Baseline` is what the writer stores (``biotac/baseline`` and the
root attributes ``baseline`` and ``calibration``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tactile_flow.hardware.biotac import FINGERS
from tactile_flow.tactile.signals import SensorCalibration

from .recording import CHUNK_FRAMES, ImportInputError, Recording, concat, head_of

@dataclass(frozen=True)
class Baseline:
    """An unloaded baseline per finger.

    Attributes:
        method: ``calibration_file`` or ``estimated``.
        calibrations: ``{finger: SensorCalibration}`` (24 counts each).
        source: one sentence saying where the numbers come from.
        details: method parameters (file and its SHA-256, or percentile, early_s, files), JSON-ready.
    """

    method: str
    calibrations: dict
    source: str
    details: dict = field(default_factory=dict)

    def counts(self, fingers, where: str = "import") -> np.ndarray:
        """(F, 24) baseline counts in the order of ``fingers``; raises :class:`ImportInputError`
        naming any finger the baseline does not cover."""
        missing = [f for f in fingers if f not in self.calibrations]
        if missing:
            raise ImportInputError(f"{where}: the {self.method.replace('_', ' ')} baseline has no finger "
                                   f"{', '.join(missing)} (it has {', '.join(self.calibrations) or 'none'})")
        return np.stack([np.asarray(self.calibrations[f].baseline_counts, float) for f in fingers])

    def to_attrs(self, fingers) -> dict:
        """Root attribute ``baseline`` (method, source, details, fingers) — JSON-ready."""
        return {"method": self.method, "source": self.source, "details": self.details, "fingers": list(fingers)}

    def calibration_attrs(self, fingers) -> dict:
        """Root attribute ``calibration``: ``{finger: SensorCalibration.to_dict()}`` for ``fingers``."""
        return {f: self.calibrations[f].to_dict() for f in fingers}


def load_calibration(path, fingers, sha256: str | None = None) -> Baseline:
    """Read a calibration JSON file (see module docstring) for an import of ``fingers``.

    Raises :class:`ImportInputError` when the file is missing, not JSON, not in either form,
    holds one sensor for a multi-finger import, or lacks a finger of the import.
    """
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ImportInputError(f"calibration={path}: no such file") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ImportInputError(f"calibration={path}: not a JSON file ({type(exc).__name__}: {exc})") from None
    fingers = list(fingers)
    try:
        if isinstance(doc, dict) and "baseline_counts" in doc:
            if len(fingers) != 1:
                raise ImportInputError(f"calibration={path}: holds one sensor ({doc.get('sensor_id')!r}) but the "
                                       f"import has fingers {', '.join(fingers)}; give {{finger: calibration}}")
            cals = {fingers[0]: SensorCalibration.from_dict(doc)}
        elif isinstance(doc, dict) and doc and set(doc) <= set(FINGERS):
            cals = {f: SensorCalibration.from_dict(d) for f, d in doc.items()}
        else:
            raise ImportInputError(f"calibration={path}: expected a SensorCalibration dict (sensor_id, source, "
                                   f"baseline_counts[24]) or {{finger: that dict}} with fingers of "
                                   f"{', '.join(FINGERS)}")
    except ImportInputError:
        raise
    except ValueError as exc:
        raise ImportInputError(f"calibration={path}: {exc}") from None
    missing = [f for f in fingers if f not in cals]
    if missing:
        raise ImportInputError(f"calibration={path}: no entry for finger {', '.join(missing)} "
                               f"(it has {', '.join(cals)})")
    return Baseline("calibration_file", cals, f"calibration file {path.name}",
                    {"file": str(path.resolve()), "sha256": sha256, "fingers_in_file": sorted(cals)})


def early_frames(rec: Recording, early_s: float) -> slice:
    """Rows of ``rec`` within ``early_s`` s of its first frame (device time); at least one."""
    t = rec.device_time
    n = int(np.searchsorted(t, t[0] + early_s, side="left")) if len(t) else 0
    return slice(0, max(1, n))


class EarlyWindow:
    """The early frames of a file, collected chunk by chunk with bounded memory.

    The frames before the first one stamped ``early_s`` s or more after the first frame
    (device time) — for increasing times exactly what :func:`early_frames` selects — at least
    one and at most ``max_frames`` (:attr:`capped` when that cut the window short). :meth:`add`
    each chunk in order; :attr:`done` once the window is complete; :meth:`recording` is the
    window (every finger of the chunks; ``meta["early_window_capped_at_frames"]`` if capped).
    """

    def __init__(self, early_s: float, max_frames: int = CHUNK_FRAMES):
        self.early_s = early_s
        self.max_frames = max_frames
        self.parts: list[Recording] = []
        self.frames = 0
        self.done = False
        self.capped = False
        self._limit: float | None = None

    def add(self, chunk: Recording) -> None:
        """Keep the part of ``chunk`` (the next frames of the file) inside the window."""
        if self.done or not chunk.n_frames:
            return
        t = chunk.device_time
        if self._limit is None:
            self._limit = float(t[0]) + self.early_s
        beyond = np.flatnonzero(t >= self._limit)
        n = int(beyond[0]) if beyond.size else chunk.n_frames
        if not self.frames:
            n = max(1, n)
        n = min(n, self.max_frames - self.frames)
        if n:
            self.parts.append(head_of(chunk, n))
            self.frames += n
        self.capped = not beyond.size and self.frames >= self.max_frames
        self.done = bool(beyond.size) or self.capped

    def recording(self) -> Recording:
        """The window as one :class:`Recording` (needs at least one frame added)."""
        rec = concat(self.parts)
        if self.capped:
            rec.meta["early_window_capped_at_frames"] = self.max_frames
        return rec


def estimate_baseline(recordings, early_s: float = 1.0, percentile: float = 95.0,
                      names=None) -> Baseline:
    """Per finger and taxel, the ``percentile`` of the electrode counts in the first ``early_s``
    s of every recording that has the finger, pooled.

    Args:
        recordings: the :class:`Recording` s of one import, or their early windows
            (:class:`EarlyWindow`); unconnected fingers already dropped.
        early_s: s from each recording's start.
        percentile: 0..100; high, because counts fall under load.
        names: a label per recording (file names) for the record.
    Returns a :class:`Baseline` with ``method="estimated"``; its details name the files whose
    early window was cut at :data:`.recording.CHUNK_FRAMES` frames (``early_window_capped``).
    """
    if not 0 < percentile <= 100:
        raise ImportInputError(f"estimate.percentile={percentile}: expected in (0, 100]")
    if not early_s > 0:
        raise ImportInputError(f"estimate.early_s={early_s}: expected a positive number of s")
    recordings = list(recordings)
    names = list(names) if names is not None else [r.meta.get("path", f"#{i}") for i, r in enumerate(recordings)]
    pooled: dict[str, list[np.ndarray]] = {}
    frames: dict[str, int] = {}
    for rec in recordings:
        rows = early_frames(rec, early_s)
        for k, f in enumerate(rec.fingers):
            pooled.setdefault(f, []).append(rec.electrodes[rows, k, :])
            frames[f] = frames.get(f, 0) + len(rec.electrodes[rows])
    cals = {}
    for f in (f for f in FINGERS if f in pooled):
        counts = np.percentile(np.concatenate(pooled[f]).astype(float), percentile, axis=0)      # (24,)
        if np.any(counts < 1) or np.any(counts > 4095):
            raise ImportInputError(f"estimated baseline of {f} has counts outside 1..4095 "
                                   f"(min {counts.min():g}); the early samples are not a sensor at rest")
        cals[f] = SensorCalibration(counts, sensor_id=f"{f} (estimated)",
                                    source=f"p{percentile:g} of the first {early_s:g} s of {len(names)} file(s)")
    details = {"percentile": percentile, "early_s": early_s, "files": [str(n) for n in names],
               "frames_per_finger": frames}
    capped = {str(n): r.meta["early_window_capped_at_frames"] for n, r in zip(names, recordings)
              if r.meta.get("early_window_capped_at_frames")}
    if capped:
        details["early_window_capped"] = {"frames": capped, "why": "the early window holds at most this many "
                                                                  "frames per file (bounded memory)"}
    return Baseline("estimated", cals,
                    f"estimated: percentile {percentile:g} of each electrode over the first {early_s:g} s "
                    f"of {len(names)} file(s) of this import", details)
