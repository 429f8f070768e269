"""Ground truth: what really happened in the simulated world, for scoring the analysis.

Times are simulated clock times (s, ``SimClock.now()``), sampled at the BioTac frame
rate (10 ms) unless stated. :meth:`GroundTruth.to_dict` gives plain arrays/dicts:

- ``contacts``: per finger, intervals of normal force > ``contact_threshold_n``
  (``finger``, ``start``, ``end``; an open interval ends at NaN).
- ``feature_crossings``: per finger and feature, ``entry``/``exit`` (first/last frame the
  feature carries part of the finger's load) and ``centre_time``: when the pad's lowest
  point crossed the feature's centre line (interpolated between frames, in contact).
- ``sweeps``: per finger, stretches of sliding contact in a constant direction:
  ``start``, ``end``, ``speed_m_s``, ``dir_world`` (n, 3) and ``dir_sensor`` (n, 3).
- ``features``: the surface's feature table (names, centres, width/height/length m, angle rad).
- ``pour``: ``pour_start``, ``slip_onset``, ``rotation``, ``downward``, ``full_slip`` (NaN: never).
- ``faults``: the faults injected (``kind``, ``time``, ``detail``).
- ``object_motions``: one row per motion of the object under the fingers (the object stage's
  ``translate``/``rotate``, or ``none``: a touch held still): ``kind``, ``finger`` (the one
  pressing hardest at its start), ``start``, ``slip_onset`` (first frame the skin broke away:
  slid or turned against friction; NaN if it never did), ``end``, ``force_n`` (that finger's
  normal force at the start), ``direction_sensor_deg`` (the object's motion relative to the
  finger in the sensor x–y plane, 0° = +x, 90° = +y; NaN unless translating),
  ``direction_world_deg``, ``distance_mm``, ``speed_mm_s``, ``rotation_deg`` (+ =
  counter-clockwise seen from outside the pad, i.e. about the sensor's −z), ``rotation_speed_deg_s``.
- ``conditions``: what the run was told (set by the protocol): ``object``, ``press_force_n``,
  ``tare`` (false: the record starts in contact), ``baseline`` (the stored calibration's method).
"""

from __future__ import annotations

import math

import numpy as np


class GroundTruth:
    def __init__(self, fingers, surface, contact_threshold_n: float = 0.05):
        self.fingers = tuple(fingers)
        self.surface = surface
        self.threshold = contact_threshold_n
        self._contacts: list[list] = []   # [finger, start, end]
        self._feature = {}          # (finger, feature) -> list of [entry, exit, centre_time]
        self._prev = {}             # finger -> (t, pole_u, touching set, in_contact)
        self._sweeps = {f: [] for f in self.fingers}
        self.pour: dict[str, float] = {k: math.nan for k in
                                       ("pour_start", "slip_onset", "rotation", "downward", "full_slip")}
        self.faults: list[tuple[str, float, str]] = []
        self._motions: list[dict] = []
        self._force = {f: 0.0 for f in self.fingers}
        self.conditions: dict = {}

    # --- updates (called by the world every frame) -----------------------------------
    def update_finger(self, t: float, finger: str, force: float, touching: set, pole_u: float,
                      v_world: np.ndarray, R_sensor: np.ndarray, sliding: bool):
        """Record one frame of one finger. ``R_sensor``: sensor→world rotation."""
        in_contact = force > self.threshold
        self._force[finger] = force
        prev = self._prev.get(finger)
        # contact intervals
        if in_contact and (prev is None or not prev[3]):
            self._contacts.append([finger, t, math.nan])
        elif not in_contact and prev is not None and prev[3]:
            for it in reversed(self._contacts):
                if it[0] == finger and math.isnan(it[2]):
                    it[2] = t
                    break
        # feature entry/exit
        prev_touch = prev[2] if prev else set()
        for k in touching - prev_touch:
            self._feature.setdefault((finger, k), []).append([t, math.nan, math.nan])
        for k in prev_touch - touching:
            self._feature[(finger, k)][-1][1] = prev[0]
        # centre-line crossings while in contact with that feature
        if prev is not None and self.surface is not None:
            for k in touching | prev_touch:
                fu = self.surface.features[k].u
                a, b = prev[1] - fu, pole_u - fu
                if not (a * b < 0 or (b == 0 and a != 0)):
                    continue
                tc = prev[0] + (t - prev[0]) * (a / (a - b))
                rec = self._feature.get((finger, k))
                if rec and math.isnan(rec[-1][2]):
                    rec[-1][2] = tc
        # sweeps
        speed = float(np.linalg.norm(v_world)) if in_contact and sliding else 0.0
        sw = self._sweeps[finger]
        if in_contact and sliding and speed > 1e-3:
            d = v_world / speed
            if sw and sw[-1]["open"] and float(d @ sw[-1]["dir"]) > math.cos(math.radians(10)):
                s = sw[-1]
                s["end"], s["n"], s["sum_speed"] = t, s["n"] + 1, s["sum_speed"] + speed
            else:
                if sw and sw[-1]["open"]:
                    sw[-1]["open"] = False
                sw.append({"start": t, "end": t, "dir": d, "dir_sensor": R_sensor.T @ d,
                           "n": 1, "sum_speed": speed, "open": True})
        elif sw and sw[-1]["open"]:
            sw[-1]["open"] = False
        self._prev[finger] = (t, pole_u, set(touching), in_contact)

    def update_pour(self, times: dict):
        for k, v in times.items():
            if math.isnan(self.pour[k]) and not math.isnan(v):
                self.pour[k] = v

    def fault(self, kind: str, t: float, detail: str = ""):
        self.faults.append((kind, t, detail))

    def object_motion(self, kind: str, start: float, end: float, finger: str, force_n: float, amount=None,
                      speed: float = math.nan, R_sensor=None) -> None:
        """A motion of the object under the fingers: ``translate`` by ``amount`` (dx, dy) m at
        ``speed`` m/s, ``rotate`` by ``amount`` rad about the base +z at ``speed`` rad/s, or
        ``none`` (a touch held still). ``R_sensor``: sensor→base rotation of ``finger``."""
        nan = math.nan
        row = {"kind": kind, "finger": finger, "start": start, "slip_onset": nan, "end": end, "force_n": force_n,
               "direction_sensor_deg": nan, "direction_world_deg": nan, "distance_mm": 0.0, "speed_mm_s": nan,
               "rotation_deg": 0.0, "rotation_speed_deg_s": nan}
        R = np.eye(3) if R_sensor is None else np.asarray(R_sensor)
        if kind == "translate":
            d = np.r_[np.asarray(amount, float), 0.0]
            ds = R.T @ d
            row.update(direction_world_deg=math.degrees(math.atan2(d[1], d[0])),
                       direction_sensor_deg=math.degrees(math.atan2(ds[1], ds[0])),
                       distance_mm=float(np.linalg.norm(d)) * 1e3, speed_mm_s=speed * 1e3)
        elif kind == "rotate":
            # about the sensor's +z by amount·(z_sensor · z_base); + in the truth is about −z
            row.update(rotation_deg=-math.degrees(float(amount) * R[2, 2]),
                       rotation_speed_deg_s=math.degrees(speed))
        self._motions.append(row)

    def touch(self, start: float, end: float) -> None:
        """A touch held still from ``start`` to ``end`` (s): an ``object_motions`` row of kind ``none``."""
        finger = max(self._force, key=self._force.get) if self._force else ""
        self.object_motion("none", start, end, finger, self._force.get(finger, 0.0))

    def slipped(self, finger: str, t: float) -> None:
        """The skin of ``finger`` broke away at ``t``: the slip onset of the motion under way."""
        for m in reversed(self._motions):
            if m["finger"] == finger and m["start"] <= t <= m["end"] + 1e-9 and math.isnan(m["slip_onset"]):
                m["slip_onset"] = t
                break

    # --- export --------------------------------------------------------------------------
    def to_dict(self) -> dict:
        """Plain numpy arrays and floats (see module docstring)."""
        c = self._contacts
        fc = [(f, k, *r) for (f, k), recs in sorted(self._feature.items()) for r in recs]
        names = [self.surface.features[k].name for _, k, *_ in fc] if self.surface else []
        sweeps = [(f, s) for f in self.fingers for s in self._sweeps[f] if s["end"] > s["start"]]
        return {
            "contacts": {"finger": np.array([x[0] for x in c], dtype=str),
                         "start": np.array([x[1] for x in c], float),
                         "end": np.array([x[2] for x in c], float)},
            "feature_crossings": {"finger": np.array([x[0] for x in fc], dtype=str),
                                  "feature": np.array(names, dtype=str),
                                  "feature_index": np.array([x[1] for x in fc], int),
                                  "entry": np.array([x[2] for x in fc], float),
                                  "exit": np.array([x[3] for x in fc], float),
                                  "centre_time": np.array([x[4] for x in fc], float)},
            "sweeps": {"finger": np.array([f for f, _ in sweeps], dtype=str),
                       "start": np.array([s["start"] for _, s in sweeps], float),
                       "end": np.array([s["end"] for _, s in sweeps], float),
                       "speed_m_s": np.array([s["sum_speed"] / s["n"] for _, s in sweeps], float),
                       "dir_world": np.array([s["dir"] for _, s in sweeps], float).reshape(-1, 3),
                       "dir_sensor": np.array([s["dir_sensor"] for _, s in sweeps], float).reshape(-1, 3)},
            "features": self.surface.describe() if self.surface else {},
            "pour": dict(self.pour),
            "faults": {"kind": np.array([f[0] for f in self.faults], dtype=str),
                       "time": np.array([f[1] for f in self.faults], float),
                       "detail": np.array([f[2] for f in self.faults], dtype=str)},
            "object_motions": {k: np.array([m[k] for m in self._motions], dtype=str if k in ("kind", "finger")
                                           else float) for k in MOTION_KEYS},
            **({"conditions": dict(self.conditions)} if self.conditions else {}),
        }


MOTION_KEYS = ("kind", "finger", "start", "slip_onset", "end", "force_n", "direction_sensor_deg",
               "direction_world_deg", "distance_mm", "speed_mm_s", "rotation_deg", "rotation_speed_deg_s")
