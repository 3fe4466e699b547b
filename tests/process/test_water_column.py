"""Water-column points: refraction by hand, class 64, LAS return numbering, returns checks."""

import dataclasses

import numpy as np
import pytest
from scipy import constants

from pipeline.process.classify import (
    BATHYMETRIC_POINT,
    LOW_NOISE,
    UNCLASSIFIED,
    WATER_COLUMN,
    WATER_SURFACE,
    ClassifySettings,
    classify_points,
)
from pipeline.process.refraction import RefractionSettings, georeference
from pipeline.process.returns import DetectedReturns, PointFlag, Points, ReturnKind
from pipeline.process.surface_fit import SurfaceFitSettings
from pipeline.process.water_column import (
    add_water_column_points,
    number_returns,
    water_column_points,
)

C = constants.c
N_AIR, N_PHASE, N_GROUP = 1.000277, 1.3415, 1.3638
ALTITUDE_M, LAYER_M, BOTTOM_M = 400.0, 4.0, 10.0


def pulses(n_side=20, spacing_m=2.0, seed=3, column_every=1):
    """Pulses over flat water at z = 0, up to 20 deg off nadir, with exact surface, layer and
    bottom times from Snell's law written out here (phase index bends, group index times)."""
    rng = np.random.default_rng(seed)
    g = (np.arange(n_side) - n_side / 2) * spacing_m
    ex, ey = (a.ravel() for a in np.meshgrid(g, g))
    n = ex.size
    theta = np.radians(rng.uniform(0.0, 20.0, n))
    az = rng.uniform(0.0, 2 * np.pi, n)
    st, ct = np.sin(theta), np.cos(theta)
    d = np.column_stack([np.sin(az) * st, np.cos(az) * st, -ct])
    o = np.column_stack([ex, ey, np.zeros(n)]) - d * (ALTITUDE_M / ct)[:, None]
    cw = np.sqrt(1.0 - (N_AIR * st / N_PHASE) ** 2)
    t_s = 2.0 * N_AIR * ALTITUDE_M / ct / C
    has_c = np.arange(n) % column_every == 0
    zero = np.zeros(n)
    return DetectedReturns(
        pulse_id=np.arange(n),
        origin_meas_m=o,
        direction_meas=d,
        has_surface=np.ones(n, bool),
        t_surface_s=t_s,
        has_bottom=np.ones(n, bool),
        t_bottom_s=t_s + 2.0 * N_GROUP * BOTTOM_M / cw / C,
        surface_confidence=np.full(n, 0.95),
        bottom_confidence=np.full(n, 0.95),
        flags=np.zeros(n, np.uint16),
        has_column=has_c,
        t_column_s=np.where(has_c, t_s + 2.0 * N_GROUP * LAYER_M / cw / C, zero),
        column_confidence=np.where(has_c, 0.9, zero),
        column_amplitude=np.where(has_c, 12.0, zero),
    )


REFR = RefractionSettings(phase_index=N_PHASE, group_index=N_GROUP)
FIT = SurfaceFitSettings(air_index=N_AIR)


def _process(ret):
    done = georeference(ret, surface_settings=FIT, refraction_settings=REFR)
    return add_water_column_points(done, ret, REFR)


def test_layer_points_at_the_layer_depth_classed_64_and_numbered():
    ret = pulses(column_every=2)
    pts = _process(ret).points
    col = pts.select(pts.kind == ReturnKind.WATER_COLUMN)
    assert len(col) == int(ret.has_column.sum())
    # exact times, flat water: the refracted point is at the layer depth to rounding
    np.testing.assert_allclose(col.depth_m, LAYER_M, atol=1e-6)
    np.testing.assert_allclose(col.xyz_m[:, 2], -LAYER_M, atol=1e-6)
    assert np.all(col.classification == WATER_COLUMN)
    done = georeference(ret, surface_settings=FIT, refraction_settings=REFR)
    np.testing.assert_allclose(water_column_points(ret, done.surface, REFR).amplitude, 12.0)
    bottom = pts.select(pts.kind == ReturnKind.BOTTOM)
    assert np.all(bottom.classification == BATHYMETRIC_POINT)
    # the column point lies on the bottom point's refracted ray, 4/10 of the way down
    entry = pts.select(pts.kind == ReturnKind.SURFACE)
    with_c = np.isin(bottom.pulse_id, col.pulse_id)
    frac = (col.xyz_m - entry.xyz_m[with_c]) / (bottom.xyz_m[with_c] - entry.xyz_m[with_c])
    np.testing.assert_allclose(frac, LAYER_M / BOTTOM_M, atol=1e-6)
    # LAS numbering in time order: surface 1, column 2, bottom 3 of 3; others 1, 2 of 2
    for kind, number in ((ReturnKind.SURFACE, 1), (ReturnKind.WATER_COLUMN, 2)):
        sel = pts.select((pts.kind == kind) & np.isin(pts.pulse_id, col.pulse_id))
        assert np.all(sel.return_number == number) and np.all(sel.number_of_returns == 3)
    assert np.all(bottom.return_number[with_c] == 3) and np.all(
        bottom.number_of_returns == 2 + with_c
    )
    assert np.all(bottom.return_number[~with_c] == 2)
    surf = pts.select(pts.kind == ReturnKind.SURFACE)
    assert np.all(surf.classification == WATER_SURFACE)


def test_no_column_returns_leave_the_points_untouched():
    ret = dataclasses.replace(
        pulses(), has_column=None, t_column_s=None, column_confidence=None, column_amplitude=None
    )
    assert not ret.has_column.any()  # filled in: no column returns
    done = georeference(ret, surface_settings=FIT, refraction_settings=REFR)
    assert add_water_column_points(done, ret, REFR) is done
    assert len(water_column_points(ret, done.surface, REFR)) == 0


def test_column_points_follow_the_bottom_rules():
    ret = pulses(n_side=4)
    conf = np.array([0.9, 0.3] + [0.9] * 14)
    flags = np.zeros(16, np.uint16)
    flags[2] = 1  # MERGED: the time is not trustworthy
    ret = dataclasses.replace(ret, column_confidence=conf, flags=flags)
    done = georeference(ret, surface_settings=FIT, refraction_settings=REFR)
    col = water_column_points(ret, done.surface, REFR, ClassifySettings(min_confidence=0.5))
    assert col.classification[0] == WATER_COLUMN
    assert col.classification[1] == LOW_NOISE
    assert col.classification[2] == UNCLASSIFIED


def test_classify_water_column_kind():
    n = 4
    pts = Points(
        pulse_id=np.arange(n),
        xyz_m=np.zeros((n, 3)),
        depth_m=np.array([4.0, 4.0, -3.0, 4.0]),
        classification=np.ones(n, np.uint8),
        kind=np.full(n, ReturnKind.WATER_COLUMN, np.uint8),
        flags=np.array([0, PointFlag.GRAZING, PointFlag.LAND, 0], np.uint16),
        detector_flags=np.zeros(n, np.uint16),
        return_number=np.full(n, 2, np.uint8),
        number_of_returns=np.full(n, 3, np.uint8),
        confidence=np.array([0.9, 0.9, 0.9, 0.1]),
        uncertainty_v_m=np.zeros(n),
        uncertainty_h_m=np.zeros(n),
    )
    out = classify_points(pts)
    # water column, no valid entry, no water column over land, low confidence
    np.testing.assert_array_equal(out.classification, [64, 1, 1, 7])


def test_number_returns_orders_by_time_whatever_the_point_order():
    kinds = np.array([2, 4, 1, 2, 1, 3, 4, 1], np.uint8)  # bottom, column, surface, ...
    pid = np.array([7, 7, 7, 9, 9, 9, 11, 11])
    n = kinds.size
    pts = Points(
        pulse_id=pid,
        xyz_m=np.zeros((n, 3)),
        depth_m=np.zeros(n),
        classification=np.ones(n, np.uint8),
        kind=kinds,
        flags=np.zeros(n, np.uint16),
        detector_flags=np.zeros(n, np.uint16),
        return_number=np.full(n, 9, np.uint8),
        number_of_returns=np.full(n, 9, np.uint8),
        confidence=np.ones(n),
        uncertainty_v_m=np.zeros(n),
        uncertainty_h_m=np.zeros(n),
    )
    out = number_returns(pts)
    # pulse 7: surface 1, column 2, bottom 3 of 3; pulse 9 has no column: untouched;
    # pulse 11: surface 1, column 2 of 2
    np.testing.assert_array_equal(out.return_number, [3, 2, 1, 9, 9, 9, 2, 1])
    np.testing.assert_array_equal(out.number_of_returns, [3, 3, 3, 9, 9, 9, 2, 2])


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"t_column_s": "surface"}, "`t_column_s` must be > `t_surface_s`"),
        ({"t_column_s": "bottom"}, "`t_column_s` must be < `t_bottom_s`"),
        ({"column_confidence": 1.5}, r"`column_confidence` must be in \[0, 1\]"),
        ({"column_amplitude": -1.0}, "`column_amplitude` must be >= 0"),
        ({"has_column": "none"}, "`t_column_s` and `column_confidence` must be 0 where"),
    ],
)
def test_detected_returns_check_the_column_fields(change, match):
    ret = pulses(n_side=2)
    kw = {f.name: getattr(ret, f.name) for f in dataclasses.fields(ret)}
    ((key, value),) = change.items()
    if value == "surface":
        value = ret.t_surface_s
    elif value == "bottom":
        value = ret.t_bottom_s + 1e-12
    elif value == "none":
        value = np.zeros(4, bool)
    else:
        value = np.full(4, value)
    kw[key] = value
    with pytest.raises(ValueError, match=match):
        DetectedReturns(**kw)
