"""The sea's correlation at a lag, measured from surface points, against analytic waves."""

from types import SimpleNamespace

import numpy as np
import pytest

from pipeline.process.sea_correlation import sea_correlation


def _survey(height_m, x_m, t_s, pulse_id=None):
    """Surface points along x on a flat fitted plane z = 0 (every pulse's plane)."""
    n = x_m.size
    pts = np.column_stack([x_m, np.zeros(n), height_m])
    surface = SimpleNamespace(
        is_water=np.ones(n, bool),
        flags=np.zeros(n, np.uint16),
        surface_point_m=pts,
        surface_z_m=lambda index, x, y: np.zeros(np.shape(x)),
        global_z_m=lambda x, y: np.zeros(np.shape(x)),
    )
    returns = SimpleNamespace(
        has_surface=np.ones(n, bool),
        t_emit_s=t_s,
        pulse_id=np.arange(n) if pulse_id is None else pulse_id,
    )
    return returns, surface


def test_a_travelling_sinusoid_gives_the_cosine_of_the_lag():
    # a 30 m wave, 0.4 m amplitude, moving at 6.8 m/s, seen by 0.05 m spaced shots every 1 ms
    # while the aircraft moves 50 m/s, plus 5 cm ranging noise: the heights above the plane
    # at lag h correlate as cos(k h) (over the pairs' short times the wave moves < 0.2 m)
    rng = np.random.default_rng(3)
    n = 20000
    t = np.arange(n) * 1e-3
    x = 50.0 * t + rng.uniform(-0.5, 0.5, n)
    k, omega = 2 * np.pi / 30.0, 2 * np.pi / 30.0 * 6.8
    z = 0.4 * np.cos(k * x - omega * t) + rng.normal(0, 0.05, n)
    corr = sea_correlation(*_survey(z, x, t), max_dt_s=0.2)
    assert corr.pairs > 1000
    lag = np.array([1.0, 3.0, 5.0])
    # the wave moves omega / k * dt while the pairs are dt apart: at most 6.8 x 0.2 s, but the
    # lag bins mix it; the analytic correlation is cos(k (h - c dt)) averaged over the pairs,
    # within 0.03 of cos(k h) at these lags (dt = h / 50 m/s: c dt = 0.136 h)
    expected = np.cos(k * lag * (1 - 6.8 / 50.0)) / np.cos(k * corr.lag_m[0] * (1 - 6.8 / 50.0))
    assert corr.at(lag) == pytest.approx(expected, abs=0.03)
    assert corr.at(0.0) == 1.0


def test_noise_alone_tells_no_sea():
    rng = np.random.default_rng(4)
    n = 20000
    t = np.arange(n) * 1e-3
    x = 50.0 * t
    corr = sea_correlation(*_survey(rng.normal(0, 0.05, n), x, t), max_dt_s=0.2)
    assert np.all(corr.at(np.array([0.1, 1.0, 5.0])) == 0.0)


def test_pulses_of_one_window_are_not_paired():
    # photon counting: 100 shots share one detection; heights identical within a window and
    # independent between windows: without the grouping the short lags would read rho = 1
    rng = np.random.default_rng(5)
    n = 20000
    t = np.arange(n) * 1e-3
    x = 50.0 * t
    z = np.repeat(rng.normal(0, 0.1, n // 100), 100)
    pid = np.arange(n)
    grouped = sea_correlation(*_survey(z, x, t, pid), max_dt_s=0.2, group=pid // 100)
    assert np.all(grouped.at(np.array([0.5, 1.0, 3.0])) == 0.0)


def test_too_few_surface_points_leave_the_plane_alone():
    corr = sea_correlation(*_survey(np.zeros(1), np.zeros(1), np.zeros(1)), max_dt_s=0.2)
    assert corr.pairs == 0 and corr.at(np.array([0.0, 2.0])).tolist() == [0.0, 0.0]


def test_reduced_pairs_are_the_pairs_block_by_block(monkeypatch):
    """The pairs reduced block by block (small blocks, several threads' worth) are, once
    concatenated, exactly the pairs made at once: the same rows, heights, lags and rises in
    the same order, whatever the block size; no pair without two points."""
    import pipeline.process.sea_correlation as sc

    rng = np.random.default_rng(8)
    n = 3000
    t = np.arange(n) * 1e-3
    x = 50.0 * t + rng.uniform(-0.5, 0.5, n)
    z = 0.3 * np.sin(2 * np.pi * x / 20.0) + rng.normal(0, 0.05, n)
    ret, surf = _survey(z, x, t)
    whole = sc.surface_pairs(ret, surf, max_dt_s=0.2)
    assert whole.row_i.size > 3 * 1000

    def keep(p):
        return p.row_i, p.row_j, p.s_i_m, p.s_j_m, p.lag_m, p.rise_m

    for block in (1000, 4096, 10**7):
        monkeypatch.setattr(sc, "_PAIR_BLOCK", block)
        n_pairs, got = sc.reduced_surface_pairs(ret, surf, keep, max_dt_s=0.2)
        assert n_pairs == whole.row_i.size
        for a, b in zip(got, keep(whole), strict=True):
            np.testing.assert_array_equal(a, b)
    one = _survey(z[:1], x[:1], t[:1])
    assert sc.reduced_surface_pairs(*one, keep, max_dt_s=0.2) is None
