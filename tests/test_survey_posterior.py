"""The bounded sample of pulses whose depth posteriors ``bathy run`` samples."""

import numpy as np

from pipeline.uncertainty.posterior_selection import choose_points, kept_for_posterior


def test_kept_share_matches_the_fraction_and_ignores_chunking():
    ids = np.arange(200_000, dtype=np.int64)
    keep = kept_for_posterior(ids, 0.01, seed=3)
    # binomial sigma of the count: sqrt(2000 * 0.99) = 44.5; the Weyl hash is even more even
    assert abs(int(keep.sum()) - 2000) < 4 * 44.5
    # chunk by chunk (any split) keeps the same pulses: the choice depends on the id alone
    parts = np.concatenate([kept_for_posterior(c, 0.01, seed=3) for c in np.split(ids, [7, 9999])])
    np.testing.assert_array_equal(parts, keep)
    # spread over the survey: every tenth of it holds about a tenth of the kept pulses
    per_tenth = np.add.reduceat(keep, np.arange(0, ids.size, ids.size // 10))
    assert np.all(np.abs(per_tenth - 200) < 4 * np.sqrt(200))
    assert not kept_for_posterior(ids, 0.0, seed=3).any()
    assert kept_for_posterior(ids[:50], 1.0, seed=3).all()


def test_choose_points_takes_the_cells_that_matter_first_and_stays_bounded():
    cand = np.arange(0, 1000, 2)  # waveforms kept for the even points
    preferred = np.array([3, 10, 12, 500, 998])  # 3 has no waveform
    sel = choose_points(cand, preferred, 20, seed=1)
    assert sel.size == 20 and np.all(np.diff(sel) > 0)
    assert {10, 12, 500, 998} <= set(sel.tolist()) and 3 not in sel
    assert np.all(np.isin(sel, cand))
    # the rest spread over the candidates, not bunched at the start
    rest = np.setdiff1d(sel, preferred)
    assert rest.max() - rest.min() > 800
    # more preferred than wanted: a seeded choice among them only
    many = choose_points(cand, cand, 7, seed=2)
    assert many.size == 7 and np.array_equal(many, choose_points(cand, cand, 7, seed=2))
    assert choose_points(cand, preferred, 0, seed=1).size == 0


def test_posterior_budget_is_per_km2_with_a_floor():
    import dataclasses

    from pipeline.process.settings import ProcessSettings
    from pipeline.scene import load_scene
    from pipeline.uncertainty.posterior_selection import posterior_budget

    from .conftest import ROOT

    defaults = ProcessSettings()
    assert defaults.posterior_pulses_per_km2 == 2000.0 and defaults.posterior_min_pulses == 48
    scene = load_scene(ROOT / "pipeline" / "scenes" / "default.toml")
    assert scene.process.posterior_pulses_per_km2 == 0.0  # the demo: the minimum only
    ps = dataclasses.replace(scene.process, posterior_pulses_per_km2=2000.0)
    assert posterior_budget(ps, 1.0) == 2000  # photon counting: windows, the same numbers
    assert posterior_budget(ps, 0.01) == 48  # 20 by density: the floor
    none = dataclasses.replace(ps, posterior_pulses_per_km2=0.0, posterior_min_pulses=0)
    assert posterior_budget(none, 1.0) == 0
