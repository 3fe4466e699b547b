"""The TPU floors read against chance with shared terms, against analytic coverage laws.

A scene's TPU point ``i`` carries one-sigma depth terms; shared ones take one normal draw per
scene, the others one per point. With a shared part ``s`` and an own part ``o`` (``s^2 + o^2
= 1``), a scene's coverage given its draw ``xi`` is, for many points,
``P(|s xi + o eta| <= k) = Phi((k - s xi) / o) - Phi((-k - s xi) / o)``; the chance that the
floor fails is the normal measure of the ``xi`` that put it outside its band. Written here by
quadrature, not taken from the module.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy.stats import norm

from pipeline.suite.chance_tpu import beyond_chance, simulated_tpu_failures
from pipeline.suite.generate import draw, suite_seeds
from pipeline.suite.strata import all_strata, pool_rows

N_PTS = 4000


def _row(shared_sigma: float, own_sigma: float, wind_m_s: float = 3.0):
    d = dataclasses.replace(
        draw(suite_seeds(1, "tuning")[0]),
        receiver="full_waveform",
        attenuation_per_m=0.15,
        wind_m_s=wind_m_s,
        cubes=(),
    )
    n = N_PTS
    true_d = np.full(n, 5.0)  # inside [1 m, 0.8 D_ext) with D_ext = 4.5 / 0.15 = 30 m
    arrays = {
        "pt_x_m": np.zeros(n),
        "pt_y_m": np.zeros(n),
        "pt_depth_m": true_d,
        "pt_true_depth_m": true_d,
        "pt_error_m": np.zeros(n),
        "tpu_true_depth_m": true_d,
        "tpu_error_m": np.zeros(n),
        "tpu_sigma_depth_m": np.full(n, np.hypot(shared_sigma, own_sigma)),
        "tpu_group": np.arange(n),
        # signed terms: the attitude's sign follows the geometry, so half are negative
        "tpu_term_attitude_y": np.where(np.arange(n) % 2, -1.0, 1.0) * shared_sigma,
        "tpu_term_timing_bottom": np.full(n, own_sigma),
        "nb_depth_m": np.zeros(0),
    }
    for k in ("post_true_depth_m", "post_median_m", "post_lo68_m", "post_hi68_m"):
        arrays[k] = np.zeros(0)
    for k in ("post_lo95_m", "post_hi95_m", "cell_x_m", "cell_y_m", "cell_depth_m"):
        arrays[k] = np.zeros(0)
    arrays |= {
        "post_converged": np.zeros(0, bool),
        "cell_true_depth_m": np.zeros(0),
        "cell_error_m": np.zeros(0),
        "cell_count": np.zeros(0, int),
    }
    return {"draw": d, "evaluation": {}, "arrays": arrays, "wall_s": 1.0}


def _fail_probability(s: float, o: float, k: float, lo: float, hi: float) -> float:
    """Normal measure of the draws ``xi`` whose coverage ``P(|s xi + o eta| <= k)`` misses."""
    xi = np.linspace(-8.0, 8.0, 160_001)
    cov = norm.cdf((k - s * xi) / o) - norm.cdf((-k - s * xi) / o)
    w = norm.pdf(xi) * (xi[1] - xi[0])
    return float(np.sum(w[(cov < lo) | (cov > hi)]))


@pytest.mark.parametrize("s", [0.0, 0.5, 0.8])
def test_one_scene_fails_as_often_as_its_shared_draw_says(s):
    o = float(np.sqrt(1.0 - s * s))
    rows = [_row(s, o)]
    pool = pool_rows(rows)
    got = simulated_tpu_failures(pool, rows, "tuning", n_rep=300, seed=3)
    for name, k, lo, hi in (("tpu68", 1.0, 0.64, 0.72), ("tpu95", 1.96, 0.93, 0.97)):
        strata = got[name]["strata"]
        assert strata >= 9  # 8 scene dimensions and the 3-6 m band, all the same points
        want = _fail_probability(s, o, k, lo, hi) if s > 0 else 0.0
        # 300 replicates: sd <= 0.029 of the share; the binomial scatter of 4000 points
        # (0.7 %) blurs the band's edges a little
        assert got[name]["mean"] / strata == pytest.approx(want, abs=0.08)


def test_a_fully_shared_error_fails_every_stratum():
    rows = [_row(1.0, 0.0)]
    got = simulated_tpu_failures(pool_rows(rows), rows, "tuning", n_rep=50, seed=1)
    # coverage is 0 or 1 in every replicate: never inside a band
    for name in ("tpu68", "tpu95"):
        assert got[name]["mean"] == got[name]["strata"] == got[name]["p10"]


def _coverage_given(xi: float, s: float, o: float, k: float) -> float:
    """Coverage of many points ``+-s xi + o eta`` at ``k`` sigmas (even in ``xi``)."""
    return float(norm.cdf((k - s * xi) / o) - norm.cdf((-k - s * xi) / o))


@pytest.mark.parametrize("s", [0.0, 0.5])
def test_a_strata_range_is_where_its_coverage_falls_95_percent_of_the_time(s):
    o = float(np.sqrt(1.0 - s * s))
    rows = [_row(s, o)]
    got = simulated_tpu_failures(pool_rows(rows), rows, "tuning", n_rep=2000, seed=5)
    for name, k in (("tpu68", 1.0), ("tpu95", 1.96)):
        ranges = got[name]["ranges"]
        assert len(ranges) == got[name]["strata"]
        lo, hi = ranges["all", "all"]
        p = _coverage_given(0.0, s, o, k)
        # binomial scatter of N_PTS points about the coverage a draw gives
        sd = float(np.sqrt(p * (1.0 - p) / N_PTS))
        if s == 0.0:  # no shared term: the binomial range alone
            assert lo == pytest.approx(p - 1.96 * sd, abs=0.3 * sd)
            assert hi == pytest.approx(p + 1.96 * sd, abs=0.3 * sd)
        else:
            # the coverage falls as |xi| grows: its 2.5 % quantile is the coverage at the
            # 97.5 % quantile of |xi| (normal: 2.2414); its 97.5 % one is near xi = 0, where
            # the coverage is flat and the binomial scatter sets the top
            want_lo = _coverage_given(norm.ppf(1.0 - 0.025 / 2.0), s, o, k)
            # the quantile of 2000 replicates: ~0.012 at 68 %, less at 95 %
            assert lo == pytest.approx(want_lo, abs=0.03)
            assert p - 2.0 * sd <= hi <= p + 3.0 * sd
        for key in ranges:
            assert ranges[key] == (lo, hi)  # every stratum holds the same points


@pytest.mark.parametrize(("xi", "want"), [(0.3, ""), (3.0, "low"), (None, "high")])
def test_an_observed_coverage_is_read_against_its_range(xi, want):
    s, o = 0.6, 0.8
    row = _row(s, o)
    n = N_PTS
    sign = np.where(np.arange(n) % 2, -1.0, 1.0)
    if xi is not None:  # errors drawn from the TPU's own model, the shared draw fixed at xi
        eta = np.random.default_rng(11).standard_normal(n)
        row["arrays"]["tpu_error_m"] = sign * s * xi + o * eta
    # (None: the errors are 0, every point inside its sigma: a TPU far too large)
    rows = [row]
    pool = pool_rows(rows)
    got = simulated_tpu_failures(pool, rows, "tuning", n_rep=400, seed=2)
    observed = next(x for x in all_strata(pool) if x["dimension"] == "all")["tuning"]["tpu"]
    for name, q in (("tpu68", "cov68"), ("tpu95", "cov95")):
        mark = beyond_chance(observed[q], got[name]["ranges"]["all", "all"])
        assert mark == want


def test_each_stratum_gets_the_range_of_its_own_scenes():
    """Two scenes in different wind strata, one whose error is shared through (s = 0.8), one
    whose errors are all its points' own: each wind stratum's range is its own scene's law
    (the shared draw's, the binomial), the strata holding both lie between."""
    s, o = 0.8, 0.6
    rows = [_row(s, o, wind_m_s=1.0), _row(0.0, 1.0, wind_m_s=10.0)]
    got = simulated_tpu_failures(pool_rows(rows), rows, "tuning", n_rep=2000, seed=4)
    ranges = got["tpu68"]["ranges"]
    lo_a, hi_a = ranges["wind m/s", "0-2"]
    lo_b, hi_b = ranges["wind m/s", "8-12"]
    p = _coverage_given(0.0, 0.0, 1.0, 1.0)
    sd = float(np.sqrt(p * (1.0 - p) / N_PTS))
    assert lo_b == pytest.approx(p - 1.96 * sd, abs=0.3 * sd)
    assert hi_b == pytest.approx(p + 1.96 * sd, abs=0.3 * sd)
    assert lo_a == pytest.approx(_coverage_given(norm.ppf(1.0 - 0.025 / 2.0), s, o, 1.0), abs=0.03)
    lo_all, hi_all = ranges["all", "all"]  # half the points shared: a range between the two
    assert lo_a < lo_all < lo_b and hi_b < hi_all
