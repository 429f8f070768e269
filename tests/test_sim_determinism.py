"""Same config and seed → bit-identical data; another seed → different data."""

import numpy as np

from tactile_flow.hardware.sim import make_sim_lab
from tactile_flow.hardware.sim.scenarios import biotac_arrays, straws_sweep


def _run(seed):
    lab = make_sim_lab({"seed": seed}, {"kind": "straws"})
    with lab:
        frames = straws_sweep(lab, speed=0.02)
    b = biotac_arrays(frames["biotac"])
    arm = np.array([np.concatenate([[s.host_time, s.controller_time], s.tcp_pose, s.tcp_wrench])
                    for s in frames["arm"]])
    hand = np.array([s.position for s in frames["hand"]])
    return b, arm, hand, lab.truth.to_dict()


def test_same_seed_is_bit_identical_and_other_seeds_differ():
    a, b, c = _run(7), _run(7), _run(8)
    for k in ("electrodes", "pdc", "tdc", "tac", "pac", "seq", "time", "device_time"):
        assert np.array_equal(a[0][k], b[0][k]), k
    assert np.array_equal(a[1], b[1]) and np.array_equal(a[2], b[2])
    assert np.array_equal(a[3]["feature_crossings"]["centre_time"], b[3]["feature_crossings"]["centre_time"])
    assert not np.array_equal(a[0]["electrodes"], c[0]["electrodes"])
    assert not np.array_equal(a[0]["pac"], c[0]["pac"])
    assert not np.array_equal(a[1][:, 6:], c[1][:, 6:])           # wrench noise
    # the physics does not depend on the seed: same truth
    np.testing.assert_array_equal(a[3]["feature_crossings"]["centre_time"],
                                  c[3]["feature_crossings"]["centre_time"])


def test_reading_more_often_does_not_change_the_data():
    """Device buffers decouple the data from when (and how often) they are read."""
    def run(poll):
        lab = make_sim_lab({"seed": 3}, {"kind": "straws"})
        with lab:
            return biotac_arrays(straws_sweep(lab, speed=0.02, poll_s=poll)["biotac"])
    a, b = run(0.01), run(0.37)
    n = min(len(a["seq"]), len(b["seq"]))        # the scripts end at different poll ticks
    assert n > 300
    for k in ("electrodes", "pdc", "pac", "time"):
        assert np.array_equal(a[k][:n * (22 if k == "pac" else 1)], b[k][:n * (22 if k == "pac" else 1)]), k
