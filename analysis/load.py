"""Read a run store (``run.zarr``) into plain arrays: :class:`RunData`.

Only this module knows the store's layout (docs/run_store.md). It never reads the ``truth``
group (that is :mod:`analysis.score`'s business, after the analysis).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from tactile_flow.runstore import packed, packedread
from tactile_flow.runstore.reader import check_version, data_arrays, open_group
from tactile_flow.runstore.sensors import recorded_sensor, require_same_sensor

from .electrodes import StoredElectrodes, screen_counts


class AnalysisInputError(ValueError):
    """The input cannot be analysed at all (not a run store, no tactile data)."""


@dataclass
class Events:
    time: np.ndarray             # (E,) s since run start
    kind: list[str]
    name: list[str]
    detail: list[dict]

    def of_kind(self, kind: str) -> list[tuple[float, str, dict]]:
        return [(float(t), n, d) for t, k, n, d in zip(self.time, self.kind, self.name, self.detail) if k == kind]


@dataclass
class RunData:
    """One run's data as numpy arrays. Times are seconds since run start.

    Attributes:
        path: the store.
        time: (T,) BioTac frame times, s.
        fingers: finger names along axis 1 of ``electrodes``.
        electrodes: (T, F, N) raw counts (float64): an array, or for a long record a
            :class:`.electrodes.StoredElectrodes` read a stretch at a time (``electrodes[a:b]``).
            Frames no finger can use and frames with a bad time stamp are removed
            (``dropped``); a finger's own bad samples stay, marked in ``valid``.
        valid: (T, F) bool, the finger's N electrodes all within the sensor's usable counts,
            1..4094 on the BioTacs (0 is a short or a deleted chunk read back as zeros, 4095 a
            saturated or shorted channel).
        pdc: (T, F) PDC counts (float32) or ``None`` (records with electrodes only).
        baseline_counts: (F, N) stored unloaded electrode counts (an imported recording's
            calibration or estimate, a recorded run's session calibration: ``biotac/baseline``)
            or ``None``; ``baseline_uncertainty`` (F, N) counts, its stated uncertainty, if stored.
        sensor: the :class:`tactile.sensor.SensorModel` the record is read with (the one it was
            recorded with: :func:`runstore.sensors.recorded_sensor`); ``sensor_how``: how it was
            found (``recorded``, or ``assumed: ...`` for a store from before models were recorded).
        dropped: what was removed from the record and why: ``{"what", "frames", "reason"}``.
        arm_time, tcp_pose, tcp_speed: (A,), (A, 6) m/rad, (A, 6) m/s, rad/s, or ``None``.
        events: the event table (empty if the group is missing).
        attrs: root attributes; ``protocol``, ``labels``, ``status``.
        config: the run's resolved config (from provenance) or {}.
        missing: groups that were absent, with what that costs.
        input_sha256: checksum of the stored arrays the analysis reads and of the frames kept.
        tree: the store opened as a read-only ``zarr.Group`` (e.g. for :func:`open_truth`).
    """

    path: Path
    time: np.ndarray
    fingers: list[str]
    electrodes: np.ndarray | StoredElectrodes
    pdc: np.ndarray | None
    arm_time: np.ndarray | None
    tcp_pose: np.ndarray | None
    tcp_speed: np.ndarray | None
    events: Events
    attrs: dict
    config: dict
    missing: dict = field(default_factory=dict)
    input_sha256: str = ""
    dropped: list = field(default_factory=list)
    valid: np.ndarray | None = None
    baseline_counts: np.ndarray | None = None
    baseline_uncertainty: np.ndarray | None = None
    tree: object = field(default=None, repr=False)
    sensor: object = field(default=None, repr=False)
    sensor_how: str = "recorded"

    @property
    def n_taxels(self) -> int:
        """Electrodes per finger (the N of ``electrodes``)."""
        return int(self.electrodes.shape[2])

    @property
    def dropped_invalid(self) -> int:
        """Frames removed from the record (every finger unusable, or a bad time stamp)."""
        return int(sum(d["frames"] for d in self.dropped))

    @property
    def protocol(self) -> str | None:
        return self.attrs.get("protocol")

    @property
    def labels(self) -> list[str]:
        return list(self.attrs.get("labels") or [])

    @property
    def status(self) -> str:
        return str(self.attrs.get("status", "unknown"))

    @property
    def rate_hz(self) -> float:
        """Nominal frame rate (median of the frame intervals)."""
        if len(self.time) < 2:
            return 100.0
        return float(1.0 / np.median(np.diff(self.time)))

    def fingertip_rotvec(self, finger: str) -> np.ndarray | None:
        """Rotation vector (3,) of the sensor frame in the TCP frame, from the run's config."""
        tips = ((self.config.get("hardware") or {}).get("fingertips") or {})
        pose = tips.get(finger)
        return None if pose is None else np.asarray(pose[3:6], float)

    def gravity_sensor(self) -> np.ndarray | None:
        """Direction of gravity in the sensor frame during a pour (hardware.pour.gravity_sensor)."""
        g = ((self.config.get("hardware") or {}).get("pour") or {}).get("gravity_sensor")
        if g is None:
            return None
        g = np.asarray(g, float)
        n = np.linalg.norm(g)
        return g / n if n > 0 else None


def is_run_store(path: Path) -> bool:
    """A directory store with its root ``zarr.json``, or a packed store (``run.zarr.zip``)."""
    return packed.is_store(path)


MAX_BACKWARD_FRACTION = 0.01
"""A time axis that goes backwards at more than this fraction of its steps (shuffled) is not trusted."""

IN_MEMORY_FRAMES = 10_000
"""Records of at most this many frames are read whole (``analysis.memory.chunk_frames``)."""


def screen_frames(path, time, in_range, all_zero, pdc, stored_valid, all_saturated=None):
    """Check the time axis and each finger's samples; choose the frames to keep.

    ``in_range`` (T, F): the finger's N electrodes all within the usable counts (1..4094 on a
    BioTac); ``all_zero``, ``all_saturated`` (T,): every electrode of every finger reads 0, or
    above the usable counts (:func:`.electrodes.screen_counts`). A record with no frame to keep is
    refused naming why its frames were dropped (all zeros, saturation, out of range).
    Returns ``(keep (T,) bool, valid (T, F) bool, dropped)``: the frames kept, the validity
    of each finger's samples, and the list of what was dropped and why. A time axis that goes
    backwards at more than :data:`MAX_BACKWARD_FRACTION` of its steps (shuffled or
    overwritten) is an :class:`AnalysisInputError`: no part of such a record can be trusted
    to be in order. A few backward or repeated stamps drop those frames.
    """
    dropped = []
    n = len(time)
    finite_t = np.isfinite(time)
    if n > 1:
        steps = np.diff(np.where(finite_t, time, -np.inf))
        backward = int(np.count_nonzero(steps[np.isfinite(steps)] < 0))
        if backward > max(1, MAX_BACKWARD_FRACTION * (n - 1)):
            first = int(np.flatnonzero(np.isfinite(steps) & (steps < 0))[0]) + 1
            raise AnalysisInputError(f"{path}: biotac/time goes backwards at {backward} of {n - 1} steps "
                                     f"(first at frame {first}); the record's order cannot be trusted")
    keep = finite_t.copy()
    if not finite_t.all():
        dropped.append({"what": "frames", "frames": int((~finite_t).sum()), "reason": "time stamp not finite"})
    # a stamp must exceed every earlier kept stamp: a backward step drops the frames up to the next later one
    running = np.maximum.accumulate(np.where(finite_t, time, -np.inf))
    late = np.r_[False, time[1:] <= running[:-1]] & finite_t
    if late.any():
        dropped.append({"what": "frames", "frames": int(late.sum()),
                        "reason": "time stamp not after the previous frame's (out of order or repeated)"})
        keep &= ~late
    valid = in_range & stored_valid[:, None]
    if pdc is not None:
        valid &= np.isfinite(pdc)
    none = keep & ~valid.any(axis=1)
    if none.any():
        zeros = none & all_zero
        saturated = none & (all_saturated if all_saturated is not None else False)
        why = ("every electrode of every finger reads 0 (a deleted or unreadable chunk read back as zeros)"
               if zeros.sum() == none.sum() else
               "every electrode of every finger reads its full scale (a BioTac's 4095: saturated, an impedance "
               "of 0 kΩ: pressed beyond the sensor's range, or its channels shorted)"
               if saturated.sum() == none.sum() else
               "no finger has all its electrodes within the usable counts (1..4094 on a BioTac)")
        dropped.append({"what": "frames", "frames": int(none.sum()), "reason": why})
        keep &= ~none
    if keep.sum() < 2:
        reasons = "; ".join(f"{d['frames']} frame(s) dropped: {d['reason']}" for d in dropped)
        raise AnalysisInputError(f"{path}: the run store holds {int(keep.sum())} valid tactile frame(s)"
                                 + (f" ({reasons})" if reasons else "") + "; nothing to analyse")
    return keep, valid[keep], dropped


def store_sensor(dt, path, requested=None):
    """``(model, how)``: the sensor model to read the opened store ``dt`` with — the one it was
    recorded with; ``requested`` (a :class:`tactile.sensor.SensorModel`, ``sensor=`` of
    ``tactile-analyze``) must be that one, else :class:`tactile.sensor.SensorModelError`."""
    b = dt["biotac"]
    shape = b["electrodes"].shape
    if len(shape) != 3:
        raise AnalysisInputError(f"{path}: biotac/electrodes has shape {tuple(shape)}; expected (time, finger, taxel)")
    recorded, how = recorded_sensor(dict(dt.attrs), int(shape[2]), str(path))
    return require_same_sensor(recorded, how, requested, str(path)), how


def open_store(path):
    """The run store at ``path``, read-only: a short packed store read whole without zarr
    (:func:`runstore.packedread.open_small`: ~10 ms less per short record), any other through
    zarr-python (:func:`runstore.reader.open_group`); a store of a newer major schema version is
    refused."""
    group = packedread.open_small(path) if packed.is_packed(path) else None
    if group is None:
        return open_group(path)
    check_version(group.attrs, str(Path(path)))
    return group


def peek_sensor(path, requested=None):
    """:func:`store_sensor` of the store at ``path`` (its attributes only; ``None`` if ``path``
    is not a readable run store: :func:`load_run` then says why)."""
    try:
        dt = open_store(Path(path))
        if "biotac" not in set(dt.group_keys()) or "electrodes" not in dt["biotac"]:
            return None
    except Exception:  # noqa: BLE001 - load_run reports it
        return None
    return store_sensor(dt, path, requested)[0]


def load_run(path, in_memory_frames: int = IN_MEMORY_FRAMES, sensor=None) -> RunData:
    """Open ``path`` (a ``run.zarr``) and read what the analysis needs, with the sensor model it
    was recorded with (``sensor``: a model asked for, which must be that one).

    The electrodes of a record longer than ``in_memory_frames`` frames stay in the store
    (:class:`.electrodes.StoredElectrodes`, read a stretch at a time); shorter ones are read whole.

    Raises :class:`AnalysisInputError` with one clear sentence when the path is not a run
    store or holds no usable tactile data. Missing optional groups (arm, events) are listed
    in ``RunData.missing``.
    """
    path = Path(path)
    if not path.exists():
        raise AnalysisInputError(f"{path}: no such file or directory")
    if not is_run_store(path):
        raise AnalysisInputError(f"{path}: not a run store (expected a zarr v3 directory with zarr.json, "
                                 f"as tactile-run writes, or a packed run.zarr.zip, as tactile-import writes)")
    try:
        dt = open_store(path)
    except Exception as exc:  # noqa: BLE001 - any reader error means: not readable as a run store
        raise AnalysisInputError(f"{path}: cannot be read as a run store ({type(exc).__name__}: "
                                 f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
    groups = set(dt.group_keys())
    if "biotac" not in groups:
        raise AnalysisInputError(f"{path}: the run store has no biotac group; nothing to analyse")
    b = dt["biotac"]
    if "electrodes" not in b or "time" not in b:
        raise AnalysisInputError(f"{path}: biotac group without electrodes/time; nothing to analyse")
    sensor, sensor_how = store_sensor(dt, path, sensor)
    time = _values(b, "time", path)
    stored = StoredElectrodes(b["electrodes"], None, lambda exc: _unreadable(path, "electrodes", exc))
    fingers = [str(f) for f in _values(b, "finger", path, None)]
    pressure = sensor.pressure.name if sensor.pressure is not None else None
    pdc = _values(b, pressure, path, np.float32) if pressure is not None and pressure in b else None   # counts: exact in f4
    baseline_counts = _values(b, "baseline", path) if "baseline" in b else None
    baseline_unc = _values(b, "baseline_uncertainty", path) if "baseline_uncertainty" in b else None
    stored_valid = _values(b, "valid", path, bool) if "valid" in b else np.ones(len(time), bool)
    in_range, all_zero, all_saturated, electrodes_sha = screen_counts(stored, sensor.valid_counts)
    keep, valid, dropped = screen_frames(path, time, in_range, all_zero, pdc, stored_valid, all_saturated)
    del in_range, all_zero
    time = time[keep]
    pdc = pdc[keep] if pdc is not None else None
    electrodes = stored.select(keep)
    if len(electrodes) <= in_memory_frames:
        electrodes = electrodes.materialise()
    missing = {}
    arm_time = tcp_pose = tcp_speed = None
    if "arm" in groups:
        a = dt["arm"]
        if "tcp_pose" in a and "time_arm" in a and a["time_arm"].shape[0] > 1:
            arm_time = np.asarray(a["time_arm"][...], float)
            tcp_pose = np.asarray(a["tcp_pose"][...], float)
            tcp_speed = np.asarray(a["tcp_speed"][...], float) if "tcp_speed" in a else None
    if arm_time is None:
        missing["arm"] = "no arm pose: world-frame directions and feature widths are skipped"
    if "events" in groups:
        e = dt["events"]
        details = []
        for s in (e["detail"][...] if "detail" in e else []):
            try:
                details.append(json.loads(str(s)) if str(s) else {})
            except json.JSONDecodeError:
                details.append({"text": str(s)})
        events = Events(np.asarray(e["time"][...], float) if "time" in e else np.zeros(0),
                        [str(k) for k in e["kind"][...]] if "kind" in e else [],
                        [str(n) for n in e["name"][...]] if "name" in e else [], details)
    else:
        events = Events(np.zeros(0), [], [], [])
        missing["events"] = "no events: no tare stretch (baseline fallback used), no step boundaries"
    attrs = dict(dt.attrs)
    labels = attrs.get("labels")
    if labels is not None and not (isinstance(labels, list) and all(isinstance(x, str) for x in labels)):
        raise AnalysisInputError(f"{path}: root attribute labels: expected a list of segment label names, got "
                                 f"{str(labels)[:60]!r}; the store's attributes are damaged")
    prov = attrs.get("provenance") or {}
    if isinstance(prov, str):
        try:
            prov = json.loads(prov)
        except json.JSONDecodeError:
            prov = {}
    config = prov.get("config") or {} if isinstance(prov, dict) else {}
    h = hashlib.sha256(electrodes_sha.encode())
    for arr in (time, keep, pdc, arm_time, tcp_pose, tcp_speed, events.time):
        if arr is not None:
            h.update(np.ascontiguousarray(arr).tobytes())
    h.update(json.dumps([events.kind, events.name], sort_keys=True).encode())
    return RunData(path=path, time=time, fingers=fingers, electrodes=electrodes, pdc=pdc, arm_time=arm_time,
                   tcp_pose=tcp_pose, tcp_speed=tcp_speed, events=events, attrs=attrs, config=config,
                   missing=missing, input_sha256=h.hexdigest(), dropped=dropped, valid=valid,
                   baseline_counts=baseline_counts, baseline_uncertainty=baseline_unc, tree=dt,
                   sensor=sensor, sensor_how=sensor_how)


def _values(group, name: str, path: Path, dtype=float) -> np.ndarray:
    """``group[name]`` read whole as an array; a chunk that cannot be read (corrupt, truncated)
    is an :class:`AnalysisInputError` naming the array."""
    try:
        return np.asarray(group[name][...], dtype)
    except Exception as exc:  # noqa: BLE001 - the codec's own error type varies
        raise _unreadable(path, name, exc) from None


def _unreadable(path: Path, name: str, exc: Exception) -> AnalysisInputError:
    why = (str(exc).splitlines() or [""])[0][:120]
    return AnalysisInputError(f"{path}/biotac/{name}: a chunk cannot be read ({type(exc).__name__}: {why}); "
                              f"the store is damaged")


def open_truth(run):
    """The ``truth`` group as {subgroup: {var: ndarray}} or ``None`` (for scoring only).
    ``run``: a :class:`RunData` (its opened store is reused) or a store's path."""
    dt = run.tree if isinstance(run, RunData) and run.tree is not None else open_group(run)
    if "truth" not in dt.group_keys():
        return None
    out = {}
    for name, node in dt["truth"].groups():
        out[name] = {v: np.asarray(a[...]) for v, a in data_arrays(node).items()}
    t0 = float(dt.attrs.get("t0_clock_s", 0.0) or 0.0)
    out["_t0"] = t0
    return out
