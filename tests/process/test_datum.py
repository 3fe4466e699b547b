"""The grid's depths are below one datum (the mean water level), not below the waves.

Analytic truth built here: a flat seabed at ``z = -Z`` under a sinusoidal sea
``eta(x) = A sin(2 pi x / L)`` of mean level ``h``. A point's ``depth_m`` (below the local
surface, as refraction makes it) is ``eta(x) + h + Z``; the depth below the mean level is
``h + Z`` everywhere, which the grid must hold to the mm.
"""

import numpy as np
import pytest

from pipeline.process.classify import BATHYMETRIC_POINT, WATER_SURFACE
from pipeline.process.datum import DatumSettings, survey_datum
from pipeline.process.grid import grid_seabed
from pipeline.process.returns import Points

SEABED_Z_M = -10.0
LEVEL_M = 0.37  # mean water level (local z), not 0, so a datum of 0 would show
AMPLITUDE_M = 0.6
WAVELENGTH_M = 7.3  # not a multiple of the 5 m cell: per-cell means of eta differ


def _points(n_side=120):
    # a regular lattice: the surface samples are symmetric about the mean level, so their median
    # is the mean level exactly (to the sampling of the sine)
    x, y = np.meshgrid(np.linspace(0.05, 49.95, n_side), np.linspace(0.05, 49.95, n_side))
    x, y = x.ravel(), y.ravel()
    n = x.size
    eta = LEVEL_M + AMPLITUDE_M * np.sin(2.0 * np.pi * x / WAVELENGTH_M)
    xyz = np.concatenate(
        [np.column_stack([x, y, eta]), np.column_stack([x, y, np.full(n, SEABED_Z_M)])]
    )
    depth = np.concatenate([np.zeros(n), eta - SEABED_Z_M])  # below the local surface
    cls = np.concatenate([np.full(n, WATER_SURFACE), np.full(n, BATHYMETRIC_POINT)])
    m = 2 * n
    return Points(
        pulse_id=np.concatenate([np.arange(n), np.arange(n)]),
        xyz_m=xyz,
        depth_m=depth,
        classification=cls.astype(np.uint8),
        kind=np.concatenate([np.ones(n), np.full(n, 2)]).astype(np.uint8),
        flags=np.zeros(m, np.uint16),
        detector_flags=np.zeros(m, np.uint16),
        return_number=np.ones(m, np.uint8),
        number_of_returns=np.ones(m, np.uint8),
        confidence=np.ones(m),
        uncertainty_v_m=np.zeros(m),
        uncertainty_h_m=np.zeros(m),
    )


def test_grid_depth_is_flat_below_the_mean_level_under_waves():
    pts = _points()
    datum = survey_datum(pts, DatumSettings())
    assert datum.source == "surface_mean"
    assert datum.water_level_m == pytest.approx(LEVEL_M, abs=0.02)
    grid = grid_seabed(pts, 5.0, bounds_m=(0, 50, 0, 50), datum_m=datum.water_level_m)
    true_depth = LEVEL_M - SEABED_Z_M
    # the cells below the local surface would differ by up to ~0.4 m (the wave's cell means)
    assert np.nanmax(grid.depth_m) - np.nanmin(grid.depth_m) < 1e-3
    np.testing.assert_allclose(grid.depth_m, true_depth, atol=0.02)
    np.testing.assert_allclose(grid.depth_m, datum.water_level_m - SEABED_Z_M, atol=1e-9)


def test_user_water_level_wins():
    pts = _points(40)
    datum = survey_datum(pts, DatumSettings(water_level_m=1.25))
    assert (datum.water_level_m, datum.source) == (1.25, "user")
    grid = grid_seabed(pts, 5.0, bounds_m=(0, 50, 0, 50), datum_m=datum.water_level_m)
    np.testing.assert_allclose(grid.depth_m, 1.25 - SEABED_Z_M, atol=1e-9)


def test_the_local_surface_reference_carries_the_waves():
    # what the grid held before: the cell means of eta (the defect this datum removes)
    grid = grid_seabed(_points(), 5.0, bounds_m=(0, 50, 0, 50))
    assert np.nanmax(grid.depth_m) - np.nanmin(grid.depth_m) > 0.2


def test_surface_fit_outliers_still_count():
    # the crests the local surface fit rejects (classes 1/7) are water returns all the same:
    # leaving them out would put the datum in the troughs
    pts = _points()
    crest = (pts.kind == 1) & (pts.xyz_m[:, 2] > LEVEL_M + 0.5 * AMPLITUDE_M)
    cls = pts.classification.copy()
    cls[crest] = 1
    datum = survey_datum(pts.replace(classification=cls))
    assert datum.water_level_m == pytest.approx(LEVEL_M, abs=0.02)


def test_spray_and_land_do_not_move_the_datum():
    pts = _points(60)
    z = pts.xyz_m.copy()
    cls = pts.classification.copy()
    surf = np.flatnonzero(pts.kind == 1)
    z[surf[:50], 2] = LEVEL_M + 15.0  # spray / birds: high noise, far above the sea
    cls[surf[:50]] = 18
    z[surf[50:400], 2] = LEVEL_M + 3.0  # a beach: ground
    cls[surf[50:400]] = 2
    clean = survey_datum(pts.select(np.setdiff1d(np.arange(len(cls)), surf[:400])))
    datum = survey_datum(pts.replace(xyz_m=z, classification=cls))
    assert datum.water_level_m == pytest.approx(clean.water_level_m, abs=1e-9)


def test_a_survey_without_surface_returns_still_gets_a_datum():
    """Zero photons (or only ground): nothing measured the water level. The run must still
    complete; the datum is the named fallback level (the level the surface fit also falls back
    to), recorded as such, so a point at z = -3 m lies 3.25 m below a 0.25 m fallback."""
    pts = _points(n_side=4)
    bottoms = pts.select(pts.kind == 2)
    bottoms = bottoms.replace(xyz_m=bottoms.xyz_m * np.array([1.0, 1.0, 0.0]) - [0.0, 0.0, 3.0])
    datum = survey_datum(bottoms, DatumSettings(fallback_water_level_m=0.25))
    assert datum.source == "fallback" and datum.n_surface_points == 0
    grid = grid_seabed(bottoms, 5.0, bounds_m=(0, 50, 0, 50), datum_m=datum.water_level_m)
    assert np.nanmax(np.abs(grid.depth_m - 3.25)) < 1e-9
    # no point at all: the same level, and an empty grid
    empty = survey_datum(bottoms.select(np.zeros(len(bottoms), bool)), DatumSettings())
    assert empty.water_level_m == 0.0 and empty.source == "fallback"


def test_clipped_surfaces_merged_with_the_column_do_not_move_the_datum():
    # a third of the surface returns clipped into the column's plateau: timed at its leading
    # edge, 0.45 m above the true level (as at 1 m altitude); flagged CLIPPED_MERGED, class 1
    from pipeline.process.returns import DetectorFlag

    pts = _points(60)
    z, cls, df = pts.xyz_m.copy(), pts.classification.copy(), pts.detector_flags.copy()
    surf = np.flatnonzero(pts.kind == 1)[::3]
    z[surf, 2] += 0.45
    cls[surf] = 1
    df[surf] |= np.uint16(DetectorFlag.CLIPPED_MERGED | DetectorFlag.SATURATED)
    clean = survey_datum(pts.select(np.setdiff1d(np.arange(len(cls)), surf)))
    datum = survey_datum(pts.replace(xyz_m=z, classification=cls, detector_flags=df))
    assert datum.water_level_m == pytest.approx(clean.water_level_m, abs=1e-9)


def test_a_survey_whose_water_surfaces_are_all_clipped_takes_their_bound_and_says_so():
    # every water pulse clipped into its column (1 J pulses): surface returns 0.15 m above the
    # true level (the early bound), class 1, no bottom; a beach face between the level and
    # 1 m up is timed and classed 41, with nothing under it. The datum is the bounds' mean,
    # flagged "clipped_bound"; before the fix it was the beach face's mean (0.5 m, the land
    # 6 m up at first, when the beach was classed 41 too)
    from pipeline.process.returns import DetectorFlag

    pts = _points(40)
    surf = np.flatnonzero(pts.kind == 1)
    z, cls, df = pts.xyz_m.copy(), pts.classification.copy(), pts.detector_flags.copy()
    beach = surf[pts.xyz_m[surf, 0] < 10.0]
    water = np.setdiff1d(surf, beach)
    z[water, 2] = LEVEL_M + 0.15
    cls[water] = 1
    df[water] |= np.uint16(DetectorFlag.CLIPPED_MERGED | DetectorFlag.SATURATED)
    z[beach, 2] = LEVEL_M + np.linspace(0.0, 1.0, beach.size)
    # no bottom returns: the surface returns alone
    sat = pts.replace(xyz_m=z, classification=cls, detector_flags=df).select(pts.kind == 1)
    datum = survey_datum(sat)
    assert datum.source == "clipped_bound"
    assert datum.water_level_m == pytest.approx(LEVEL_M + 0.15, abs=1e-9)


def test_the_datum_is_set_by_the_surface_returns_with_water_under_them():
    # a calm sea off nadir from high up: half the pulses return only the seabed, 2-5 m down,
    # as their "surface" return (nothing under it); the other half return the sea and a
    # bottom. The datum is the sea's level, not the mean of both
    pts = _points(60)
    n = int(np.count_nonzero(pts.kind == 1))
    lone = np.flatnonzero(pts.kind == 2)[: n // 2]  # these pulses keep no bottom ...
    keep = np.setdiff1d(np.arange(len(pts.kind)), lone)
    pts = pts.select(keep)
    z = pts.xyz_m.copy()
    alone = (pts.kind == 1) & ~np.isin(pts.pulse_id, pts.pulse_id[pts.kind == 2])
    z[alone, 2] = np.linspace(-5.0, -2.0, int(alone.sum()))  # ... and a seabed echo for surface
    datum = survey_datum(pts.replace(xyz_m=z))
    assert datum.water_level_m == pytest.approx(LEVEL_M, abs=0.02)
