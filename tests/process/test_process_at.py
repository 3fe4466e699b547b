"""Processing asked at some pulses only (a block's, issue 15): the local planes
(``fit_water_surface(planes_at=)``) and the kriged sea (``seabed_points(krige_at=)``,
``georeference``, ``no_bottom_points``) of the pulses asked are those of a run asking all, to
the bit, while every loaded echo is still a neighbour.

A moving sine sea (``tests/process/test_wave_entry.py``) shot at random points over 0.4 s,
with ranging noise and blunders on the surface times (outliers of their planes, which the
kriging leaves out), some pulses without a surface echo and some without a bottom; asked at
blocks of 97 rows.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import constants

from pipeline.process.refraction import georeference, seabed_points
from pipeline.process.returns import PointFlag
from pipeline.process.survey_wide import survey_wide
from pipeline.process.water_surface import WaterSurface
from tests.process.test_wave_entry import FIT, REFR, sine_sea_pulses
from tests.test_process_tiles import _assert_same_points

C = constants.c


def wave_survey(seed: int, n: int = 6000):
    """Pulses over a 12 m sea moving at its phase speed, 80 x 40 m, noisy surface times."""
    rng = np.random.default_rng(seed)
    lam = 12.0
    speed = np.sqrt(9.80665 * lam / (2.0 * np.pi))
    x, y = rng.uniform(0.0, 80.0, n), rng.uniform(0.0, 40.0, n)
    t = np.sort(rng.uniform(0.0, 0.4, n))
    ret, _ = sine_sea_pulses(
        0.4, lam, x - speed * t, y, theta_deg=15.0, along_x=True, seabed_z_m=-8.0
    )
    shift = np.column_stack([speed * t, np.zeros(n), np.zeros(n)])
    noise_m = rng.normal(0.0, 0.03, n)
    blunder = rng.random(n) < 0.04
    noise_m[blunder] += rng.choice([-1.0, 1.0], blunder.sum()) * rng.uniform(
        0.3, 1.5, blunder.sum()
    )
    no_surface = rng.random(n) < 0.05
    no_bottom = rng.random(n) < 0.1
    return dataclasses.replace(
        ret,
        origin_meas_m=ret.origin_meas_m + shift,
        t_emit_s=t,
        has_surface=~no_surface,
        t_surface_s=np.where(no_surface, 0.0, ret.t_surface_s + 2.0 * noise_m / C),
        surface_confidence=np.where(no_surface, 0.0, 1.0),
        has_bottom=~no_bottom,
        t_bottom_s=np.where(no_bottom, 0.0, ret.t_bottom_s),
        bottom_confidence=np.where(no_bottom, 0.0, 1.0),
    )


def blocks_of_rows(n: int, seed: int, size: int = 97) -> np.ndarray:
    """``(n,)`` bool: a random third of the blocks of ``size`` consecutive rows."""
    rng = np.random.default_rng(seed)
    block = np.arange(n) // size
    return rng.random(block.max() + 1)[block] < 1.0 / 3.0


def assert_rows_equal(got: WaterSurface, want: WaterSurface, rows: np.ndarray):
    for f in dataclasses.fields(WaterSurface):
        a, b = getattr(got, f.name), getattr(want, f.name)
        if f.name in WaterSurface.SURVEY_FIELDS or a is None or b is None:
            assert (a is None) == (b is None), f.name
            continue
        np.testing.assert_array_equal(a[rows], b[rows], err_msg=f.name)


@pytest.fixture(scope="module")
def survey():
    ret = wave_survey(5)
    wide = survey_wide(ret, surface_settings=FIT, refraction_settings=REFR)
    whole = georeference(ret, surface_settings=FIT, refraction_settings=REFR, wide=wide)
    return ret, wide, whole


def test_the_sea_is_kriged_and_has_outliers(survey):
    _, wide, whole = survey
    s = whole.surface
    assert wide.sea.covariance is not None and s.sea_field is not None
    assert np.isfinite(whole.sea_change_m).mean() > 0.5
    outliers = (s.flags & np.uint16(PointFlag.SURFACE_OUTLIER)) != 0
    assert 50 < np.count_nonzero(outliers & s.is_water) < 0.2 * len(s)


@pytest.mark.parametrize("seed", [1, 2])
def test_planes_asked_at_blocks_of_rows_are_those_of_all(survey, seed):
    from pipeline.process.surface_fit import fit_water_surface

    ret, wide, _ = survey
    whole = fit_water_surface(ret, FIT, wide.surface)
    rows = blocks_of_rows(len(ret), seed)
    got = fit_water_surface(ret, FIT, wide.surface, planes_at=rows)
    assert_rows_equal(got, whole, rows)
    # the others keep the global plane: not the survey's
    other = ~rows & whole.is_water
    assert np.any(got.normal[other] != whole.normal[other])
    np.testing.assert_array_equal(got.n_used[~rows], 0)


@pytest.mark.parametrize("seed", [3, 4])
def test_the_sea_kriged_at_blocks_of_rows_is_that_of_all(survey, seed):
    ret, _, whole = survey
    rows = blocks_of_rows(len(ret), seed)
    surface = whole.surface
    want = seabed_points(ret, surface, REFR)
    got = seabed_points(ret, surface, REFR, krige_at=rows)
    mine = np.isin(want.pulse_id, ret.pulse_id[rows])
    _assert_same_points(got.select(mine), want.select(mine))
    # the others read the plane
    plane = seabed_points(ret, surface, REFR, krige_at=np.zeros(len(ret), bool))
    np.testing.assert_array_equal(got.depth_m[~mine], plane.depth_m[~mine])
    assert np.any(plane.depth_m[~mine] != want.depth_m[~mine])


def test_georeference_asked_at_rows_and_their_kriging_reach_gives_their_points(survey):
    """Planes at every pulse within the kriging's reach of the rows (here: all), the sea kriged
    at the rows: the rows' points and held sea change are the run's asking all."""
    ret, wide, whole = survey
    rows = blocks_of_rows(len(ret), 5)
    kw = {"surface_settings": FIT, "refraction_settings": REFR, "wide": wide}
    got = georeference(ret, **kw, planes_at=np.ones(len(ret), bool), krige_at=rows)
    mine = np.isin(whole.points.pulse_id, ret.pulse_id[rows])
    _assert_same_points(got.points.select(mine), whole.points.select(mine))
    np.testing.assert_array_equal(got.sea_change_m[rows], whole.sea_change_m[rows])
    assert np.isnan(got.sea_change_m[~rows]).all()
    assert_rows_equal(got.surface, whole.surface, np.ones(len(ret), bool))


def test_asking_at_some_pulses_needs_the_survey_wide_figures(survey):
    ret, _, _ = survey
    with pytest.raises(ValueError, match="survey-wide"):
        georeference(ret, surface_settings=FIT, krige_at=np.ones(len(ret), bool))


def test_class45_points_kriged_at_blocks_of_rows_are_those_of_all():
    from types import SimpleNamespace

    from pipeline.process.survey_points import no_bottom_points

    ret = wave_survey(7)
    wide = survey_wide(ret, surface_settings=FIT, refraction_settings=REFR)
    proc = georeference(ret, surface_settings=FIT, refraction_settings=REFR, wide=wide)
    ins = SimpleNamespace(window_s=400e-9, pre_trigger_s=50e-9)
    ctx = SimpleNamespace(instrument=ins, refraction=REFR)
    want = no_bottom_points(ret, proc, ctx)
    rows = blocks_of_rows(len(ret), 8)
    got = no_bottom_points(ret, proc, ctx, krige_at=rows)
    mine = np.isin(want.pulse_id, ret.pulse_id[rows])
    assert mine.sum() > 50
    _assert_same_points(got.select(mine), want.select(mine))
    plane = no_bottom_points(ret, proc, ctx, krige_at=np.zeros(len(ret), bool))
    assert np.any(plane.depth_m[mine] != want.depth_m[mine])


def test_a_strip_needs_its_kriging_reach_of_planes_around_it(survey):
    """A block's strip (x in [30, 50] m): the sea kriged at its pulses, the local planes
    within a beam reach and the kriging's allowance (the surface fit's ``radius_m``) of it
    (:func:`~pipeline.survey_block_reach.processing_rows`): its points are the whole run's.
    With the planes at the strip alone they are not: its edges' soundings are kriged from
    echoes outside it whose planes were not fitted, so whose blunders are not left out."""
    from pipeline.survey_block_reach import processing_rows

    ret, wide, whole = survey
    pos = (
        ret.origin_meas_m[:, :2]
        + ret.direction_meas[:, :2] * (C * ret.t_surface_s / (2.0 * FIT.air_index))[:, None]
    )
    pos = np.where(ret.has_surface[:, None], pos, whole.surface.entry_m[:, :2])
    # the beam reach: from a pulse's position to its entry and its sounding (15° off nadir)
    pts = whole.points
    at = np.searchsorted(ret.pulse_id, pts.pulse_id)
    beam = float(np.max(np.hypot(*(pts.xyz_m[:, :2] - pos[at]).T)))
    assert 1.0 < beam < 5.0
    box = (30.0, 50.0, -1e9, 1e9)
    strip = processing_rows(pos, np.zeros(len(ret), bool), box, 0.0)
    planes = processing_rows(pos, strip, box, beam + FIT.radius_m)
    kw = {"surface_settings": FIT, "refraction_settings": REFR, "wide": wide}
    mine = np.isin(pts.pulse_id, ret.pulse_id[strip])
    want = pts.select(mine)
    got = georeference(ret, **kw, planes_at=planes, krige_at=strip).points
    _assert_same_points(got.select(mine), want)
    alone = georeference(ret, **kw, planes_at=strip, krige_at=strip).points.select(mine)
    assert np.any(alone.depth_m != want.depth_m)
