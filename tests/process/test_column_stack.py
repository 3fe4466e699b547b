"""The survey's column decay from stacked columns, against hand-built waveforms of known decay.

Each waveform is written here: white noise of known σ, a surface echo at a pulse-dependent time
and strength, then the water-column return ``A_i exp(−2 k l)``, ``l = v τ / 2`` the in-water
path at the round-trip time ``τ`` after the surface (``v = c / n_g``; ``A_i`` varies from pulse
to pulse), blurred by the system's Gaussian, and on a third of the pulses a bright bottom echo
at a pulse-dependent depth. The truth is ``k``: past its onset the filtered column is
``A_i' exp(−k v τ)`` whatever the blur, and a sum of such exponentials decays at the same
rate. The column is faint (a few filtered noise σ at its top, clear water): a pulse's own column
is a handful of samples above the noise, which biases a per-pulse fit high.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.special import ndtr

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.column_stack import ColumnStack, stack_column, stacked_decay_per_m
from pipeline.process.detect import DetectSettings, detect_full_waveform
from pipeline.process.detection_limit import DetectorModel, NoBottomSettings
from pipeline.process.no_bottom import chunk_inputs, excess_decay_summary

DT_S = 1e-9
FWHM_S = 3e-9
SIGMA_SAMPLES = FWHM_S / DT_S / (2.0 * math.sqrt(2.0 * math.log(2.0)))
N_G = 1.34
V_M_S = SPEED_OF_LIGHT_M_S / N_G
K_PER_M = 0.06  # the lidar decay of clear coastal water (suite tuning seed 54: 0.061 /m)
NOISE_COUNTS = 2.0
NOISE_SAMPLES = 30
N_SAMPLES = 400
#: The stacked estimate's stated tolerance (relative).
REL_TOL = 0.10

# what chunk_inputs reads of the processing context: the receiver and the water's group index
CTX = SimpleNamespace(
    instrument=SimpleNamespace(
        sample_interval_s=DT_S,
        system_fwhm_s=FWHM_S,
        noise_samples=NOISE_SAMPLES,
        shot_noise_counts=0.0,
    ),
    refraction=SimpleNamespace(group_index=N_G),
)


def _filtered_noise():
    # white noise of σ through the unit-area Gaussian of σ_samples
    return NOISE_COUNTS / math.sqrt(2.0 * math.sqrt(math.pi) * SIGMA_SAMPLES)


def _waveforms(
    n, seed=0, column_top_sigma=4.0, bottoms=True, faint_bottoms=False, dark_seabed=None
):
    """(n, N_SAMPLES) waveforms: baseline, noise, surface, column of decay ``K_PER_M``, bottoms.

    ``faint_bottoms``: every pulse without a bright bottom has one 240-250 samples below the
    surface whose filtered peak is two filtered noise σ (under the detector's 5 σ threshold).
    ``dark_seabed``: ``(lo, hi)`` samples below the surface; every pulse without a bright
    bottom meets a black seabed there (no echo): its column stops.
    """
    rng = np.random.default_rng(seed)
    s = SIGMA_SAMPLES
    a = K_PER_M * V_M_S * DT_S  # column decay per sample: exp(−2 k l), l = v τ / 2
    i_surface = rng.uniform(40.0, 60.0, n)[:, None]  # aircraft height and waves
    tau = np.arange(N_SAMPLES)[None, :] - i_surface  # samples after the surface
    # column levels of the pulses (incidence, surface transmission): the top of the filtered
    # column at ~column_top_sigma filtered noise σ
    level = column_top_sigma * _filtered_noise() * rng.lognormal(0.0, 0.3, (n, 1))
    # exp(−a τ) H(τ) blurred by the system Gaussian (exponentially modified Gaussian)
    column = level * np.exp(-a * tau + 0.5 * (a * s) ** 2) * ndtr(tau / s - a * s)
    if dark_seabed is not None:  # the column ends at the seabed, blurred by the system
        has = (np.arange(n) % 3 == 0)[:, None] if bottoms else np.zeros((n, 1), dtype=bool)
        t_sea = rng.uniform(*dark_seabed, (n, 1))
        column = column * np.where(has, 1.0, ndtr((t_sea - tau) / s))
    surface = rng.uniform(300.0, 900.0, (n, 1)) * np.exp(-0.5 * (tau / s) ** 2)
    y = 50.0 + column + surface + rng.normal(0.0, NOISE_COUNTS, (n, N_SAMPLES))
    if bottoms:
        # a bright bottom on every third pulse, 40-300 samples below the surface
        has = (np.arange(n) % 3 == 0)[:, None]
        tb = rng.uniform(40.0, 300.0, (n, 1))
        y = y + has * 150.0 * np.exp(-0.5 * ((tau - tb) / s) ** 2)
    if faint_bottoms:
        # a Gaussian of σ_samples and peak p filters (unit-area Gaussian of σ_samples) to a
        # peak p / √2
        faint = ~has if bottoms else np.ones((n, 1), dtype=bool)
        tb = rng.uniform(240.0, 250.0, (n, 1))
        peak = 2.0 * math.sqrt(2.0) * _filtered_noise()
        y = y + faint * peak * np.exp(-0.5 * ((tau - tb) / s) ** 2)
    return y


def _survey(y, n_chunks=1):
    """The no-bottom summary of waveforms ``y`` processed in ``n_chunks`` chunks."""
    detect = DetectSettings()
    inputs = []
    for part in np.array_split(y, n_chunks):
        found = detect_full_waveform(part, DT_S, FWHM_S, detect, noise_samples=NOISE_SAMPLES)
        inputs.append(chunk_inputs(part, found, CTX, detect, NoBottomSettings()))
    cat = {
        k: np.concatenate([d[k] for d in inputs])
        for k in ("t_b", "loss", "floor", "alpha", "ok", "none")
    }
    counts = {"bottoms": cat["t_b"].size, "no_column": int(np.sum(cat["none"] & ~cat["ok"]))}
    stack, open_ = (
        ColumnStack.total([d[k] for d in inputs], DT_S)
        for k in ("column_stack", "column_stack_open")
    )
    alpha_ok = cat["alpha"][cat["ok"]]
    return excess_decay_summary(
        cat["t_b"], cat["loss"], cat["floor"], alpha_ok, stack, counts, CTX, detect, open_
    )[1]


@pytest.fixture(scope="module")
def clear_water():
    y = _waveforms(3000)
    found = detect_full_waveform(y, DT_S, FWHM_S, DetectSettings(), noise_samples=NOISE_SAMPLES)
    # the scene is what it claims: every surface found, the planted bottoms found
    assert found.has_surface.all()
    assert found.has_bottom.sum() >= 0.9 * 1000
    return y


def test_stacked_column_recovers_the_known_decay(clear_water):
    summary = _survey(clear_water)
    assert summary["column_decay_per_m"] == pytest.approx(K_PER_M, rel=REL_TOL)


def test_median_of_per_pulse_fits_is_biased_high_in_the_same_water(clear_water):
    # the same check the stack passes fails for the per-pulse fits (the old estimate)
    old = _survey(clear_water)["column_decay_median_fit_per_m"]
    assert old > (1.0 + REL_TOL) * K_PER_M


def test_faint_bottoms_under_the_noise_do_not_flatten_the_decay():
    # each faint bottom is under the noise (none is found), but the stack of 2000 of them is a
    # bump far above the column there (~6x): it must not enter the fit (with it: 0.050 /m)
    y = _waveforms(3000, seed=3, faint_bottoms=True)
    found = detect_full_waveform(y, DT_S, FWHM_S, DetectSettings(), noise_samples=NOISE_SAMPLES)
    assert found.has_bottom.sum() <= 1000 + 20  # the bright ones (and a handful of faint ones)
    assert _survey(y)["column_decay_per_m"] == pytest.approx(K_PER_M, rel=REL_TOL)


def test_faint_bottoms_do_not_flatten_the_decay_of_open_columns_alone():
    # no bright bottom anywhere: the decay is the open columns', and their stack holds the bump
    y = _waveforms(3000, seed=3, bottoms=False, faint_bottoms=True)
    summary = _survey(y)
    assert summary["column_decay_from"] == "open"
    assert summary["column_decay_per_m"] == pytest.approx(K_PER_M, rel=REL_TOL)


def test_open_columns_that_stop_at_an_unseen_seabed_do_not_steepen_the_decay():
    """Two pulses in three find no bottom: a black seabed 40-60 samples down (4.5-6.7 m of
    path, the shoal of tuning seed 7003) stops their column with no echo, while the stack still
    shows the column there (~5 filtered noise σ at the top, half of it at the seabed, from 2000
    pulses). Their stack falls off a cliff there; the closed columns (ending before a bright
    bottom) are water all the way, and the decay is theirs."""
    y = _waveforms(3000, seed=5, column_top_sigma=5.0, dark_seabed=(40.0, 60.0))
    summary = _survey(y)
    assert summary["column_decay_from"] == "closed"
    assert summary["column_decay_per_m"] == pytest.approx(K_PER_M, rel=REL_TOL)
    # the open columns alone: steepened by their ends (what the survey's decay was before)
    open_only = _survey(_waveforms(3000, seed=5, column_top_sigma=5.0, bottoms=False,
                                   dark_seabed=(40.0, 60.0)))  # fmt: skip
    assert open_only["column_decay_from"] == "open"
    assert open_only["column_decay_per_m"] > (1.0 + REL_TOL) * K_PER_M


def test_bright_column_agrees_with_per_pulse_fits():
    # where each pulse's column is long (a bright column) both estimates find the decay
    summary = _survey(_waveforms(600, seed=1, column_top_sigma=200.0))
    assert summary["column_decay_per_m"] == pytest.approx(K_PER_M, rel=0.05)
    assert summary["column_decay_median_fit_per_m"] == pytest.approx(K_PER_M, rel=0.05)


def test_stack_does_not_depend_on_the_chunking(clear_water):
    one, three = _survey(clear_water, 1), _survey(clear_water, 3)
    assert three["column_decay_per_m"] == pytest.approx(one["column_decay_per_m"], rel=1e-9)


def test_chunk_stacks_add_to_the_whole_stack(clear_water):
    det = DetectorModel(
        dt_s=DT_S,
        pulse_fwhm_s=FWHM_S,
        noise_samples=NOISE_SAMPLES,
        threshold_sigma=5.0,
        min_separation_fwhm=2.5,
        group_index=N_G,
    )
    y = clear_water[:500]
    ts = np.full(len(y), 50.0 * DT_S)
    end = np.full(len(y), 350.0 * DT_S)
    whole = stack_column(y, ts, end, det)
    # chunks of different waveform lengths: the shorter stack is padded with empty bins
    parts = ColumnStack.total(
        [
            stack_column(y[:200, :380], ts[:200], end[:200], det),
            stack_column(y[200:], ts[200:], end[200:], det),
        ],
        DT_S,
    )
    n = whole.n_pulses.size
    assert np.array_equal(parts.n_pulses[:n], whole.n_pulses)
    np.testing.assert_allclose(parts.sum_counts[:n], whole.sum_counts, rtol=1e-12, atol=1e-9)
    # each pulse counts from its first column sample, ceil(50 + 2.5 × 3), to before sample 350
    assert whole.n_pulses[0] == 500 and whole.n_pulses[350 - 58 - 1] == 500
    assert whole.n_pulses[350 - 58] == 0


def test_no_column_gives_none():
    # surface and noise only (clear water at night): nothing to fit, no NaN
    summary = _survey(_waveforms(600, seed=2, column_top_sigma=0.0, bottoms=False))
    assert summary["column_decay_per_m"] is None
    assert stacked_decay_per_m(ColumnStack.empty(DT_S), N_G) is None


def test_decay_is_fitted_over_one_set_of_pulses_over_a_slope():
    """Columns ``A_i exp(-alpha j)`` plus white noise: over a sloping seabed the pulses reaching
    a bin thin out with it, and where their levels differ with their end (here the pulses that
    leave early are twice as bright) the stack of the pulses reaching each bin falls faster
    than the water decays as they leave (17 % here). Fitted over the pulses reaching the run's
    end it is the water's own decay (within its noise, 1 %)."""
    from pipeline.process.column_stack import _accumulate

    alpha = 0.03  # per bin
    m, n = 120, 4000
    j = np.arange(m)
    rng = np.random.default_rng(4)
    ends = np.where(np.arange(n) < n // 2, rng.integers(10, 60, n), 200)  # half leave early
    level = np.where(ends < 100, 2.0, 1.0) * (1.0 + 0.1 * rng.standard_normal(n))
    filt = level[:, None] * np.exp(-alpha * j)[None, :] + 0.2 * rng.standard_normal((n, m))
    stack = _accumulate(filt, np.zeros(n), ends.astype(float), DT_S)
    want = alpha / DT_S * N_G / SPEED_OF_LIGHT_M_S  # k = alpha n_g / c per metre
    got = stacked_decay_per_m(stack, N_G)
    assert got == pytest.approx(want, rel=0.01)
    # the same stack without its per-end sums (every pulse reaching each bin): biased steep
    old = ColumnStack(stack.sum_counts, stack.sum_sq_counts2, stack.n_pulses, DT_S, None)
    assert stacked_decay_per_m(old, N_G) > 1.1 * want
    # chunked: the stacks add (the per-end sums too) to the same decay
    halves = [_accumulate(filt[s], np.zeros(n // 2), ends[s].astype(float), DT_S)
              for s in (slice(0, n // 2), slice(n // 2, n))]  # fmt: skip
    total = ColumnStack.total(halves, DT_S)
    assert stacked_decay_per_m(total, N_G) == pytest.approx(got, rel=1e-8)
