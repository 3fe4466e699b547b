"""The column carried back (compiled): an exponential column written out by hand."""

from __future__ import annotations

import math

import numpy as np

from pipeline.process.detect_near import column_excess


def test_exponential_column_is_carried_back_to_the_window_mean_formula():
    m, k, amp, offset, width = 80, 0.05, 200.0, 4, 10
    t = np.arange(m, dtype=float)
    y = (amp * np.exp(-k * t))[None, :]
    excess, column, carried = column_excess(y, np.array([1.0]), offset, width)
    # the two windows' means have the ratio e^{k width}: the decay is measured exactly, and
    # the mean of the first window carried back by (offset + (width - 1) / 2) samples is
    # y(t) sinh(k width / 2) / (width sinh(k / 2))
    gain = math.sinh(k * width / 2) / (width * math.sinh(k / 2))
    inside = t + offset + 2 * width <= m
    np.testing.assert_allclose(carried[0, inside], gain * y[0, inside], rtol=1e-12)
    np.testing.assert_allclose(excess[0], y[0] - carried[0], rtol=0, atol=1e-12)
    # the column follows where both windows fit and stand above the floor (1 count: the
    # column falls under it at t = ln(200) / 0.05 = 106, past the waveform)
    assert np.array_equal(column[0], inside)
