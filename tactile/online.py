"""Online tactile flow: the method one BioTac frame at a time, for several fingers.

:class:`OnlineFlow` takes the stream as it arrives — one frame of raw electrode counts
(F, N) for all fingers every ~10 ms (N taxels of the sensor model) — and returns, for every finger and view, the
aggregates of the tactile flow between that finger's previous frame and this one
(:class:`OnlineStep`), in a bounded, preallocated state. Per finger and sample::

    counts → impedance → activation (− rest impedance) → one Kalman *filter* step
      → per view: the 8-bit tactile frame → dense flow from the previous frame
      → the aggregates of that flow field over the view's footprint

Online and offline
------------------
The offline pipeline (:mod:`tactile.pipeline`) smooths the activation with a Kalman
filter followed by a Rauch–Tung–Striebel smoother. The smoother runs backwards from the
end of the record: its estimate at time t uses every later sample, so it cannot run
online. The online form therefore applies the Kalman filter only (forward, causal); the
offline analysis keeps the smoother. Everything else is the same computation, so the
online results equal the offline pipeline run with the smoother off::

    model = TactileModel.build(replace(config, smooth=False))
    act = model.smooth(signals.counts_to_activation(counts, baseline))      # (T, F, N)
    process_view(model, act[:, f], view).dynamic                           # = online, finger f

frame by frame: the 8-bit frames bit for bit, the aggregates to float rounding
(tests/test_online.py). The filtered activation lags the smoothed one by a few samples
(the filter's time constant is ~1/sqrt(Q/R) ≈ 6 samples at the defaults), so online flow
is a little later and noisier than the offline analysis of the same record.

Missing and bad samples
-----------------------
A finger whose counts in a frame are not finite, outside 1..4095 or flagged invalid is
skipped for that frame: its filter, its previous frames and its renderer state stay at
its last good sample and continue from there, so its results equal the offline pipeline
run on its good samples only (the flow after a gap spans the gap). A frame whose
sequence number or time does not increase (a duplicate or a late frame), or whose time is
not finite, is skipped for every finger. Nothing about the data raises; :meth:`OnlineFlow.counters` counts it.

Cost
----
Everything is allocated in the constructor: per finger the filter state, per finger and
view two 8-bit frames, the renderer's walk cache and a flow field, per view the
renderer's work arrays. A push then calls compiled kernels on those buffers (numba for
the filter, interpolation, rendering and aggregation; OpenCV's Farnebäck writes into the
preallocated flow field; DIS and TV-L1 return a new field, copied in) and nothing
accumulates, however long the stream. Farnebäck dominates: see benchmarks/bench_online.py
for latency and throughput. An :class:`OnlineFlow` is one stream's state: not for
concurrent use from several threads.

With ``config.render = "linear"`` the frames may differ from the offline ones by one
8-bit level at rare pixels: offline renders :data:`tactile.frames.LINEAR_BLOCK` frames with
one float32 BLAS product, whose rounding depends on the number of frames in the product.
"""

# numba's on-disk cache is checked against this file's size and time and names the module it was
# compiled in: this file changed when the package moved under tactile_flow (0.2), so a cache from
# before the move is not loaded.

from __future__ import annotations

import math
import operator
from dataclasses import dataclass, fields
from typing import Sequence

import cv2
import numba
import numpy as np

from . import _frame_kernels, aggregate, farneback, flow, frames, signals
from ._checks import finite_array
from .pipeline import TactileModel

__all__ = ["OnlineFlow", "OnlineStep"]

AGGREGATES = ("mean_col", "mean_row", "magnitude", "direction", "divergence", "curl", "confidence")
"""The per finger × view fields of :class:`OnlineStep` (those of
:class:`tactile.aggregate.FlowAggregates` for one frame, the mean split into its two
components)."""

COUNTERS = ("processed", "skipped_invalid", "skipped_order", "gaps")


@dataclass(eq=False)
class OnlineStep:
    """The results of one :meth:`OnlineFlow.push`.

    The object and its arrays belong to the :class:`OnlineFlow` and are **overwritten by
    the next push**; keep a result with :meth:`copy`.

    Attributes:
        seq: the frame's sequence number.  t: its time, s (as pushed).
        processed: (F,) bool, whether each finger's sample was used.
        mean_col, mean_row: (F, V) mean flow over the view's footprint, px/frame (image
            columns, rows).
        magnitude: (F, V) |mean|, px/frame.  direction: (F, V) atan2(row, col), rad.
        divergence, curl: (F, V) mean over the footprint interior, 1/frame.
        confidence: (F, V) fraction of footprint pixels moving more than ``config.noise``.
        activation_total: (F,) sum of the N filtered activations, kΩ: the PDC proxy
            :func:`tactile.signals.pdc_proxy` of the filtered activation.
        activation_contact: (F,) sum of their absolute values, kΩ: how much the skin is
            touched, whatever the sign of each taxel's change. A shear stretch raises some
            taxels' impedance and lowers others', so under a growing load the signed sum
            can fall to zero or below while the finger still holds; this one cannot (it is
            never below |activation_total|): what the slip detector arms on.

    Flow is from the finger's previous *processed* frame ("px/frame" = per processed
    frame); a finger's first frame (after construction or :meth:`OnlineFlow.reset`) has
    zero flow, as :func:`tactile.flow.dynamic_flow`. Every value of a finger that was not
    processed is NaN. All arrays float64 except ``processed``.
    """

    seq: int
    t: float
    processed: np.ndarray
    mean_col: np.ndarray
    mean_row: np.ndarray
    magnitude: np.ndarray
    direction: np.ndarray
    divergence: np.ndarray
    curl: np.ndarray
    confidence: np.ndarray
    activation_total: np.ndarray
    activation_contact: np.ndarray

    def copy(self) -> "OnlineStep":
        """An independent copy (its arrays are not reused by later pushes)."""
        return OnlineStep(**{f.name: np.copy(getattr(self, f.name))
                             if isinstance(getattr(self, f.name), np.ndarray) else getattr(self, f.name)
                             for f in fields(self)})


@numba.njit(cache=True, nogil=True)
def _filter_step(counts, usable, baseline, r, q, x, p, n, counts_max, reference):  # pragma: no cover - compiled
    """One sample of every finger through counts → activation → Kalman filter, in place.

    ``counts`` (F, N) raw counts; ``usable`` (F,) bool: on entry the caller's validity
    flags, on return whether each finger's row was used (flagged valid and every count
    finite within 1..counts_max). ``baseline`` (F, N) rest impedance, kΩ; ``r``, ``q``:
    observation and process variances, kΩ². State, updated for used fingers only:
    ``x`` (F, N) filtered activation, kΩ; ``p`` (F,) its variance, kΩ²; ``n`` (F,) samples
    filtered so far (0: the next one is the first). ``counts_max``, ``reference``: the
    sensor's ADC full scale (counts) and reference resistor (kΩ).

    The arithmetic is that of :func:`tactile.signals.counts_to_impedance`,
    :func:`~tactile.signals.activation` and one step of the kernels behind
    :func:`~tactile.signals.kalman_filter` (``_gains_kernel``, ``_filter_kernel``) with
    their prior: x0 = the first sample, P0 = R, no prediction at the first sample.
    """
    for f in range(counts.shape[0]):
        ok = usable[f]
        for c in range(counts.shape[1]):
            e = counts[f, c]
            if not (e >= 1.0 and e <= counts_max):      # NaN fails too
                ok = False
        usable[f] = ok
        if not ok:
            continue
        first = n[f] == 0
        p_pred = r if first else p[f] + q
        k = p_pred / (p_pred + r)
        p[f] = p_pred - k * p_pred
        for c in range(counts.shape[1]):
            z = (counts_max / counts[f, c] - 1.0) * reference - baseline[f, c]
            prev = z if first else x[f, c]
            x[f, c] = prev + k * (z - prev)
        n[f] += 1


@numba.njit(cache=True, nogil=True)
def _results(sums, moving, n_mask, processed, mean_col, mean_row, magnitude, direction, divergence, curl,
             confidence, activation_total, activation_contact):  # pragma: no cover - compiled
    """The (F, V) aggregates from ``sums`` (F, V, 4) = (Σ u, Σ v, divergence, curl) and
    ``moving`` (F, V) footprint pixels above the noise, as :func:`tactile.aggregate.aggregate_flow`
    finishes them (``n_mask`` (V,): footprint pixels per view); NaN (and NaN
    ``activation_total``, ``activation_contact``) for fingers not ``processed``."""
    for f in range(sums.shape[0]):
        if not processed[f]:
            activation_total[f] = activation_contact[f] = np.nan
        for v in range(sums.shape[1]):
            if processed[f]:
                u, w = sums[f, v, 0], sums[f, v, 1]
                mean_col[f, v], mean_row[f, v] = u, w
                magnitude[f, v] = math.hypot(u, w)
                direction[f, v] = math.atan2(w, u)
                divergence[f, v], curl[f, v] = sums[f, v, 2], sums[f, v, 3]
                confidence[f, v] = np.float64(moving[f, v]) / n_mask[v]
            else:
                mean_col[f, v] = mean_row[f, v] = magnitude[f, v] = direction[f, v] = np.nan
                divergence[f, v] = curl[f, v] = confidence[f, v] = np.nan


class OnlineFlow:
    """The tactile-flow pipeline for a stream of BioTac frames, one frame per :meth:`push`.

    Args:
        model: the precomputed model (geometry, views, renderer, flow and noise settings
            from ``model.config``; ``config.smooth`` is ignored: online is filter-only, see
            the module docstring).
        baseline_impedance: (F, N) rest impedance per finger, kΩ (N: the model's taxels), as
            :func:`tactile.signals.activation` takes it (from
            :func:`~tactile.signals.baseline_from_rest` or stored calibrations).
        fingers: the F finger names, in the order of the rows of every pushed frame.
        views: names in ``model.plans`` (default: all of ``model.config.views``), V of them.

    Attributes:
        fingers, views: as given (tuples).

    :meth:`counters` says per finger how many samples were processed, skipped (invalid,
    out of order) and how many gaps the stream had.
    """

    def __init__(self, model: TactileModel, baseline_impedance, fingers: Sequence[str],
                 views: Sequence[str] | None = None):
        if isinstance(fingers, str):
            raise ValueError(f"fingers: expected a sequence of finger names, got the string {fingers!r}")
        self.fingers = tuple(fingers)
        if not self.fingers or len(set(self.fingers)) != len(self.fingers):
            raise ValueError(f"fingers: expected one or more distinct finger names, got {self.fingers}")
        self.views = tuple(model.config.views if views is None else views)
        unknown = [v for v in self.views if v not in model.plans]
        if not self.views or unknown or len(set(self.views)) != len(self.views):
            raise ValueError(f"views: expected distinct names from {sorted(model.plans)}, got {self.views}")
        n_f, n_v = len(self.fingers), len(self.views)
        baseline = finite_array("baseline_impedance", baseline_impedance, ndim=2)
        n_t = model.n_taxels
        if baseline.shape != (n_f, n_t):
            raise ValueError(f"baseline_impedance: expected shape ({n_f}, {n_t}) (fingers × "
                             f"taxels, kΩ), got {baseline.shape}")
        self.model = model
        e = model.sensor.electrodes if model.sensor is not None else None
        self._counts_max = float(signals.COUNTS_MAX if e is None else e.counts_max)
        self._reference = float(signals.REFERENCE_KOHM if e is None else e.reference_kohm)
        c = model.config
        self._baseline = np.ascontiguousarray(baseline)
        self._r, self._q = float(c.kalman_r), float(c.kalman_q)
        self._linear = c.render == "linear"
        self._farneback = c.flow.method == "farneback"
        fc = c.flow
        self._flow_params = (fc.pyr_scale, fc.levels, fc.winsize, fc.iterations, fc.poly_n,
                             fc.poly_sigma, fc.flags)
        low, gain = frames._u8_mapping(*c.intensity_range)

        # Per finger: the filter state and the counters.
        self._counts = np.empty((n_f, n_t))
        self._usable = np.empty(n_f, np.bool_)
        self._x = np.zeros((n_f, n_t))
        self._abs_x = np.zeros((n_f, n_t))            # scratch of |x| (activation_contact)
        self._x32 = np.zeros((n_f, 1, n_t), np.float32)             # linear renderer's input
        self._p = np.zeros(n_f)
        self._n = np.zeros(n_f, np.int64)
        self._finger_seq = [0] * n_f                                # seq of the last processed sample
        self._slot = np.zeros(n_f, np.int64)                        # which frame buffer is current
        self._counters = {name: np.zeros(n_f, np.int64) for name in COUNTERS}
        self._last_seq: int | None = None
        self._last_t: float | None = None

        # Per view: the renderer's constants and work arrays, the aggregation weights.
        self._per_view = []
        for name in self.views:
            plan = model.plans[name]
            render = (np.ascontiguousarray(model.weights[plan.vertices].T),          # (N, K)
                      *frames.frame_geometry(plan, model.mesh, c.scale))
            scratch = (np.empty(len(plan.vertices)), *frames.frame_scratch(plan))
            linear = (model.operators[name].T, np.empty((1, plan.mask.size), np.float32))
            self._per_view.append((render, scratch, linear, aggregate.aggregation_constants(plan.mask, c.noise)))
        self._n_mask = np.array([model.plans[name].mask.sum() for name in self.views], np.float64)

        # Per finger × view: two 8-bit frames, the walk cache, the flow field, result slots.
        self._sums = np.zeros((n_f, n_v, 4))                      # Σ u, Σ v, divergence, curl
        self._moving = np.zeros((n_f, n_v), np.float32)           # footprint pixels moving
        self._frames = [[np.zeros((2,) + model.plans[name].shape, np.uint8) for name in self.views]
                        for _ in range(n_f)]
        self._cache = [[frames.frame_cache(model.plans[name]) for name in self.views] for _ in range(n_f)]
        self._field = [[np.zeros(model.plans[name].shape + (2,), np.float32) for name in self.views]
                       for _ in range(n_f)]
        self._estimators = [[None if self._farneback else flow.FlowEstimator(c.flow) for _ in self.views]
                            for _ in range(n_f)]
        # Farnebäck on frames without a pyramid level: each frame expanded once, kept for the next
        self._streams = [[farneback.Stream(model.plans[name].shape, c.flow)
                          if self._farneback and farneback.supports(model.plans[name].shape, c.flow) else None
                          for name in self.views] for _ in range(n_f)]
        # Argument tuples of the hot path, built once (the arrays in them are updated in place).
        self._calls = [[self._view_calls(f, v, low, gain) for v in range(n_v)] for f in range(n_f)]

        nan_fv = lambda: np.full((n_f, n_v), np.nan)                           # noqa: E731
        self._step = OnlineStep(seq=0, t=math.nan, processed=np.zeros(n_f, np.bool_),
                                **{name: nan_fv() for name in AGGREGATES},
                                activation_total=np.full(n_f, np.nan), activation_contact=np.full(n_f, np.nan))

    def _view_calls(self, f, v, low, gain):
        """Finger f, view v: ``(slots, field, aggregate args)``; ``slots[s]`` = (render args,
        current frame, previous frame) when frame buffer s is the current one."""
        render, scratch, (op_t, linear_out), weights = self._per_view[v]
        both, field = self._frames[f][v], self._field[f][v]
        slots = []
        for s in (0, 1):
            if self._linear:
                args = (self._x32[f], op_t, linear_out, linear_out.reshape(both[s].shape), low, gain, both[s])
            else:
                args = (self._x[f], *render, self._cache[f][v], low, gain, both[s], *scratch)
            slots.append((args, both[s], both[1 - s]))
        return slots, field, (field.reshape(1, -1), *weights, self._sums[f, v:v + 1], self._moving[f, v:v + 1])

    # ------------------------------------------------------------------ streaming

    def push(self, seq: int, t: float, counts, valid=None) -> OnlineStep:
        """Process one frame of every finger; returns the (reused) :class:`OnlineStep`.

        Args:
            seq: the frame's sequence number (an integer; must increase from frame to frame).
            t: its time, s (device or host clock; must increase).
            counts: (F, N) raw electrode counts, rows in the order of ``fingers``.
            valid: optional (F,) bool; False skips that finger for this frame.

        Raises ``ValueError`` only for arguments of the wrong shape or type; bad data
        (NaN, out-of-range counts, duplicate or late frames) is skipped and counted.
        """
        n_f = len(self.fingers)
        arr = np.asarray(counts)
        if arr.shape != (n_f, self.model.n_taxels):
            raise ValueError(f"counts: expected shape ({n_f}, {self.model.n_taxels}) (fingers {self.fingers} × "
                             f"taxels), got {arr.shape}")
        if valid is not None and np.shape(valid) != (n_f,):
            raise ValueError(f"valid: expected shape ({n_f},) (one flag per finger {self.fingers}), "
                             f"got {np.shape(valid)}")
        try:
            seq = operator.index(seq)
            t = float(t)
        except (TypeError, ValueError):
            raise ValueError(f"seq, t: expected an integer sequence number and a time in s, "
                             f"got {seq!r}, {t!r}") from None
        step = self._step
        step.seq, step.t = seq, t
        in_order = math.isfinite(t) and (self._last_seq is None or (seq > self._last_seq and t > self._last_t))
        if not in_order:
            self._counters["skipped_order"] += 1
            step.processed[:] = False
            return self._finish(step)
        self._last_seq, self._last_t = seq, t

        np.copyto(self._counts, arr, casting="unsafe")
        if valid is None:
            self._usable[:] = True
        else:
            np.copyto(self._usable, valid, casting="unsafe")
        _filter_step(self._counts, self._usable, self._baseline, self._r, self._q, self._x, self._p, self._n,
                     self._counts_max, self._reference)
        np.copyto(step.processed, self._usable)
        for f in range(n_f):
            if self._usable[f]:
                self._process_finger(f, seq)
            else:
                self._counters["skipped_invalid"][f] += 1
        return self._finish(step)

    def _process_finger(self, f: int, seq: int) -> None:
        """Frames, flow and aggregate sums of finger f, whose filter has just taken a sample."""
        counters = self._counters
        counters["processed"][f] += 1
        first = self._n[f] == 1
        if not first and seq != self._finger_seq[f] + 1:
            counters["gaps"][f] += 1
        self._finger_seq[f] = seq
        slot = self._slot[f] = 1 - self._slot[f]
        if self._linear:
            self._x32[f, 0] = self._x[f]
        for v, (slots, field, aggregate_args) in enumerate(self._calls[f]):
            render, current, previous = slots[slot]
            if self._linear:
                x32, op_t, out, img, low, gain, frame = render
                np.matmul(x32, op_t, out=out)
                _frame_kernels._store_u8(img, low, gain, frame)
            else:
                _frame_kernels._render_activation_u8(*render)
            stream = self._streams[f][v]
            if first:
                field[:] = 0.0
                if stream is not None:
                    stream.push(current)
            elif stream is not None:
                stream.push(current, field)
            elif self._farneback:
                cv2.calcOpticalFlowFarneback(previous, current, field, *self._flow_params)
            else:
                np.copyto(field, self._estimators[f][v](previous, current))
            aggregate._aggregate(*aggregate_args)

    def _finish(self, step: OnlineStep) -> OnlineStep:
        """The step's arrays from the aggregate sums and the filter state."""
        np.sum(self._x, axis=1, out=step.activation_total)
        np.sum(np.abs(self._x, out=self._abs_x), axis=1, out=step.activation_contact)
        _results(self._sums, self._moving, self._n_mask, step.processed, step.mean_col, step.mean_row,
                 step.magnitude, step.direction, step.divergence, step.curl, step.confidence,
                 step.activation_total, step.activation_contact)
        return step

    # ------------------------------------------------------------------ state

    def reset(self, finger: str | int | None = None) -> None:
        """Start a finger (a name or row index; ``None``: every finger) afresh: its next
        good sample is the first of its filter (x0 = that sample, P0 = R) and has zero
        flow, and its renderer starts from rest. ``reset()`` also forgets the last
        ``seq`` and ``t``, so a stream whose counter restarted (device reconnect) is
        accepted again. Counters are kept."""
        if finger is None:
            targets = range(len(self.fingers))
            self._last_seq = self._last_t = None
        else:
            targets = [self._finger(finger)]
        for f in targets:
            self._n[f] = 0
            for v, name in enumerate(self.views):
                self._cache[f][v][:] = frames.frame_cache(self.model.plans[name])
                if not self._farneback:       # a fresh estimator, as offline per record
                    self._estimators[f][v] = flow.FlowEstimator(self.model.config.flow)

    def frame(self, finger: str | int, view: str) -> np.ndarray:
        """The finger's latest processed 8-bit frame (H, W) in ``view``, read-only and
        overwritten by a later push (zeros before the first)."""
        f, v = self._finger(finger), self._view(view)
        out = self._frames[f][v][self._slot[f]].view()
        out.flags.writeable = False
        return out

    def flow_field(self, finger: str | int, view: str) -> np.ndarray:
        """The finger's latest flow field (H, W, 2) float32 px/frame (Δcol, Δrow) in
        ``view``, read-only and overwritten by a later push."""
        f, v = self._finger(finger), self._view(view)
        out = self._field[f][v].view()
        out.flags.writeable = False
        return out

    def counters(self) -> dict[str, dict[str, int]]:
        """Per finger, what happened to its samples so far: ``{finger: {counter: n}}``
        (plain ints, JSON-ready), cumulative (not cleared by :meth:`reset`):

        - ``processed``: samples used;
        - ``skipped_invalid``: samples skipped because a count was not finite or outside
          1..4095, or the finger was flagged invalid;
        - ``skipped_order``: frames skipped because ``seq`` or ``t`` did not increase
          (duplicates, late frames) or ``t`` was not finite — counted for every finger;
        - ``gaps``: processed samples that do not directly follow the finger's previous
          processed one (``seq`` jumped: frames lost or skipped in between).
        """
        return {name: {k: int(self._counters[k][f]) for k in COUNTERS}
                for f, name in enumerate(self.fingers)}

    def _finger(self, finger) -> int:
        """Row index of a finger given by name or index."""
        if isinstance(finger, str) and finger in self.fingers:
            return self.fingers.index(finger)
        if isinstance(finger, (int, np.integer)) and not isinstance(finger, bool) \
                and 0 <= finger < len(self.fingers):
            return int(finger)
        raise ValueError(f"finger: expected one of {self.fingers} or an index in [0, {len(self.fingers)}), "
                         f"got {finger!r}")

    def _view(self, view) -> int:
        if view not in self.views:
            raise ValueError(f"view: expected one of {self.views}, got {view!r}")
        return self.views.index(view)
