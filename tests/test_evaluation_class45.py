"""Class-45 claims against the truth: "no bottom down to here" holds above the true seabed.

Hand-made points over a hand-written seabed (5 m at x = 0, deepening 0.1 m per metre east,
and per pulse 0.01 m deeper per pulse id, as a moving sea's truth is): the count of claims
past the seabed is read off the numbers written here.
"""

from types import SimpleNamespace

import numpy as np

from pipeline.evaluation_points import class45_arrays, class45_report
from pipeline.process.classify import BATHYMETRIC_POINT, NO_BOTTOM_FOUND_AT


class Seabed:
    per_pulse = True

    def __call__(self, x_m, y_m, pulse_id=None):
        d = 5.0 + 0.1 * np.asarray(x_m)
        return d if pulse_id is None else d + 0.01 * np.asarray(pulse_id)


def _points(x, depth, cls, pid):
    n = len(x)
    return SimpleNamespace(
        xyz_m=np.column_stack([x, np.zeros(n), -np.asarray(depth)]),
        depth_m=np.asarray(depth, dtype=float),
        classification=np.asarray(cls, dtype=np.uint8),
        pulse_id=np.asarray(pid),
    )


def test_claims_past_the_true_seabed_are_counted():
    # true depths at the class-45 points: 5.0, 6.02, 7.1, 8.0 (x 0, 10, 20, 30; ids 0, 2, 10, 0)
    pts = _points(
        x=[0.0, 10.0, 20.0, 30.0, 10.0],
        depth=[4.0, 6.5, 7.0, 8.75, 99.0],
        cls=[NO_BOTTOM_FOUND_AT] * 4 + [BATHYMETRIC_POINT],  # a sounding is no claim
        pid=[0, 2, 10, 0, 5],
    )
    a = class45_arrays(pts, Seabed())
    np.testing.assert_allclose(a["nb_true_depth_m"], [5.0, 6.02, 7.1, 8.0])
    r = class45_report(pts, Seabed())
    assert r["class45_past_seabed"] == 2  # 6.5 past 6.02, 8.75 past 8.0
    assert r["class45_past_seabed_over_0.5m"] == 1  # 0.75 m; 0.48 m is within
    assert abs(r["class45_past_seabed_m_max"] - 0.75) < 1e-12


def test_no_claim_no_count():
    pts = _points(x=[0.0], depth=[3.0], cls=[BATHYMETRIC_POINT], pid=[0])
    r = class45_report(pts, Seabed())
    assert r == {
        "class45_past_seabed": 0,
        "class45_past_seabed_over_0.5m": 0,
        "class45_past_seabed_m_max": None,
    }
