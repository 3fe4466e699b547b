"""The flank trend (compiled running sums) against means written out by hand."""

from __future__ import annotations

import numpy as np

from pipeline.process.detect import flank_trend


def test_ramp_takes_the_larger_later_flank_and_one_side_at_the_ends():
    m, gap, length = 30, 2, 4
    y = np.arange(m, dtype=float)[None, :] * 0.5
    got = flank_trend(y, gap, length)[0]
    for t in range(m):
        left = [0.5 * u for u in range(max(t - gap - length, 0), max(t - gap, 0))]
        right = [0.5 * u for u in range(min(t + gap + 1, m), min(t + gap + 1 + length, m))]
        means = [np.mean(s) for s in (left, right) if s]
        assert got[t] == max(means), t


def test_invalid_samples_are_left_out_of_the_flank_means():
    y = np.array([[5.0, 5.0, 5.0, 100.0, 1.0, 1.0, 1.0, 1.0, 9.0, 9.0]])
    valid = np.ones_like(y, dtype=bool)
    valid[0, 8:] = False  # the 9s do not count: the right flank of sample 3 is the 1s alone
    got = flank_trend(y, 1, 3, valid)[0]
    assert got[3] == 5.0  # left [0, 2) = 5, 5; right (4, 8) holds 1, 1, 1 → the larger: 5
    # sample 6: left [2, 5) = 5, 100, 1; right [8, 10) holds only invalid 9s → the left alone
    assert got[6] == (5.0 + 100.0 + 1.0) / 3.0
