"""The column after a clipped surface echo, against hand-built waveforms of known decay.

A nadir profiler over light wind clips every surface echo at the digitiser's top code: the
echo's plateau and its tail hide the first nanoseconds of the column, and before the column
was read past the tail (:func:`~pipeline.process.detection_limit.column_first_s`) no column of
such a survey was read at all. Each waveform here is written out: a baseline, white noise of
known σ, a Gaussian surface echo 30 to 300 000 times the top code, the water-column return
``A_i exp(−2 k l)`` blurred by the system Gaussian (``l = v τ / 2``), on a third of the pulses a
bright bottom, then clipped at the top code. The truth is ``k``.
"""

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.ndimage import gaussian_filter1d
from scipy.special import ndtr

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.detect import DetectSettings, detect_full_waveform
from pipeline.process.detection_limit import (
    DetectorModel,
    NoBottomSettings,
    column_first_s,
    column_margins,
)
from pipeline.process.no_bottom import chunk_inputs, excess_decay_summary
from pipeline.process.no_bottom_settings import DEFAULT_EXCESS_DECAY_PER_M
from pipeline.process.returns import DetectorFlag

DT_S = 1e-9
FWHM_S = 3e-9
SIGMA = FWHM_S / DT_S / (2.0 * math.sqrt(2.0 * math.log(2.0)))  # samples
N_G = 1.34
K_PER_M = 0.12  # suite held-out seed 1's water (c 0.119 /m)
NOISE = 2.0
NOISE_SAMPLES = 30
N_SAMPLES = 300
TOP = 1023.0  # a 10-bit digitiser
BASE = 50.0
REL_TOL = 0.10  # as the stacked decay's test of unclipped columns (test_column_stack)

CTX = SimpleNamespace(
    instrument=SimpleNamespace(
        sample_interval_s=DT_S,
        system_fwhm_s=FWHM_S,
        noise_samples=NOISE_SAMPLES,
        shot_noise_counts=0.0,
        amplitude_full_scale=TOP + 1.0,
    ),
    refraction=SimpleNamespace(group_index=N_G),
)
DET = DetectorModel(
    dt_s=DT_S,
    pulse_fwhm_s=FWHM_S,
    noise_samples=NOISE_SAMPLES,
    threshold_sigma=DetectSettings().threshold_sigma,
    min_separation_fwhm=DetectSettings().min_separation_fwhm,
    group_index=N_G,
)


def _waveforms(n, seed=0, clip=True, bottom_counts=150.0):
    """(n, N_SAMPLES) waveforms (module notes); unclipped with ``clip=False``."""
    rng = np.random.default_rng(seed)
    a = K_PER_M * SPEED_OF_LIGHT_M_S / N_G * DT_S  # decay per sample
    tau = np.arange(N_SAMPLES)[None, :] - rng.uniform(40.0, 60.0, (n, 1))
    level = 60.0 * rng.lognormal(0.0, 0.3, (n, 1))  # a bright nadir column
    column = level * np.exp(-a * tau + 0.5 * (a * SIGMA) ** 2) * ndtr(tau / SIGMA - a * SIGMA)
    surface = TOP * 10.0 ** rng.uniform(1.5, 5.5, (n, 1)) * np.exp(-0.5 * (tau / SIGMA) ** 2)
    has = (np.arange(n) % 3 == 0)[:, None]
    bottom = (
        has * bottom_counts * np.exp(-0.5 * ((tau - rng.uniform(40.0, 120.0, (n, 1))) / SIGMA) ** 2)
    )
    y = BASE + column + surface + bottom + rng.normal(0.0, NOISE, (n, N_SAMPLES))
    return np.minimum(y, TOP) if clip else y


def _summary(y, top_code=TOP, settings=None):
    detect = DetectSettings()
    found = detect_full_waveform(
        y, DT_S, FWHM_S, detect, noise_samples=NOISE_SAMPLES, top_code=top_code
    )
    d = chunk_inputs(y, found, CTX, detect, NoBottomSettings())
    counts = {"bottoms": d["t_b"].size, "no_column": int(np.sum(d["none"] & ~d["ok"]))}
    _, s = excess_decay_summary(
        d["t_b"], d["loss"], d["floor"], d["alpha"][d["ok"]], d["column_stack"], counts, CTX,
        detect,
        d["column_stack_open"],
        settings,
    )  # fmt: skip
    return found, d, s


@pytest.fixture(scope="module")
def clipped():
    return _summary(_waveforms(1500), TOP)


def test_every_surface_echo_is_clipped(clipped):
    found, _, _ = clipped
    assert np.all(found.flags & np.uint16(DetectorFlag.SATURATED))
    assert not np.any(found.flags & np.uint16(DetectorFlag.CLIPPED_MERGED))


def test_the_column_after_clipped_echoes_gives_the_known_decay(clipped):
    _, _, s = clipped
    assert s["column_decay_per_m"] == pytest.approx(K_PER_M, rel=REL_TOL)


def test_clipped_pulses_get_their_own_column_and_bottoms(clipped):
    _, d, s = clipped
    # two thirds have no bottom: each gets a measured column (a detection limit) ...
    assert np.count_nonzero(d["none"]) >= 990
    assert np.count_nonzero(d["ok"]) >= 0.9 * 1000
    # ... and the bright bottoms of the third enter the bottoms' extra decay
    assert s["bottoms_used"] >= 0.9 * 500


def test_columns_above_clipped_bottoms_are_stacked_and_their_bottoms_left_out():
    # a shallow bright seabed clips too (suite held-out seed 12: surface and bottom at the top
    # code): the column between them is whole, the bottom's peak is not its amplitude
    _, d, s = _summary(_waveforms(1500, seed=1, bottom_counts=20.0 * TOP))
    assert s["column_decay_per_m"] == pytest.approx(K_PER_M, rel=REL_TOL)
    assert s["column_decay_from"] == "closed"
    assert d["column_stack"].n_pulses[0] >= 0.9 * 500  # the bottoms' columns
    assert s["bottoms_used"] == 0
    # no bottom to fit the extra decay with: the stated default, not 0 (the weakest fading)
    assert s["excess_decay_from"] == "default"
    assert s["excess_decay_per_m"] == pytest.approx(DEFAULT_EXCESS_DECAY_PER_M, rel=1e-12)
    _, _, s2 = _summary(
        _waveforms(1500, seed=1, bottom_counts=20.0 * TOP),
        settings=NoBottomSettings(default_excess_decay_per_m=0.03),
    )
    assert s2["excess_decay_from"] == "default"
    assert s2["excess_decay_per_m"] == pytest.approx(0.03, rel=1e-12)


def test_bottoms_enough_to_fit_give_their_own_extra_decay(clipped):
    _, _, s = clipped
    assert s["excess_decay_from"] == "fit"


def _per_pulse_k(y, found, first_s, rows):
    """Median per-pulse column decay (per metre) of ``rows``."""
    f = None if first_s is None else first_s[rows]
    cm = column_margins(y[rows], found.t_surface_s[rows], found.noise_sigma[rows], DET, first_s=f)
    return float(np.median(cm.alpha_per_s[cm.ok])) * N_G / SPEED_OF_LIGHT_M_S


def test_each_pulse_reads_its_column_past_the_echo_tail_not_before():
    # a bright column: each pulse's own fit is unbiased where it starts past the tail; from
    # one separation after the surface (the unclipped echoes' start) the tail of the
    # brightest echoes steepens it: the start is what the other tests stand on
    y = _waveforms(900)
    found = detect_full_waveform(
        y, DT_S, FWHM_S, DetectSettings(), noise_samples=NOISE_SAMPLES, top_code=TOP
    )
    first = column_first_s(found.t_surface_s, found.surface_amplitude, DET, TOP - BASE)
    ratio = math.sqrt(2.0) * found.surface_amplitude / (TOP - BASE)
    none = ~found.has_bottom
    for rows in (none, none & (ratio > 1e4)):
        assert _per_pulse_k(y, found, first, rows) == pytest.approx(K_PER_M, rel=REL_TOL)
    assert _per_pulse_k(y, found, None, none & (ratio > 1e4)) > 1.3 * K_PER_M  # 1.44 here


def test_a_clipped_echo_is_below_the_brightest_recorded_one_where_its_column_starts():
    # brute force on a fine grid (h samples): a Gaussian echo A times the top code, clipped,
    # matched-filtered; from column_first_s on it stays below the filtered echo at the top
    # code one separation after that echo's centre (the start every unclipped pulse has)
    h = 0.01
    x = np.arange(6000) - 1000.0  # fine steps from the echo's centre
    g = np.exp(-0.5 * (x * h / SIGMA) ** 2)
    top = TOP - BASE
    sep = DET.min_separation_fwhm * FWHM_S / DT_S  # samples
    level = gaussian_filter1d(top * g, SIGMA / h)[1000 + round(sep / h)]
    for a in (0.5, 2.0, 30.0, 1e3, 1e5):
        filt = gaussian_filter1d(np.minimum(a * top * g, top), SIGMA / h)
        amp = a * top / math.sqrt(2.0)  # the detector's filtered peak of such an echo
        start = column_first_s(np.array([0.0]), np.array([amp]), DET, top)[0] / DT_S
        i = 1000 + math.ceil(start / h)
        assert np.all(filt[i:] <= level * (1.0 + 1e-6)), a
        # and not far later: one sample earlier a clipped echo is still above that level
        if a > 1.0:
            assert filt[i - round(1.0 / h)] > level, a
