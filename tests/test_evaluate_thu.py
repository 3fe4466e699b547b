"""The error within a sounding's THU95, against a seabed with a wall written out by hand.

The seabed is flat at z = -10 m with a 2 m-high box (top z = -8 m) over |x| <= 1, |y| <= 1:
a sounding's true depth at any position is known without the simulator, and so is the distance
from a position to the box's wall.
"""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.evaluate_thu import error_within_thu_m


def _seabed(x, y):
    x, y = np.asarray(x, float), np.asarray(y, float)
    return np.where((np.abs(x) <= 1.0) & (np.abs(y) <= 1.0), -8.0, -10.0)


SIGMA_H = 0.1  # THU95 = 2.45 * 0.1 = 0.245 m


def test_a_sounding_beside_the_wall_reading_the_top_is_within_its_thu():
    # 3 cm outside the wall, reading the top (8 m deep where the truth is 10 m): -2 m at its
    # position, 0 against the top 3 cm away, inside its 0.245 m THU95
    e = error_within_thu_m([1.03], [0.0], [-2.0], [SIGMA_H], _seabed)
    assert e[0] == pytest.approx(0.0, abs=1e-12)
    # and inside the box by 3 cm, reading the floor around it: +2 m there, 0 against the floor
    e = error_within_thu_m([0.97], [0.0], [2.0], [SIGMA_H], _seabed)
    assert e[0] == pytest.approx(0.0, abs=1e-12)


def test_a_sounding_farther_than_its_thu_stays_gross():
    # 0.5 m from the wall (> 0.245 m): nothing within its THU has its depth
    e = error_within_thu_m([1.5], [0.0], [-2.0], [SIGMA_H], _seabed)
    assert e[0] == -2.0
    # the same position with a THU that reaches the wall (sigma 0.25 m: 0.6125 m) is not
    e = error_within_thu_m([1.5], [0.0], [-2.0], [0.25], _seabed)
    assert e[0] == pytest.approx(0.0, abs=1e-12)


def test_a_wall_at_nine_tenths_of_the_thu_is_found():
    # the disc's sampling (16 rings, 64 spokes) reaches 0.9 R whatever the wall's direction:
    # soundings 0.9 R outside each of the four walls, and off a corner along the diagonal
    d = 0.9 * 2.45 * SIGMA_H
    along = np.linspace(-0.8, 0.8, 9)
    c = 1.0 + d / np.sqrt(2.0)
    x = np.concatenate([np.full(9, 1.0 + d), np.full(9, -1.0 - d), along, along, [c, -c]])
    y = np.concatenate([along, along, np.full(9, 1.0 + d), np.full(9, -1.0 - d), [c, -c]])
    e = error_within_thu_m(x, y, np.full(x.size, -2.0), np.full(x.size, SIGMA_H), _seabed)
    np.testing.assert_allclose(e, 0.0, atol=1e-12)


def test_what_is_not_searched_is_returned_as_given():
    x = np.array([1.03, 1.03, 1.03, 5.0])
    err = np.array([-0.9, -2.0, np.nan, 1.5])
    sig = np.array([SIGMA_H, np.nan, SIGMA_H, 0.0])
    e = error_within_thu_m(x, np.zeros(4), err, sig, _seabed)
    # |error| <= 1 m: not a gross error, not searched (the box top is 2 m off anyway);
    # no THU (NaN or 0): no disc; a NaN error stays NaN
    assert e[0] == -0.9 and e[1] == -2.0 and np.isnan(e[2]) and e[3] == 1.5


def test_never_farther_than_at_the_position_and_brute_force_agrees():
    # random soundings around the box: the searched error is never larger in magnitude than
    # the error at the position, and it matches a brute-force search on a fine grid of the disc
    rng = np.random.default_rng(3)
    n = 300
    x, y = rng.uniform(-1.6, 1.6, n), rng.uniform(-1.6, 1.6, n)
    depth = rng.choice([8.0, 10.0], n) + rng.normal(0.0, 0.05, n)
    err = depth - (0.0 - _seabed(x, y))
    e = error_within_thu_m(x, y, err, np.full(n, SIGMA_H), _seabed)
    assert np.all(np.abs(e) <= np.abs(err) + 1e-12)
    r = 2.45 * SIGMA_H
    g = np.linspace(-r, r, 201)
    gx, gy = np.meshgrid(g, g)
    inside = gx**2 + gy**2 <= r**2
    for i in np.flatnonzero(np.abs(err) > 1.0):
        true_d = -_seabed(x[i] + gx[inside], y[i] + gy[inside])
        best = np.min(np.abs(depth[i] - true_d))
        # the brute force's grid is finer: it can find a sliver the rings miss, never the
        # reverse; both agree on which soundings are gross (no depth within 1 m in the disc)
        assert np.abs(e[i]) >= best - 1e-12
        assert (np.abs(e[i]) > 1.0) == (best > 1.0) or abs(best - 1.0) < 0.1
