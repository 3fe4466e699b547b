"""The evaluation's water-column section, worked by hand."""

import json

import numpy as np
import pytest

from pipeline.evaluate import water_column_report
from pipeline.process.returns import Points


def _points(classes, depths):
    n = len(classes)
    return Points(
        pulse_id=np.arange(n),
        xyz_m=np.zeros((n, 3)),
        depth_m=np.asarray(depths, float),
        classification=np.asarray(classes, np.uint8),
        kind=np.full(n, 4, np.uint8),
        flags=np.zeros(n, np.uint16),
        detector_flags=np.zeros(n, np.uint16),
        return_number=np.ones(n, np.uint8),
        number_of_returns=np.ones(n, np.uint8),
        confidence=np.ones(n),
        uncertainty_v_m=np.zeros(n),
        uncertainty_h_m=np.zeros(n),
    )


def test_depth_errors_against_the_layer():
    pts = _points([64, 64, 64, 40, 64], [3.9, 4.05, 4.4, 10.0, 4.0])
    rep = water_column_report(pts, layer_depth_m=4.0, layer_thickness_m=0.5)
    assert rep["n"] == 4 and rep["layer_depth_m"] == 4.0
    # errors -0.1, 0.05, 0.4, 0.0: median 0.025, mean 0.0875; within +-0.25: 3 of 4
    assert rep["median_error_m"] == pytest.approx(0.025)
    assert rep["error"]["bias_m"] == pytest.approx(0.0875)
    assert rep["error"]["max_abs_m"] == pytest.approx(0.4)
    assert rep["fraction_within_layer"] == pytest.approx(0.75)
    json.dumps(rep)  # JSON-ready


def test_without_a_layer_only_the_count():
    rep = water_column_report(_points([64, 41], [2.0, 0.0]), layer_depth_m=0.0)
    assert rep["n"] == 1 and rep["error"] is None and rep["median_error_m"] is None
    empty = water_column_report(_points([40], [5.0]), layer_depth_m=4.0)
    assert empty["n"] == 0 and empty["median_error_m"] is None and empty["error"]["n"] == 0
    json.dumps(empty)
