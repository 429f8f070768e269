"""Latency and sustained throughput of the online pipeline (tactile.online.OnlineFlow).

Prints JSON lines, on one thread:

- ``latency``: one finger, one view ("bottom"), frame 32×32 and 64×64: the time of each
  ``push`` (counts in → aggregates out), median / p99 / max over ``--samples`` pushes of
  realistic data (bumps sliding across the pad in changing directions, 12-bit counts with
  sensor noise), after a warm-up; ``flow_only`` is OpenCV's Farnebäck alone on the same
  frame pairs, the floor of the per-sample cost.
- ``throughput``: 5 fingers × 3 views at 100 Hz, frame 28×40 (the default) and 32×32:
  ``--seconds`` of data pushed as fast as possible. ``realtime_margin`` = data seconds /
  processing seconds (> 1: keeps up, with that factor to spare); ``cpu_fraction`` = CPU
  seconds per second of data (the share of one core the stream takes at 100 Hz).

    python benchmarks/bench_online.py [--samples 3000] [--seconds 30] [--render exact linear]
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from tactile_flow.tactile import FINGERS, signals, synthetic  # noqa: E402
from tactile_flow.tactile.online import OnlineFlow  # noqa: E402
from tactile_flow.tactile.pipeline import TactileConfig, TactileModel  # noqa: E402

cv2.setNumThreads(1)
RATE = 100.0
WARMUP = 200


def emit(**row):
    print(json.dumps(row), flush=True)


def counts_record(taxels, n_fingers, n_samples, rng):
    """(T, F, 24) raw counts and the (F, 24) rest impedance: each finger sees bumps crossing
    the pad in a new direction every 1.5 s (0.5 s of rest between), plus 0.07 kΩ of
    activation noise, converted to 12-bit counts with ±4 counts of ADC noise."""
    period = 2.0
    out = np.zeros((n_samples, n_fingers, 24))
    for f in range(n_fingers):
        k = 0
        for start in range(0, n_samples, int(period * RATE)):
            heading = 2.399963 * (k + f)                       # golden angle: every direction
            d = np.array([np.cos(heading), np.sin(heading), 0.0])
            bump = synthetic.moving_bump(taxels, -7 * d, 9.3 * d, duration=1.5, rate_hz=RATE)
            stop = min(n_samples, start + len(bump))
            out[start:stop, f] = bump[: stop - start]
            k += 1
    act = out + rng.normal(0, 0.07, out.shape)
    rest_counts = rng.uniform(1700, 3500, (n_fingers, 24))
    z = signals.counts_to_impedance(rest_counts) + act
    counts = np.clip(np.rint(4095.0 / (1.0 + np.maximum(z, 0) / 10.0)) + rng.normal(0, 4, z.shape).round(), 1, 4095)
    return counts, signals.counts_to_impedance(rest_counts)


def latency(model, counts, baseline, render):
    online = OnlineFlow(model, baseline, FINGERS[:1], views=("bottom",))
    for i in range(WARMUP):
        online.push(i, i / RATE, counts[i])
    n = len(counts) - WARMUP
    dt = np.empty(n)
    frames = np.empty((n,) + model.plans["bottom"].shape, np.uint8)
    clock = time.perf_counter
    for k, i in enumerate(range(WARMUP, len(counts))):
        t0 = clock()
        online.push(i, i / RATE, counts[i])
        dt[k] = clock() - t0
        frames[k] = online.frame(0, "bottom")
    c = model.config.flow
    field = np.empty(frames.shape[1:] + (2,), np.float32)
    flow_dt = np.empty(n - 1)
    for k in range(1, n):
        t0 = clock()
        cv2.calcOpticalFlowFarneback(frames[k - 1], frames[k], field, c.pyr_scale, c.levels, c.winsize,
                                     c.iterations, c.poly_n, c.poly_sigma, c.flags)
        flow_dt[k - 1] = clock() - t0
    us = dt * 1e6
    emit(bench="latency", render=render, fingers=1, views=["bottom"], frame=list(model.config.size),
         samples=n, median_us=round(float(np.median(us)), 1), p99_us=round(float(np.percentile(us, 99)), 1),
         max_us=round(float(us.max()), 1), flow_only_median_us=round(float(np.median(flow_dt) * 1e6), 1))


def throughput(model, counts, baseline, render):
    online = OnlineFlow(model, baseline, FINGERS)
    for i in range(WARMUP):
        online.push(i, i / RATE, counts[i])
    data_s = (len(counts) - WARMUP) / RATE
    wall0, cpu0 = time.perf_counter(), time.process_time()
    for i in range(WARMUP, len(counts)):
        online.push(i, i / RATE, counts[i])
    wall, cpu = time.perf_counter() - wall0, time.process_time() - cpu0
    emit(bench="throughput", render=render, fingers=len(FINGERS), views=list(online.views),
         frame=list(model.config.size), rate_hz=RATE, data_seconds=data_s, processing_seconds=round(wall, 3),
         realtime_margin=round(data_s / wall, 2), cpu_fraction=round(cpu / data_s, 4),
         us_per_sample=round(wall / (len(counts) - WARMUP) * 1e6, 1),
         us_per_finger_view=round(wall / (len(counts) - WARMUP) / (len(FINGERS) * len(online.views)) * 1e6, 1))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=3000, help="latency: pushes measured (after warm-up)")
    ap.add_argument("--seconds", type=float, default=30.0, help="throughput: seconds of 100 Hz data")
    ap.add_argument("--render", nargs="+", default=["exact"], choices=["exact", "linear"])
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    for render in args.render:
        for size in ((32, 32), (64, 64)):
            model = TactileModel.build(TactileConfig(size=size, views=("bottom",), smooth=False, render=render))
            counts, baseline = counts_record(model.taxels, 1, args.samples + WARMUP, rng)
            latency(model, counts, baseline, render)
        for size in ((28, 40), (32, 32)):
            model = TactileModel.build(TactileConfig(size=size, smooth=False, render=render))
            counts, baseline = counts_record(model.taxels, len(FINGERS), int(args.seconds * RATE) + WARMUP, rng)
            throughput(model, counts, baseline, render)


if __name__ == "__main__":
    main()
