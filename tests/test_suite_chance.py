"""The chance a calibrated uncertainty misses a coverage band, against sums written out by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.suite.chance import band_miss_probability, expected_failures


def _miss_by_hand(n, p, lo, hi):
    # the binomial law summed term by term over the counts whose fraction lies in the band
    inside = sum(
        math.comb(n, k) * p**k * (1.0 - p) ** (n - k) for k in range(n + 1) if lo <= k / n <= hi
    )
    return 1.0 - inside


@pytest.mark.parametrize(
    "n, p, lo, hi",
    [
        (60, 0.95, 0.93, 0.97),
        (60, 0.68, 0.64, 0.72),
        (250, 0.6827, 0.64, 0.72),
        (100, 0.95, 0.93, 0.97),
    ],
)
def test_against_the_binomial_sum(n, p, lo, hi):
    assert band_miss_probability(n, p, lo, hi) == pytest.approx(
        _miss_by_hand(n, p, lo, hi), abs=1e-12
    )


def test_against_simulated_coverages():
    # 200 000 strata of 60 calibrated 95 % intervals each: the share outside 93-97 %
    rng = np.random.default_rng(5)
    frac = rng.binomial(60, 0.95, 200_000) / 60
    seen = np.mean((frac < 0.93) | (frac > 0.97))
    assert band_miss_probability(60, 0.95, 0.93, 0.97) == pytest.approx(seen, abs=0.005)


def test_large_n_rarely_misses_and_bad_n_is_refused():
    assert band_miss_probability(100_000, 0.95, 0.93, 0.97) < 1e-12
    with pytest.raises(ValueError, match="`n`"):
        band_miss_probability(0, 0.95, 0.93, 0.97)


def test_expected_failures_sum_only_judged_strata():
    row = {"in_floor_window": True, "heldout": {"tpu": {"n": 100}, "posterior": {"n": 60}}}
    out = expected_failures([row, {**row, "in_floor_window": False}], "heldout")
    assert out["tpu68"] == out["tpu95"] == 0.0  # fewer than 200 points: not judged
    assert out["post95"] == pytest.approx(_miss_by_hand(60, 0.95, 0.93, 0.97), abs=1e-12)
    assert out["post68"] == pytest.approx(_miss_by_hand(60, 0.68, 0.64, 0.72), abs=1e-12)
