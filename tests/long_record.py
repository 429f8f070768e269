"""A long five-finger record made from the real resting bag, for the long-record tests and
``benchmarks/bench_long_analysis.py``.

The real resting bag ``tests/data/biotac_rest_untouched.bag`` (100 Hz; its two unconnected
fingers get a connected finger's data, so five fingers rest) is tiled end to end to the length
asked for, with a 2 s press on one finger every ``press_every_s`` (the fingers in turn): the
electrodes move by up to ~300 counts in a spatial bump that travels across the taxels, PDC rises
by ~200 counts. It is written through the importer's own streaming writer
(:func:`importers.writer.write_import_store`, one chunk in memory), so the store is what
``tactile-import`` would write for such a bag.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

BAG = Path(__file__).resolve().parent / "data" / "biotac_rest_untouched.bag"
RATE_HZ = 100.0
PRESS_S = 2.0


def five_fingers(rec):
    """The bag with its unconnected fingers (all-zero electrodes) given a connected finger's data,
    so that all five fingers carry a real resting signal."""
    live = [i for i in range(len(rec.fingers)) if rec.electrodes[:, i].any()]
    src = [i if i in live else live[i % len(live)] for i in range(len(rec.fingers))]
    pick = (lambda a: None if a is None else a[:, src])
    return replace(rec, electrodes=pick(rec.electrodes), pdc=pick(rec.pdc), tdc=pick(rec.tdc), tac=pick(rec.tac))


class TiledReader:
    """The resting bag tiled to ``frames`` frames with presses (the importer's Reader protocol)."""

    def __init__(self, frames: int, press_every_s: float):
        from tactile_flow.importers.bag import BagFile, read_bag
        rest = read_bag(BAG)
        self.path, self.meta, self.finger_names = BAG, dict(BagFile(BAG).meta), rest.fingers
        self.rest = five_fingers(replace(rest, pac=None))      # PAC is not what the analysis reads
        self.frames, self.press_every_s = frames, press_every_s

    def chunks(self, frames: int = 5000):
        r, n_rest = self.rest, self.rest.n_frames
        for start in range(0, self.frames, frames):
            i = np.arange(start, min(start + frames, self.frames))
            k = i % n_rest
            t = i / RATE_HZ
            el = r.electrodes[k].astype(np.int64)
            pdc = r.pdc[k].astype(np.int64) if r.pdc is not None else None
            self._press(t, el, pdc)
            yield replace(r, seq=i.astype(np.int64), device_time=t, host_time=t + 1e-3,
                          electrodes=el, pdc=pdc,
                          tdc=None if r.tdc is None else r.tdc[k], tac=None if r.tac is None else r.tac[k])

    def _press(self, t: np.ndarray, el: np.ndarray, pdc: np.ndarray | None) -> None:
        """Add the presses in place: press j starts at (j + 0.5) · press_every_s on finger j mod F."""
        j = np.floor(t / self.press_every_s - 0.5).astype(int)
        phase = t - (j + 0.5) * self.press_every_s       # s into press j
        on = (j >= 0) & (phase >= 0) & (phase < PRESS_S)
        if not on.any():
            return
        w = np.sin(np.pi * phase[on] / PRESS_S) ** 2          # 0 → 1 → 0 over the press
        centre = 24 * phase[on] / PRESS_S                     # the bump travels over the taxels
        bump = np.exp(-0.5 * ((np.arange(24)[None, :] - centre[:, None]) / 3.0) ** 2)
        f = j[on] % el.shape[1]
        rows = np.flatnonzero(on)
        el[rows, f, :] -= np.rint(300 * w[:, None] * bump).astype(np.int64)
        if pdc is not None:
            pdc[rows, f] += np.rint(200 * w).astype(np.int64)

    def finish(self, rate_hz: float) -> None:
        pass


def make_store(run_dir: Path, hours: float, press_every_s: float) -> Path:
    """Write ``run_dir/run.zarr`` holding ``hours`` h of tiled record; its path."""
    from tactile_flow.importers.importer import scan
    from tactile_flow.importers.recording import PreparedSource
    from tactile_flow.importers.writer import write_import_store
    reader = TiledReader(int(round(hours * 3600 * RATE_HZ)), press_every_s)
    found = scan(reader)
    prepared = PreparedSource(reader, found, found.fingers, {"kept": list(found.fingers)})
    run_dir.mkdir(parents=True)
    write_import_store(prepared, run_dir / "run.zarr", {"source": str(BAG), "importer": "bench_long_analysis"},
                       {"source": str(BAG), "fingers": list(found.fingers)})
    return run_dir / "run.zarr"
