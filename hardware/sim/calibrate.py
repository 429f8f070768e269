"""Derive the simulator's resting-sensor calibration from a real BioTac recording.

Run once (needs the ``rosbags`` package; the simulator itself does not)::

    python -m tactile_flow.hardware.sim.calibrate tests/data/biotac_rest_untouched.bag \
        hardware/sim/biotac_rest_calibration.json

For every connected sensor (disconnected ones read pdc = -22072 and are skipped) it
stores: per-electrode mean (baseline, counts), per-electrode noise std after removing a
linear trend (counts), the lag-1 autocorrelation of that noise, the linear drift
(counts/s), and mean / std / drift of PDC, TDC, TAC and of the two PAC samples.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

DISCONNECTED_PDC = -22072


def read_biotac_bag(path, topic: str = "/rh/tactile") -> dict[str, np.ndarray]:
    """Arrays from a ROS1/ROS2 bag of ``sr_robot_msgs/BiotacAll``.

    Returns ``electrodes`` (T, 5, 24), ``pdc``/``tdc``/``tac``/``pac0``/``pac1`` (T, 5),
    ``stamp`` (T,) header stamps (s).
    """
    from rosbags.highlevel import AnyReader

    out: dict[str, list] = {k: [] for k in ("electrodes", "pdc", "tdc", "tac", "pac0", "pac1", "stamp")}
    with AnyReader([Path(path)]) as reader:
        conns = [c for c in reader.connections if c.topic == topic]
        if not conns:
            raise ValueError(f"{path}: no topic {topic}")
        for conn, _, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            out["stamp"].append(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)
            out["electrodes"].append([np.asarray(b.electrodes) for b in msg.tactiles])
            for k in ("pdc", "tdc", "tac", "pac0", "pac1"):
                out[k].append([getattr(b, k) for b in msg.tactiles])
    return {k: np.asarray(v, dtype=np.float64) for k, v in out.items()}


def _trend(y: np.ndarray, t: np.ndarray):
    """Slope (per s) and residual of a per-column least-squares line."""
    coef = np.polyfit(t, y, 1)
    resid = y - np.outer(t, coef[0]) - coef[1] if y.ndim == 2 else y - coef[0] * t - coef[1]
    return coef[0], resid


def derive_calibration(path) -> dict:
    data = read_biotac_bag(path)
    t = data["stamp"] - data["stamp"][0]
    connected = [f for f in range(data["pdc"].shape[1]) if np.all(data["pdc"][:, f] != DISCONNECTED_PDC)]
    sensors = []
    for f in connected:
        e = data["electrodes"][:, f, :]
        slope, resid = _trend(e, t)
        ac = [np.corrcoef(resid[1:, k], resid[:-1, k])[0, 1] for k in range(e.shape[1])]
        s = {"source_finger_index": f,
             "electrode_baseline": np.round(e.mean(0), 2).tolist(),
             "electrode_noise_std": np.round(resid.std(0), 3).tolist(),
             "electrode_noise_lag1": float(np.round(np.median(ac), 3)),
             "electrode_drift_per_s": np.round(slope, 3).tolist()}
        for k in ("pdc", "tdc", "tac"):
            sl, r = _trend(data[k][:, f], t)
            s[k] = {"mean": round(float(data[k][:, f].mean()), 2), "noise_std": round(float(r.std()), 3),
                    "drift_per_s": round(float(sl), 4)}
        pac = np.concatenate([data["pac0"][:, f], data["pac1"][:, f]])
        s["pac"] = {"mean": round(float(pac.mean()), 2), "noise_std": round(float(pac.std()), 3)}
        sensors.append(s)
    digest = hashlib.sha256(Path(path).read_bytes()).hexdigest()
    return {
        "source": {"file": Path(path).name, "sha256": digest,
                   "origin": "3dperceptionlab/tactile-gcn, biotacs-noise/untouched_2018-11-19-12-29-56.bag "
                             "(MIT licence, Copyright (c) 2018 3D Perception Lab)",
                   "n_frames": int(len(t)), "duration_s": round(float(t[-1]), 3),
                   "frame_rate_hz": round(float((len(t) - 1) / t[-1]), 3)},
        "method": "per connected sensor: mean; std of residual after a per-channel linear "
                  "fit in time (noise); slope of that fit (drift); median lag-1 autocorrelation",
        "sensors": sensors,
    }


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print("usage: python -m tactile_flow.hardware.sim.calibrate BAG OUT.json", file=sys.stderr)
        return 2
    cal = derive_calibration(argv[0])
    Path(argv[1]).write_text(json.dumps(cal, indent=1) + "\n")
    print(f"wrote {argv[1]}: {len(cal['sensors'])} sensors")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
