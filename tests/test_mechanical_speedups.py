"""Helpers made faster without changing a bit of their results (issue 36, dataset throughput)."""

from __future__ import annotations

import numpy as np
import pytest

from tactile_flow.analysis.slip import _running_median3


@pytest.mark.parametrize("n", [*range(0, 9), 275])
def test_running_median_of_three_is_one_np_median_per_frame_bit_for_bit(n):
    rng = np.random.default_rng(n)
    for trial in range(40):
        x = rng.normal(size=n) * 10 ** rng.uniform(-3, 5)
        if n and trial % 7 == 0:
            x[rng.integers(n)] = np.nan                        # a NaN makes its windows NaN, as before
        if n > 2 and trial % 5 == 0:
            x[1] = x[2]                                        # ties
        before = np.array([np.median(x[max(0, i - 1):i + 2]) for i in range(n)])
        after = _running_median3(x)
        assert after.dtype == before.dtype and after.shape == before.shape
        assert before.tobytes() == after.tobytes()
