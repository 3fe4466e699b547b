"""DetectedReturns and Points validate their arrays."""

import numpy as np
import pytest

from pipeline.process.returns import DetectedReturns, Points


def good(n=4):
    return dict(
        pulse_id=np.arange(n),
        origin_meas_m=np.zeros((n, 3)),
        direction_meas=np.tile([0.0, 0.0, -1.0], (n, 1)),
        has_surface=np.array([True, True, False, False][:n]),
        t_surface_s=np.array([1e-6, 1e-6, 0.0, 0.0][:n]),
        has_bottom=np.array([True, False, True, False][:n]),
        t_bottom_s=np.array([2e-6, 0.0, 2e-6, 0.0][:n]),
        surface_confidence=np.array([0.5, 1.0, 0.0, 0.0][:n]),
        bottom_confidence=np.array([0.5, 0.0, 1.0, 0.0][:n]),
        flags=np.zeros(n, np.uint16),
    )


def test_valid_and_read_only():
    r = DetectedReturns(**good())
    assert len(r) == 4
    with pytest.raises(ValueError):
        r.t_surface_s[0] = 3.0
    sub = r.select(r.has_bottom)
    np.testing.assert_array_equal(sub.pulse_id, [0, 2])


@pytest.mark.parametrize(
    ("key", "value", "match"),
    [
        ("t_surface_s", np.array([np.nan, 1e-6, 0.0, 0.0]), "finite"),
        ("t_surface_s", np.array([1e-6, 1e-6, 1e-6, 0.0]), "must be 0 where"),
        ("t_bottom_s", np.array([0.5e-6, 0.0, 2e-6, 0.0]), "t_bottom_s` must be > `t_surface_s"),
        ("direction_meas", np.tile([0.0, 0.0, -2.0], (4, 1)), "unit vectors"),
        ("surface_confidence", np.array([1.5, 1.0, 0.0, 0.0]), r"\[0, 1\]"),
        ("has_bottom", np.array([1, 0, 1, 0]), "boolean"),
        ("origin_meas_m", np.zeros((4, 2)), "shape"),
        ("flags", np.array([0, 0, 0, 70000]), "uint16"),
    ],
)
def test_rejects_bad_input(key, value, match):
    kw = good()
    kw[key] = value
    with pytest.raises(ValueError, match=match):
        DetectedReturns(**kw)


def test_optional_sigmas_checked():
    kw = good()
    kw["t_bottom_sigma_s"] = np.array([1e-10, 0.0, 0.0, 0.0])  # missing for pulse 2
    with pytest.raises(ValueError, match="t_bottom_sigma_s"):
        DetectedReturns(**kw)


def test_points_concatenate_and_check():
    n = 3
    kw = dict(
        pulse_id=np.arange(n),
        xyz_m=np.zeros((n, 3)),
        depth_m=np.zeros(n),
        classification=np.ones(n, np.uint8),
        kind=np.full(n, 2, np.uint8),
        flags=np.zeros(n, np.uint16),
        detector_flags=np.zeros(n, np.uint16),
        return_number=np.ones(n, np.uint8),
        number_of_returns=np.ones(n, np.uint8),
        confidence=np.ones(n),
        uncertainty_v_m=np.zeros(n),
        uncertainty_h_m=np.zeros(n),
    )
    p = Points(**kw)
    both = Points.concatenate([p, p])
    assert len(both) == 6 and both.amplitude is None
    with pytest.raises(ValueError, match="uncertainty_v_m"):
        Points(**{**kw, "uncertainty_v_m": -np.ones(n)})
