"""The survey's extinction depth from its points, against hand-built depth sets.

Written references: the median of a set, the 95th percentile by linear interpolation (numpy's
default, Hyndman & Fan type 7), and what a hydrographer reads from a survey: bottoms found
down to some depth, no-bottom limits gathering where the light gives out, and a shore's merged
bottoms (shallow limits) that say nothing of the water's penetration.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.process.extinction import MIN_CLASS45, extinction_depth


def test_turbid_slope_lost_where_its_limits_gather():
    # seabed found from 2 to 8 m (uniform), then 41 limits at 7.5 ... 9.5 m
    d40 = np.linspace(2.0, 8.0, 601)
    d45 = np.linspace(7.5, 9.5, 41)
    ext, src, found = extinction_depth(d45, d40)
    assert src == "class45_beyond_found"
    assert found == pytest.approx(2.0 + 0.95 * 6.0)
    # the limits at or past 7.7 m: 7.70, 7.75 ... 9.50 (37 of them), median 8.60
    assert ext == pytest.approx(8.6)


def test_a_shore_is_not_the_light_giving_out():
    # a shoal found everywhere from 0 to 4.9 m; 25 beach pulses with limits 0.5-2 m
    d40 = np.linspace(0.0, 4.9, 491)
    d45 = np.linspace(0.5, 2.0, 25)
    ext, src, found = extinction_depth(d45, d40)
    assert ext is None and src == "not_reached"
    assert found == pytest.approx(0.95 * 4.9)
    # the plain median of those limits would have said 1.25 m
    assert np.median(d45) == pytest.approx(1.25)


def test_shore_limits_do_not_pull_a_real_extinction_up():
    d40 = np.linspace(2.0, 8.0, 601)
    d45 = np.r_[np.full(30, 8.4), np.full(40, 1.0)]  # 40 shore limits outnumber 30 real ones
    assert np.percentile(d40, 95.0) < 8.4
    ext, src, _ = extinction_depth(d45, d40)
    assert (ext, src) == (pytest.approx(8.4), "class45_beyond_found")


def test_limits_above_the_seabed_it_found_are_local_losses():
    # limits at 6 m while a quarter of the bottoms were found deeper than 7.5 m
    d40 = np.linspace(0.0, 10.0, 1001)
    ext, src, found = extinction_depth(np.full(5 * MIN_CLASS45, 6.0), d40)
    assert found == pytest.approx(9.5) and (ext, src) == (None, "not_reached")


def test_too_few_limits_or_no_soundings():
    assert extinction_depth(np.full(MIN_CLASS45 - 1, 7.0), np.zeros(0))[:2] == (
        None,
        "not_reached",
    )
    ext, src, found = extinction_depth(np.full(MIN_CLASS45, 7.0), np.zeros(0))
    assert (ext, src, found) == (7.0, "class45_beyond_found", None)
    # non-finite and non-positive limits do not count
    bad = np.r_[np.full(MIN_CLASS45 - 1, 7.0), np.nan, -1.0, 0.0]
    assert extinction_depth(bad, np.zeros(0))[0] is None
