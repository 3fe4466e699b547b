"""Process-side waveform model and the emcee depth posterior.

References: the closed-form column against a slow formula and a brute-force convolution, the
noise laws against their moments, the Fisher information against the score's covariance.
Statistical (seeded): simulation-based calibration of the 68 % / 95 % intervals over 120
pulses drawn from the model and its noise law (the 500-pulse table is in
``benchmarks/RESULTS_posterior.md``), posterior sigma vs the Cramér–Rao bound, and the
refracted 3-D posterior against the analytic seabed point. The sampler itself against a
posterior known in closed form (a Gaussian target): the chains it calls converged reproduce
its mean and covariance.
"""

import dataclasses
import hashlib
import math
import pickle

import numpy as np
import pytest
from scipy import constants, stats
from scipy.signal import fftconvolve
from scipy.special import log_ndtr, ndtr

from pipeline.errors import NumericalError, SceneError
from pipeline.process.refraction import RefractionSettings
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_fit import SurfaceFitSettings, fit_water_surface
from pipeline.uncertainty.posterior import (
    PosteriorFlag,
    PosteriorSettings,
    interval_summary,
    log_prob,
    log_prob_blocks,
    make_pulse_batch,
    sample_batch,
    start_theta,
)
from pipeline.uncertainty.seabed_posterior import (
    draws_to_seabed,
    draws_to_seabed_rows,
    seabed_posteriors,
    water_cosine,
)
from pipeline.uncertainty.waveform_information import (
    depth_crb_m,
    fisher_information,
    score,
)
from pipeline.uncertainty.waveform_model import (
    N_PARAMS,
    WaveformSystem,
    draw_waveform,
    expected_waveform,
    in_water_delay_s,
    noise_variance,
)

C = constants.c
N_G = 1.3638
FW = WaveformSystem(
    sample_interval_s=1e-9,
    pulse_fwhm_s=3e-9,
    counts_per_photoelectron=5.0,
    excess_noise_factor=1.3,
    electronic_noise_counts=2.0,
    offset_counts=100.0,
)
PC = WaveformSystem(sample_interval_s=1e-9, pulse_fwhm_s=3e-9, receiver="photon_counting")
# the production rules (tau_factor, acceptance range, the restart); at most 4000 steps
FAST = PosteriorSettings(max_steps=4000)


def theta(depth=4.0, t_ns=10.0, a_s=2000.0, a_c=600.0, a_b=800.0, k=0.2, bg=4.0, lw=0.0, lws=0.0):
    return np.array(
        [depth, t_ns, math.log(a_s), math.log(a_c), math.log(a_b), math.log(k), bg, lw, lws]
    )


def window(th, dt=1e-9, cos_w=1.0, after_ns=12.0):
    """Samples covering the surface, the column and the bottom plus a tail."""
    return int(math.ceil((th[1] * 1e-9 + in_water_delay_s(th[0], cos_w, N_G)) / dt + after_ns))


def slow_model(th, m, system, cos_w=1.0):
    """The same model written out plainly: no bands, the simulator's log_ndtr form of psi."""
    dt, s = system.sample_interval_s, system.pulse_sigma_s
    depth, t_ns, la_s, la_c, la_b, lk, bg, lw, lws = th
    t_s = t_ns * 1e-9
    s_b, s_s = s * math.exp(lw), s * math.exp(lws)
    r = math.exp(lk) * C / system.group_index
    tau = 2.0 * system.group_index * depth / (C * cos_w)
    edges = (np.arange(m + 1) - 0.5) * dt

    def cdf(u):
        return ndtr(u / s) - np.exp(-r * u + 0.5 * (r * s) ** 2 + log_ndtr(u / s - r * s))

    cum = cdf(edges - t_s) - math.exp(-r * tau) * cdf(edges - t_s - tau)
    column = math.exp(la_c) / (1.0 - math.exp(-r * tau)) * np.diff(cum)
    surface = math.exp(la_s) * np.diff(ndtr((edges - t_s) / s_s))
    bottom = math.exp(la_b) * np.diff(ndtr((edges - t_s - tau) / s_b))
    return system.offset_counts + bg + surface + column + bottom


# --- the waveform model: references ----------------------------------------------------------
@pytest.mark.parametrize("depth", [0.01, 1.0, 2.5, 8.0])  # bands overlapping, touching, apart
@pytest.mark.parametrize("k", [0.005, 0.2, 5.0])
@pytest.mark.parametrize("fwhm", [1e-9, 3e-9, 8e-9])
@pytest.mark.parametrize("lw", [0.0, 1.5])
def test_model_matches_the_plain_formula(depth, k, fwhm, lw):
    system = WaveformSystem(sample_interval_s=1e-9, pulse_fwhm_s=fwhm, electronic_noise_counts=1.0)
    th = theta(depth=depth, t_ns=40.3, k=k, lw=lw, lws=0.5 * lw)
    m = window(th, after_ns=60.0)
    fast = expected_waveform(th, m, system)
    ref = slow_model(th, m, system)
    # the bands drop terms below exp(-8.5²/2) = 2e-16 of the areas: float64 rounding level
    np.testing.assert_allclose(fast, ref, rtol=0, atol=1e-9 * np.max(ref - system.offset_counts))


def test_column_is_an_exponential_blurred_by_the_pulse():
    """Brute force: exp(-r x) on [0, tau] on a 1 ps grid, convolved, integrated over bins."""
    th = theta(depth=3.0, t_ns=20.0, a_s=1e-300, a_b=1e-300, bg=0.0)
    th[2] = th[4] = -700.0  # no surface or bottom return
    system = WaveformSystem(sample_interval_s=1e-9, pulse_fwhm_s=3e-9, electronic_noise_counts=1)
    m = 80
    model = expected_waveform(th, m, system)
    s, r = system.pulse_sigma_s, 0.2 * C / N_G
    tau = in_water_delay_s(3.0, 1.0, N_G)
    step = 1e-12
    t = np.arange(-20e-9, 100e-9, step)
    x = t - 20e-9
    col = np.where((x >= 0) & (x <= tau), np.exp(-r * x), 0.0)
    k = np.arange(-10 * s, 10 * s, step)
    g = np.exp(-0.5 * (k / s) ** 2)
    blurred = fftconvolve(col, g / g.sum(), mode="same")
    cum = np.cumsum(blurred) * step
    edges = (np.arange(m + 1) - 0.5) * 1e-9
    brute = np.diff(np.interp(edges, t, cum))
    brute *= 600.0 / brute.sum()  # normalised to the column's total
    # a 1 ps grid: relative error ~ step / sigma
    np.testing.assert_allclose(model, brute, atol=2e-3 * brute.max())


def test_areas_add_up_to_the_counts():
    th = theta(depth=5.0, t_ns=30.0)
    m = window(th, after_ns=80.0)
    mu = expected_waveform(th, m, FW)
    total = np.sum(mu - FW.offset_counts - 4.0)
    # every return is normalised to its area; bin integrals telescope
    assert total == pytest.approx(2000.0 + 600.0 + 800.0, rel=1e-9)


def test_model_is_vectorised_over_walkers():
    rng = np.random.default_rng(0)
    th = theta() + rng.normal(0, 0.05, (6, N_PARAMS))
    cw = rng.uniform(0.8, 1.0, 6)
    rows = expected_waveform(th, 70, FW, cw)
    for i in range(6):
        # a batch's bands are as wide as its widest echo: terms beyond 8.5 sigma (< 2e-16 of
        # the areas, ~3400 counts) may differ
        one = expected_waveform(th[i], 70, FW, cw[i])
        np.testing.assert_allclose(rows[i], one, rtol=0, atol=1e-15 * 3400 * 100)


@pytest.mark.parametrize(
    "th",
    [
        theta(depth=0.01, k=5.0),  # shallowest, strongest attenuation
        theta(depth=0.01, k=0.005),
        theta(depth=9.0, t_ns=0.0, k=0.005),  # surface on the first sample
        theta(depth=9.0, t_ns=0.0, a_s=1e-3, a_c=1e-3, a_b=1e9, bg=0.0),
    ],
)
def test_extreme_parameters_stay_finite(th):
    mu = expected_waveform(th, 100, FW)  # RuntimeWarnings are errors here
    assert np.all(np.isfinite(mu)) and np.all(mu >= FW.offset_counts - 1e-9)


def test_gaussian_noise_law_moments():
    th = theta()
    m = window(th)
    mu = expected_waveform(th, m, FW)
    draws = draw_waveform(np.tile(th, (20000, 1)), m, FW, np.random.default_rng(1))
    var = 4.0 + 1.0 / 12.0 + 1.3 * 5.0 * (mu - 100.0)
    np.testing.assert_allclose(noise_variance(mu, FW), var, rtol=1e-12)
    # 20000 draws: the sample variance is within 3 % (6 sigma of its 1 % spread)
    np.testing.assert_allclose(draws.var(axis=0), var, rtol=0.03)
    assert np.all(np.abs(draws.mean(axis=0) - mu) <= 6 * np.sqrt(var / 20000))


def test_poisson_noise_law_moments():
    th = theta(a_s=300.0, a_c=100.0, a_b=80.0, bg=0.3)
    m = window(th)
    draws = draw_waveform(np.tile(th, (20000, 1)), m, PC, np.random.default_rng(2))
    mu = expected_waveform(th, m, PC)
    assert np.all(draws == np.round(draws))
    assert np.all(np.abs(draws.mean(axis=0) - mu) <= 6 * np.sqrt(mu / 20000))
    np.testing.assert_allclose(draws.var(axis=0), mu, rtol=0.06, atol=0.01)


@pytest.mark.parametrize(
    "system",
    [FW, PC, dataclasses.replace(FW, surface_misfit=0.15)],
    ids=["gaussian", "poisson", "gaussian-surface-misfit"],
)
def test_fisher_information_is_the_covariance_of_the_score(system):
    th = theta(a_s=800.0, a_c=300.0, a_b=300.0, bg=0.5)
    m = window(th)
    n = 3000
    y = draw_waveform(np.tile(th, (n, 1)), m, system, np.random.default_rng(3))
    _, grad, _ = score(y, np.tile(th, (n, 1)), system)
    info = fisher_information(th, m, system)
    emp = np.cov(grad, rowvar=False)
    # 3000 draws: sample variances within ~2.6 % (1 sigma); 12 % is 4.5 sigma
    np.testing.assert_allclose(np.diag(emp), np.diag(info), rtol=0.12)
    assert np.all(np.abs(grad.mean(axis=0)) < 5 * np.sqrt(np.diag(info) / n))


def test_full_waveform_needs_some_signal_free_noise():
    with pytest.raises(SceneError, match="electronic_noise_counts"):
        WaveformSystem(sample_interval_s=1e-9, pulse_fwhm_s=3e-9, quantisation_step_counts=0.0)


# --- log_prob -------------------------------------------------------------------------------
def test_log_prob_prior_box_nan_and_pickle():
    th = theta()
    m = window(th)
    y = draw_waveform(th, m, FW, np.random.default_rng(4))
    data = make_pulse_batch(y, FW)
    lp = log_prob(th, data, FW)
    assert np.isfinite(lp)
    walkers = np.tile(th, (4, 1))
    walkers[1, 0] = -1.0  # negative depth
    walkers[2, 5] = math.log(50.0)  # attenuation above its bound
    walkers[3, 0] = 50.0  # bottom after the window
    out = log_prob(walkers, data, FW)
    assert out[0] == pytest.approx(lp, rel=1e-12) and np.all(np.isneginf(out[1:]))
    blocks = log_prob_blocks(walkers, data, FW)
    np.testing.assert_array_equal(blocks[:, 0], out)
    with pytest.raises(NumericalError, match="NaN"):
        log_prob(np.where(np.arange(N_PARAMS) == 3, np.nan, th), data, FW)
    with pytest.raises(NumericalError, match="finite"):
        make_pulse_batch(np.where(np.arange(m) == 5, np.nan, y), FW)
    f, d, s = pickle.loads(pickle.dumps((log_prob, data, FW)))
    assert f(th, d, s) == lp


def test_settings_are_checked():
    with pytest.raises(ValueError, match="depth_bounds_m"):
        PosteriorSettings(depth_bounds_m=(5.0, 1.0))
    with pytest.raises(ValueError, match="cos_water"):
        make_pulse_batch(np.zeros(20), FW, cos_water=0.0)


def test_start_is_the_detectors_estimate():
    th = theta(depth=5.0, t_ns=15.0)
    m = window(th)
    y = draw_waveform(th, m, FW, np.random.default_rng(5))
    start = start_theta(y, FW)
    # the detector times to a fraction of a sample: depth within ~ 0.2 ns c / (2 n_g) = 2 cm
    assert abs(start[0] - 5.0) < 0.05 and abs(start[1] - 15.0) < 0.3
    assert start_theta(np.full(m, 100.0) + np.random.default_rng(6).normal(0, 2, m), FW) is None


# --- the sampler: statistics ----------------------------------------------------------------
def draw_truths(n, rng, *, pc=False):
    """Known parameters over a range of depths and SNR, and their noisy waveforms."""
    depth = rng.uniform(1.0, 6.0, n)
    t_ns = 10.0 + rng.uniform(0.0, 1.0, n)
    if pc:  # photon counting: tens to hundreds of photons per return
        areas = np.exp(rng.uniform(np.log([150, 60, 40]), np.log([800, 300, 300]), (n, 3)))
        bg = rng.uniform(0.02, 0.3, n)
    else:
        areas = np.exp(rng.uniform(np.log([500, 100, 150]), np.log([5000, 2000, 3000]), (n, 3)))
        bg = rng.uniform(0.5, 10.0, n)
    k = np.exp(rng.uniform(np.log(0.08), np.log(0.5), n))
    # bottom echoes from the system response alone up to twice its width (pulse stretching)
    lw = np.log(rng.uniform(1.0, 2.0, n))
    lws = np.log(rng.uniform(1.0, 1.3, n))  # surface echo widened by the footprint
    th = np.column_stack([depth, t_ns, np.log(areas), np.log(k), bg, lw, lws])
    system = PC if pc else FW
    waves = [draw_waveform(t, window(t), system, rng) for t in th]
    return th, waves


def binomial_band(n, p, alpha=1e-3):
    """Two-sided (1 - alpha) range of a binomial fraction: a miscalibrated sampler fails it."""
    return stats.binom.ppf(alpha / 2, n, p) / n, stats.binom.ppf(1 - alpha / 2, n, p) / n


CRB_FW = theta(depth=4.0, a_s=2000, a_c=500, a_b=1200)
CRB_PC = theta(depth=4.0, a_s=1000, a_c=1000, a_b=400, bg=0.5)


@pytest.fixture(scope="module")
def fw_batch():
    """One sampler run: 120 calibration pulses and 8 realisations of the CRB pulse."""
    rng = np.random.default_rng(11)
    th, waves = draw_truths(120, rng)
    crb_rng = np.random.default_rng(21)
    waves += [draw_waveform(CRB_FW, window(CRB_FW), FW, crb_rng) for _ in range(8)]
    hashes = [hashlib.sha1(w.tobytes()).hexdigest() for w in waves]
    chains = sample_batch(waves, FW, FAST, seed=1)
    assert [hashlib.sha1(w.tobytes()).hexdigest() for w in waves] == hashes  # inputs kept
    return th, chains


@pytest.mark.slow
def test_intervals_are_calibrated(fw_batch):
    """Simulation-based calibration over 120 pulses (the 500-pulse run is the benchmark)."""
    th, all_chains = fw_batch
    draws = all_chains.draws[:120]
    s = interval_summary(draws[:, :, 0], axis=1)
    d = th[:, 0]
    cover95 = np.mean((s["lo95"] <= d) & (d <= s["hi95"]))
    cover68 = np.mean((s["lo68"] <= d) & (d <= s["hi68"]))
    lo95, hi95 = binomial_band(120, 0.95)  # [0.875, 1.0]
    lo68, hi68 = binomial_band(120, 0.68)  # [0.533, 0.817]
    assert lo95 <= cover95 <= hi95, cover95
    assert lo68 <= cover68 <= hi68, cover68
    # the normalised errors are standard normal: median 0 and spread 1 (120 draws: sigma of
    # the median 0.11, of the normalised MAD ~0.1; bounds at ~3 sigma). The MAD, not the
    # standard deviation: a flagged chain stuck a few sigma out must not dominate the check
    z = (s["median"] - d) / s["std"]
    mad = 1.4826 * np.median(np.abs(z - np.median(z)))
    assert abs(np.median(z)) < 0.35 and abs(mad - 1.0) < 0.3, (np.median(z), mad)
    # weak water columns (log k barely constrained) and the free bottom width mix slowly:
    # those are flagged, not hidden; 67-80 % converge within 2500 steps in this set
    assert np.mean(all_chains.converged[:120]) >= 0.6


def gaussian_target(monkeypatch, waves, means, covs):
    """Make each pulse's log posterior ``-(x - m)' C^-1 (x - m) / 2`` (``means``, ``covs``: one
    per waveform of ``waves``): a Gaussian likelihood under a flat prior, whose posterior is
    normal with mean ``m`` and covariance ``C``."""
    import pipeline.uncertainty.posterior as posterior_module

    keys = {make_pulse_batch([w], FW).samples[0].tobytes(): i for i, w in enumerate(waves)}
    prec = [np.linalg.inv(c) for c in covs]

    def gaussian_blocks(theta_, data, system):
        x = np.atleast_2d(theta_).reshape(-1, len(data), N_PARAMS)
        blocks = np.empty(x.shape[:2])
        for j in range(len(data)):
            i = keys[data.samples[j][data.valid[j]].tobytes()]
            d = x[:, j] - means[i]
            blocks[:, j] = -0.5 * np.einsum("wi,ij,wj->w", d, prec[i], d)
        return np.column_stack([blocks.sum(axis=1), blocks])

    monkeypatch.setattr(posterior_module, "log_prob_blocks", gaussian_blocks)


def test_converged_chains_sample_a_known_gaussian_posterior(monkeypatch):
    """The whole sampler (starts, burn-in, adapted proposal, chunks, convergence, thinning)
    against a posterior known in closed form: a Gaussian likelihood under the flat prior.

    Each pulse's log posterior is replaced by ``-(x - m)' C^-1 (x - m) / 2``, the posterior of
    a Gaussian likelihood with a flat prior: normal with mean ``m`` and covariance ``C``.
    ``m`` lies 1-2 sigma from the waveform's mode the walkers start at and ``C`` is 1.5² times
    the Laplace covariance with extra correlation, so the burn-in and the adapted proposal must
    find it. Whatever the convergence rules say, the chains called converged must reproduce
    ``m`` and ``C``: the whitened draws have mean 0 and covariance I, and the analytic 68 % /
    95 % depth intervals hold 68 % / 95 % of the draws.
    """
    from pipeline.uncertainty.waveform_model import covariance

    rng = np.random.default_rng(51)
    th, waves = draw_truths(10, rng)
    m_all, c_all = [], []
    for t, w in zip(th, waves, strict=True):
        c = 1.2**2 * covariance(fisher_information(t, w.size, FW))
        sd = np.sqrt(np.diag(c))
        r = np.full((N_PARAMS, N_PARAMS), 0.2) + 0.8 * np.eye(N_PARAMS)  # extra correlation
        c = np.linalg.cholesky(c / np.outer(sd, sd)) @ np.linalg.cholesky(r)
        c = np.outer(sd, sd) * (c @ c.T) / np.sqrt(np.outer(np.diag(c @ c.T), np.diag(c @ c.T)))
        m_all.append(t + sd * rng.uniform(0.25, 0.75, N_PARAMS) * rng.choice([-1, 1], N_PARAMS))
        c_all.append(c)
    gaussian_target(monkeypatch, waves, m_all, c_all)
    chains = sample_batch(waves, FW, FAST, seed=7)
    ok = chains.converged
    assert ok.sum() >= 8, chains.flags  # a Gaussian target: (nearly) every pulse converges
    z95, z68 = stats.norm.ppf(0.975), stats.norm.ppf(0.84)
    for i in np.flatnonzero(ok):
        x = chains.draws[i]
        z = np.linalg.solve(np.linalg.cholesky(c_all[i]), (x - m_all[i]).T).T  # whitened
        # ~2000 thinned draws of ~500 independent ones: mean error ~0.05, covariance ~0.07
        assert np.all(np.abs(z.mean(axis=0)) < 0.2), z.mean(axis=0)
        np.testing.assert_allclose(np.cov(z, rowvar=False), np.eye(N_PARAMS), atol=0.25)
        sd0 = math.sqrt(c_all[i][0, 0])
        inside = [np.mean(np.abs(x[:, 0] - m_all[i][0]) <= k * sd0) for k in (z68, z95)]
        assert abs(inside[0] - 0.68) < 0.08 and abs(inside[1] - 0.95) < 0.04, inside


@pytest.mark.slow
def test_posterior_sigma_reaches_the_cramer_rao_bound_gaussian(fw_batch):
    """Flat bottom, 8 noise realisations of one pulse: the posterior sigma of the depth is
    the CRB of the same model (Bernstein–von Mises at this SNR)."""
    _, chains = fw_batch
    crb = depth_crb_m(CRB_FW, window(CRB_FW), FW)
    ratio = np.mean(np.std(chains.draws[120:, :, 0], axis=1)) / crb
    # the brief's bar is 20 %; posterior sigmas scatter by ~5 % between realisations
    assert 0.8 < ratio < 1.2, ratio


@pytest.mark.slow
def test_posterior_sigma_reaches_the_cramer_rao_bound_poisson():
    m = window(CRB_PC)
    rng = np.random.default_rng(21)
    waves = [draw_waveform(CRB_PC, m, PC, rng) for _ in range(8)]
    chains = sample_batch(waves, PC, FAST, seed=2)
    ratio = np.mean(np.std(chains.draws[:, :, 0], axis=1)) / depth_crb_m(CRB_PC, m, PC)
    assert 0.8 < ratio < 1.2, ratio  # as above, with the Poisson Fisher information
    assert np.mean(chains.converged) >= 0.75


N_AIR, N_W = 1.000277, 1.3415


def level_water_survey(rng, nx=8, ny=5):
    """Pulses 300 m up, 0-15 deg off nadir, onto level water at z = 0 over 2-5 m depths.

    Returns the detected returns (exact times), the fitted surface, the refraction settings,
    the true seabed points, depths, in-water cosines and surface times.
    """
    n = nx * ny
    gx, gy = np.meshgrid(np.arange(nx) * 1.5, np.arange(ny) * 1.5)
    ex = np.column_stack([gx.ravel(), gy.ravel(), np.zeros(n)])
    inc = np.radians(rng.uniform(0.0, 15.0, n))
    az = rng.uniform(0, 2 * np.pi, n)
    d = np.column_stack([np.sin(inc) * np.sin(az), np.sin(inc) * np.cos(az), -np.cos(inc)])
    o = ex - d * (300.0 / np.cos(inc))[:, None]
    sw = N_AIR * np.sin(inc) / N_W
    cw = np.sqrt(1.0 - sw**2)
    t_dir = np.column_stack([np.sin(az) * sw, np.cos(az) * sw, -cw])
    depth = rng.uniform(2.0, 5.0, n)
    bottom = ex + t_dir * (depth / cw)[:, None]
    t_s = 2.0 * 300.0 / np.cos(inc) * N_AIR / C
    t_b = t_s + in_water_delay_s(depth, cw, N_G)
    ret = DetectedReturns(
        pulse_id=np.arange(n),
        origin_meas_m=o,
        direction_meas=d,
        has_surface=np.ones(n, bool),
        t_surface_s=t_s,
        has_bottom=np.ones(n, bool),
        t_bottom_s=t_b,
        surface_confidence=np.full(n, 0.9),
        bottom_confidence=np.full(n, 0.9),
        flags=np.zeros(n, np.uint16),
    )
    surface = fit_water_surface(ret, SurfaceFitSettings(air_index=N_AIR))
    rst = RefractionSettings(phase_index=N_W, group_index=N_G)
    return ret, surface, rst, bottom, depth, cw, t_s


def test_seabed_posterior_through_refraction():
    """Flat water at z = 0, beams off nadir: the refracted posterior holds the analytic point."""
    rng = np.random.default_rng(31)
    n = 40  # enough surface returns for the local fits; 4 pulses are sampled
    ret, surface, rst, bottom, depth, cw, t_s = level_water_survey(rng)
    d = ret.direction_meas
    np.testing.assert_allclose(water_cosine(d, surface.normal, N_AIR, N_W), cw, rtol=1e-9)
    rows = np.array([0, 13, 22, 39])
    m = 90
    waves = np.zeros((n, m))
    t0 = t_s - 10e-9  # the surface sits 10 ns into each window
    for i in rows:
        th = theta(depth=depth[i], t_ns=10.0, a_s=3000, a_c=500, a_b=1500)
        waves[i] = draw_waveform(th, m, FW, rng, cw[i])
    post = seabed_posteriors(waves, t0, ret, surface, FW, FAST, rst, rows=rows, seed=3)
    assert np.all(post.converged)
    err = post.xyz_median_m - bottom[rows]
    # within 4 posterior sigmas per coordinate (+1 mm for the horizontal, which only the
    # in-water angle spreads)
    assert np.all(np.abs(err) <= 4 * post.xyz_std_m + 1e-3), (err, post.xyz_std_m)
    dep = post.depth_m
    assert np.all((dep["lo95"] - 0.01 <= depth[rows]) & (depth[rows] <= dep["hi95"] + 0.01))
    # level water: the refracted depth of every draw is the sampled depth parameter plus how
    # far below the fitted plane the draw's surface time puts the entry (the pulse enters at
    # its own echo: no detector sigma, weight 1): c t_s / (2 n_air) - r_e along the beam (the
    # fitted plane's tilt over the metre from entry to point: < 0.1 mm)
    chains = sample_batch(waves[rows[:1]], FW, FAST, cos_water=cw[rows[:1]], seed=4)
    r0 = int(rows[0])
    pts = draws_to_seabed(chains.draws[0], r0, float(t0[r0]), ret, surface, FW, float(cw[r0]), rst)
    t_s_draw = float(t0[r0]) + chains.draws[0, :, 1] * 1e-9
    below = (C * t_s_draw / (2 * N_AIR) - surface.range_to_entry_m[r0]) * -d[r0, 2]
    np.testing.assert_allclose(pts.depth_m, chains.draws[0, :, 0] + below, atol=1e-4)
    # several pulses' draws in one pass of the refraction: each pulse's points as alone
    draws = [chains.draws[0], chains.draws[0][::-1] + 0.01, chains.draws[0][:7]]
    many = draws_to_seabed_rows(draws, rows[:3], t0[rows[:3]], ret, surface, FW, cw[rows[:3]], rst)
    for dr, r, got in zip(draws, rows[:3], many, strict=True):
        alone = draws_to_seabed(dr, int(r), float(t0[r]), ret, surface, FW, float(cw[r]), rst)
        np.testing.assert_array_equal(got.xyz_m, alone.xyz_m)
        np.testing.assert_array_equal(got.depth_m, alone.depth_m)


def test_a_pulse_without_bottom_is_flagged_not_sampled():
    th = theta()
    m = window(th)
    rng = np.random.default_rng(41)
    good = draw_waveform(th, m, FW, rng)
    empty = 100.0 + rng.normal(0.0, 2.0, m)
    chains = sample_batch([good, empty], FW, FAST, seed=5)
    assert chains.flags[1] & PosteriorFlag.NO_START and not chains.converged[1]
    assert np.all(chains.draws[1] == 0.0)
    assert not chains.flags[0] & PosteriorFlag.NO_START
