"""The global water plane stays level where the points' spread cannot tell tilt from waves."""

import numpy as np
import pytest

from pipeline.process.surface_land import global_plane
from pipeline.process.surface_settings import SurfaceFitSettings


def test_a_profiler_track_over_waves_does_not_tilt_the_sea():
    # a nadir profiler's water-surface points: 57 m along y, the roll wandering the track
    # across x over 7 m, under a 0.15 m sea whose sampled heights happen to rise 5 cm per metre
    # across (the waves met where the roll put the beam: chance, not a sloping sea; the
    # unregularised fit tilts the plane by 2.9 degrees, as on suite seed 9008, where 9 degrees
    # across bent every beam 1 m sideways on an 18-degree slope). The sea is level
    rng = np.random.default_rng(11)
    n = 2500
    y = np.linspace(0.0, 57.0, n)
    x = rng.uniform(-10.5, -3.5, n)
    z = 0.05 * (x + 7.0) + rng.normal(0, 0.15, n)
    plane, _ = global_plane(np.column_stack([x, y, z]), SurfaceFitSettings())
    assert abs(plane[1]) < 2e-3 and abs(plane[2]) < 2e-3
    # without the prior (a loose one) the same points tilt it by several degrees
    loose, _ = global_plane(
        np.column_stack([x, y, z]), SurfaceFitSettings(global_tilt_prior_rad=1.0)
    )
    assert abs(loose[1]) > 0.04


def test_a_survey_wide_sea_tilt_is_still_measured():
    # a 1 km x 1 km cloud of surface points on a plane tilted 3e-4 (30 cm per km, three times
    # the prior's sigma) with 0.1 m of waves: the data pin the tilt to ~1e-6, far inside the
    # prior, and the fit keeps it
    rng = np.random.default_rng(12)
    n = 100_000
    x, y = rng.uniform(-500, 500, n), rng.uniform(-500, 500, n)
    z = 0.2 + 3e-4 * x - 1e-4 * y + rng.normal(0, 0.1, n)
    plane, _ = global_plane(np.column_stack([x, y, z]), SurfaceFitSettings())
    assert plane[1] == pytest.approx(3e-4, abs=5e-6)
    assert plane[2] == pytest.approx(-1e-4, abs=5e-6)
