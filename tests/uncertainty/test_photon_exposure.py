"""The live exposure weighted by where the light falls: piled-up echoes timed right.

The truth is drawn in the tests: Gaussian echoes at known times, photons per shot, the
non-paralyzable dead time applied shot by shot (:func:`_record` of the posterior's tests).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.special import ndtr

from pipeline.process.photon_livetime import bin_live_fraction
from pipeline.uncertainty.photon_exposure import (
    ReferenceRate,
    reference_rate,
    weighted_live_fraction,
)
from tests.uncertainty.test_photon_posterior import DEAD_S, SIGMA_S, _kept, _posterior, _record

DT = 0.667e-9  # a 0.1 m height bin at nadir


def _draw_echo(rng, n_shots, pe, t_true, bg_per_ns=0.0):
    """First-photon events of one echo (and a background) with the dead time, per shot."""
    times = []
    for _ in range(n_shots):
        t = t_true + SIGMA_S * rng.standard_normal(rng.poisson(pe))
        t = np.sort(np.concatenate([t, rng.uniform(-20e-9, 20e-9, rng.poisson(bg_per_ns * 40))]))
        last = -np.inf
        for x in t:
            if x >= last + DEAD_S:
                times.append(x)
                last = x
    return np.array(times)


def _binned_ml_time(y, live, edges, t_guess):
    """The echo time of the binned Poisson law ``y ~ Poisson(L_j mu_j)``, areas profiled."""

    def nll(tc_ns):
        tc = tc_ns * 1e-9  # the minimiser's tolerances are absolute: work in ns
        shape = ndtr((edges[1:] - tc) / SIGMA_S) - ndtr((edges[:-1] - tc) / SIGMA_S)
        # the area's maximum-likelihood value given the time, in closed form
        area = y.sum() / max(float(np.sum(live * shape)), 1e-300)
        lam = np.maximum(live * area * shape, 1e-300)
        return float(np.sum(lam - y * np.log(lam)))

    g = t_guess * 1e9
    fit = minimize_scalar(nll, bounds=(g - 1.0, g + 1.0), method="bounded", options={"xatol": 1e-5})
    return fit.x * 1e-9


def test_a_uniform_reference_gives_the_plain_live_share():
    rng = np.random.default_rng(3)
    t_ev = np.sort(rng.uniform(0.0, 30e-9, 400))
    dead = np.full(t_ev.size, DEAD_S)
    m, t0, n_live = 50, 0.0, 120
    ref = ReferenceRate.uniform()
    got = weighted_live_fraction(t_ev, dead, t0, DT, m, n_live, ref)
    # the same events as heights on a nadir beam (1 m of height per 2/c of time, any scale):
    # time sample j is height bin m - 1 - j, both centred on t0 + j dt
    scale = DT  # seconds per metre: a bin of 1 m
    z = -t_ev / scale
    plain = bin_live_fraction(
        np.zeros(z.size, dtype=np.int64), z, dead / scale, -(t0 + (m - 0.5) * DT) / scale,
        DT / scale, m, np.array([n_live]),
    )[0, ::-1]  # fmt: skip
    # the plain share floors at 0.02, the weighted one only at MIN_WEIGHTED_LIVE
    np.testing.assert_allclose(np.maximum(got, 0.02), plain, rtol=0, atol=1e-12)


def test_a_piled_up_echo_is_timed_right_with_the_weighted_share_not_the_plain_one():
    # 20 photoelectrons per shot in a 1.6 ns dead time: each shot records its first photon.
    # The plain share (floored at 0.02, as processing's rates) moves the echo early by
    # 0.04-0.19 ns; the weighted one, its reference the echo as a detector found it but 0.1 ns
    # off, kept it within 0.03 ns in each of 6 windows (2026-11-30)
    rng = np.random.default_rng(7)
    m, n_shots = 61, 1000
    edges = (np.arange(m + 1) - 0.5 - m // 2) * DT
    plain_err, weighted_err = [], []
    for _ in range(8):
        t_true = rng.uniform(-DT / 2, DT / 2)
        t_ev = _draw_echo(rng, n_shots, 20.0, t_true)
        y = np.histogram(t_ev, edges)[0].astype(np.float64)
        dead = np.full(t_ev.size, DEAD_S)
        t0 = edges[0] + DT / 2
        uniform = ReferenceRate.uniform()
        plain = np.maximum(weighted_live_fraction(t_ev, dead, t0, DT, m, n_shots, uniform), 0.02)
        ref = reference_rate(y, plain, t0, t_true + 0.1e-9, t_true + 0.1e-9, DT, SIGMA_S)
        weighted = weighted_live_fraction(t_ev, dead, t0, DT, m, n_shots, ref)
        plain_err.append(_binned_ml_time(y, plain, edges, t_true) - t_true)
        weighted_err.append(_binned_ml_time(y, weighted, edges, t_true) - t_true)
    assert np.mean(plain_err) < -0.05e-9, plain_err
    assert abs(np.mean(weighted_err)) < 0.03e-9, weighted_err


def test_the_depth_posterior_holds_under_a_bright_surface():
    """20 pe per shot at the surface: the posterior's depth covers the truth (5 m)."""
    rng = np.random.default_rng(5)
    n = 2000
    off, times, t_s, t_b = _record(rng, n, 20.0, 0.3, 0.02, DEAD_S)
    post, ch = _posterior(_kept(off, times, n, DEAD_S), t_s, t_b)
    assert ch.converged[0]
    assert abs(post["median"] - 5.0) < 2.5 * post["std"], post
    assert post["lo95"] <= 5.0 <= post["hi95"]
