"""Compile the method's numba kernels on every core before a first analysis needs them.

numba compiles a kernel the first time it is called and keeps it on disk (``__pycache__``
beside the source, or ``$NUMBA_CACHE_DIR``). So the first analysis on a machine, or the
first after an upgrade, compiles about half a minute of kernels (2-core machine), one after
the other, before it can do anything else; a run with the live slip monitor compiles its
own kernels before the arm moves. The kernels fall into independent groups (the geodesics
of the model, the renderer, Farnebäck's flow with the aggregation, the Kalman smoother, the
live chain). :func:`compiling` compiles each group that is not on disk yet in a child
process, as many at once as there are cores. Each child calls the real code on a few
made-up frames. The children write numba's on-disk cache, and the analysis then loads the
kernels from it.

Only the entry kernels of a group (the ones Python calls) decide whether it is on disk. The
helpers they call are compiled with them. A group that is already cached costs one
small file read, and nothing starts when every group is cached or there is one core.
``tests/test_warmup.py`` checks that after a warm-up the analysis of a run compiles nothing.
"""

from __future__ import annotations

import contextlib
import importlib
import os
import pickle
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np

__all__ = ["ANALYSIS", "LIVE", "available_cores", "cold_groups", "compile_cold", "compile_group", "compiling"]

COST_S = {"model": 13.4, "frames": 18.5, "flow": 13.7, "signals": 4.5, "online": 30.4}
"""Time (s) a child takes for each group on this 2-core machine, cache empty (``python -m
tactile.warmup GROUP``): the longest go first when the groups are shared out among the
children. ``model`` also computes the geodesic distances of the configured mesh and caches
them. The analysis's four add up to more than the same kernels compiled in one process
(~35 s): each child starts Python and numba and compiles numba's own helpers again."""

WAIT_S = 600.0
"""Longest wait (s) for the children: one still compiling then is stopped, and whatever it had
not cached compiles where it is first used."""

ANALYSIS = ("model", "frames", "flow", "signals")
"""The groups an offline analysis calls."""
LIVE = ("model", "online")
"""The groups the live monitor (:class:`tactile.online.OnlineFlow`) calls."""


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity, not the machine's count)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:                       # pragma: no cover - macOS, Windows
        return max(1, os.cpu_count() or 1)


def _entries(group: str, config) -> list[tuple[str, str]]:
    """(module, kernel) that Python calls for ``group`` (not ``model``: see :func:`cold_groups`)
    under ``config`` (a :class:`tactile.pipeline.TactileConfig`); the empty list if it calls none."""
    from . import farneback
    if group == "frames":
        return [("tactile_flow.tactile._frame_kernels", k) for k in
                (("_rasterise", "_render_frames") if config.render == "exact" else ("_rasterise", "_store_u8"))]
    if group == "flow":
        flow = [("tactile_flow.tactile._farneback_kernels", "expand"), ("tactile_flow.tactile._farneback_kernels", "flows")] \
            if farneback.supports(config.size, config.flow) else []
        return flow + [("tactile_flow.tactile.aggregate", "_aggregate")]
    if group == "signals":
        return [("tactile_flow.tactile.signals", k) for k in ("_gains_kernel", "_filter_kernel", "_smooth_kernel_inplace",
                                                 "_median_kernel")]
    if group == "online":
        return [("tactile_flow.tactile.online", "_filter_step"), ("tactile_flow.tactile.online", "_results"),
                ("tactile_flow.tactile._frame_kernels", "_render_activation_u8"), ("tactile_flow.tactile._farneback_kernels", "advance")]
    _unknown(group)


def _on_disk(module: str, kernel: str) -> bool:
    """Whether numba's disk cache holds a current compilation of ``module.kernel``. Reads
    numba's cache index (not a public API): anything unexpected counts as cached, so that
    a change in numba costs the parallel warm-up, never a wrong result."""
    try:
        cache = getattr(importlib.import_module(module), kernel)._cache
        return bool(cache._cache_file._load_index())
    except Exception:  # noqa: BLE001 - see the docstring
        return True


_WARM: set = set()
"""(group, config, sensor, cache directories) found compiled on disk by this process: they stay so for it (asking
numba's cache index again cost ~7 ms a run of a dataset)."""


def cold_groups(config, groups=ANALYSIS, sensor=None) -> list[str]:
    """The ``groups`` of kernels ``config`` needs that numba has not compiled on this machine
    (for ``model``: whose geodesic distances for ``sensor`` — a :class:`tactile.sensor.SensorModel`,
    default the BioTac SP — are not on disk; with them there, the geodesic kernel is never called)."""
    def cold(group):
        key = (group, repr(config), None if sensor is None else sensor.sha256, os.environ.get("NUMBA_CACHE_DIR"),
               os.environ.get("TACTILE_CACHE_DIR"), os.environ.get("XDG_CACHE_HOME"))
        if key in _WARM:
            return False
        if group == "model":
            is_cold = not _model_on_disk(config, sensor)
        else:
            is_cold = any(not _on_disk(m, k) for m, k in _entries(group, config))
        if not is_cold:
            _WARM.add(key)
        return is_cold
    return [g for g in groups if cold(g)]


def _model_on_disk(config, sensor=None) -> bool:
    """Whether the model's geodesic distances are in the disk cache (or it needs none)."""
    from . import surface
    from .pipeline import TactileModel
    if config.geodesic != "accurate":
        return True
    try:
        taxels, _, mesh = TactileModel.surface_of(config, sensor=sensor)
        return surface.weights_on_disk(mesh, taxels, config.geodesic)
    except Exception:  # noqa: BLE001 - the model's own build reports what is wrong
        return True


def compile_group(group: str, config, sensor=None) -> None:
    """Compile (or load) the kernels of ``group`` by running the real code on a few frames
    (``sensor``: the model whose geodesic distances ``model`` computes; default the BioTac SP)."""
    from . import aggregate, flow, online, signals, surface
    from .pipeline import TactileModel
    rng = np.random.default_rng(0)
    h, w = config.size
    if group == "model":                        # the geodesic distances, computed and cached on disk
        taxels, _, mesh = TactileModel.surface_of(config, sensor=sensor)
        surface.interpolation_weights(mesh, taxels, geodesic=config.geodesic)
    elif group in ("frames", "online"):
        model = _coarse_model(config)
        view = next(iter(model.plans))
        n = model.n_taxels
        activation = rng.uniform(0.0, 2.0, (4, n))
        if group == "frames":
            model.render_uint8(activation, view)
            model.render(activation, view)
        else:                                    # as protocols.live.warm_up: a few frames pushed
            stream = online.OnlineFlow(model, np.full((1, n), 10.0), ("ff",), tuple(model.plans))
            for i in range(3):
                stream.push(i, 0.01 * i, np.full((1, n), 3000.0 - 100 * i))
    elif group == "flow":
        frames = rng.integers(0, 255, (6, h, w), dtype=np.uint8)
        mask = np.zeros((h, w), bool)
        mask[2:-2, 2:-2] = True
        for fields in (flow.dynamic_flow(frames, config=config.flow),
                       flow.static_flow(frames, np.zeros((h, w), np.uint8), config=config.flow)):
            aggregate.aggregate_flow(fields, mask, noise=config.noise)
    elif group == "signals":
        counts = rng.normal(0.0, 1.0, (20, 2, 24))              # the kernels' types, not a sensor's shape
        signals.kalman_smooth(counts, R=config.kalman_r, Q=config.kalman_q)
        signals.running_median(counts, 5)
    else:
        _unknown(group)


def _unknown(group: str):
    raise ValueError(f"warm-up group: expected one of {sorted(COST_S)}, got {group!r}")


def _coarse_model(config):
    """A model of ``config`` on a coarse mesh with the paper's geodesics (built in a second or
    two, nothing cached): the renderer's kernels see the same types as with the real one."""
    import tempfile

    from .pipeline import TactileModel
    with tempfile.TemporaryDirectory() as tmp:
        small = replace(config, geodesic="paper", mesh_spacing=max(config.mesh_spacing, 2.5))
        return TactileModel.build(small, cache_dir=tmp)


def _share_out(groups: list[str], processes: int) -> list[list[str]]:
    """Groups into ``processes`` lists of about equal compile time, longest first."""
    bins: list[list[str]] = [[] for _ in range(min(processes, len(groups)))]
    for g in sorted(groups, key=COST_S.__getitem__, reverse=True):
        min(bins, key=lambda b: sum(COST_S[x] for x in b)).append(g)
    return bins


@contextlib.contextmanager
def compiling(config, workers: int | None = None, console=None, groups=ANALYSIS, sensor=None):
    """Compile the kernels of ``groups`` that ``config`` needs and that are not on disk yet in
    up to ``workers`` (default: the cores available) child processes while the ``with`` body
    runs; wait for them at its end.

    With one worker, or when everything is on disk, nothing starts: the kernels compile on
    first use, as always. A child that fails costs only time (the kernel then compiles where
    it is first used), and so does one still compiling after :data:`WAIT_S`; an exception in
    the body stops the children.
    """
    workers = available_cores() if workers is None else workers
    cold = cold_groups(config, groups, sensor) if workers > 1 else []
    if not cold:
        yield
        return
    if console is not None:
        n = min(workers, len(cold))
        console(f"compiling the numba kernels for this machine ({', '.join(cold)}) in {n} "
                f"process{'es' if n > 1 else ''}: once after an install or an upgrade")
    env = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    children = []
    try:
        for share in _share_out(cold, workers):
            child = subprocess.Popen([sys.executable, "-m", "tactile_flow.tactile.warmup", *share], stdin=subprocess.PIPE,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
            children.append(child)
            with contextlib.suppress(BrokenPipeError):
                child.stdin.write(pickle.dumps((config, sensor)))
                child.stdin.close()
        yield
        deadline = time.monotonic() + WAIT_S
        for child in children:
            with contextlib.suppress(subprocess.TimeoutExpired):     # then killed below
                child.wait(max(0.0, deadline - time.monotonic()))
    finally:
        for child in children:
            if child.poll() is None:
                child.kill()
                child.wait()


def compile_cold(config, workers: int | None = None, console=None, groups=ANALYSIS, sensor=None) -> None:
    """:func:`compiling` with nothing else to do meanwhile: returns when the children are done."""
    with compiling(config, workers, console, groups, sensor):
        pass


def _main(groups: list[str]) -> int:
    config, sensor = pickle.load(sys.stdin.buffer)
    for group in groups:
        compile_group(group, config, sensor)
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
