"""The seabed posterior marginalised over what the waveform does not see.

Truth built in the test: level water, exact returns, waveforms drawn from the process-side model
with known depths; the depth the evaluation compares with is moved by a nuisance the waveform
cannot see, drawn here with a known per-pulse sigma (e.g. a horizontal navigation error of
``sigma_h`` over a seabed of slope ``g``: ``g delta``, sigma ``g sigma_h``), 1.6-5 times the
waveform's own ranging sigma (~1.2 cm), as on the sloping and wavy suite scenes.
"""

import math

import numpy as np
import pytest

from pipeline.uncertainty.posterior import PosteriorSettings
from pipeline.uncertainty.seabed_posterior import seabed_posteriors
from pipeline.uncertainty.survey_posterior import nuisance_depth_sigma_m
from pipeline.uncertainty.waveform_model import draw_waveform
from tests.uncertainty.test_posterior import FW, binomial_band, level_water_survey, theta


@pytest.mark.slow
def test_intervals_hold_a_truth_moved_by_the_nuisances():
    rng = np.random.default_rng(71)
    ret, surface, rst, _, depth, cw, t_s = level_water_survey(rng, nx=10, ny=6)
    n, m = len(ret), 130
    waves = np.zeros((n, m))
    for i in range(n):
        th = theta(depth=depth[i], t_ns=20.0, a_s=3000, a_c=500, a_b=1500)
        waves[i] = draw_waveform(th, m, FW, rng, cw[i])
    # a horizontal navigation error over a 10 % slope: depth moves by g * delta; sigma_h
    # 0.2-0.6 m per pulse, so 2-6 cm against ~1 cm of ranging noise
    g = 0.1
    sigma_h = rng.uniform(0.2, 0.6, n)
    truth = depth + g * sigma_h * rng.standard_normal(n)
    st = PosteriorSettings(max_steps=2000)
    post = seabed_posteriors(
        waves, t_s - 20e-9, ret, surface, FW, st, rst, seed=5, nuisance_depth_sigma_m=g * sigma_h
    )
    d = post.depth_m
    cover95 = np.mean((d["lo95"] <= truth) & (truth <= d["hi95"]))
    cover68 = np.mean((d["lo68"] <= truth) & (truth <= d["hi68"]))
    lo95, hi95 = binomial_band(n, 0.95)  # 60 pulses: [0.85, 1.0]
    lo68, hi68 = binomial_band(n, 0.68)
    assert lo95 <= cover95 <= hi95, cover95
    assert lo68 <= cover68 <= hi68, cover68
    # the waveform's own sigma is kept apart (the cells add the TPU's other terms themselves)
    total = np.sqrt(post.waveform_std_m**2 + (g * sigma_h) ** 2)
    np.testing.assert_allclose(d["std"], total, rtol=0.15)
    assert np.median(post.waveform_std_m / (g * sigma_h)) < 0.5  # the nuisance dominates


def test_nuisance_sigma_is_every_tpu_term_but_the_timing():
    """The depth column of every term in quadrature, the two timing terms left out."""
    rows = np.array([[9.0, 9.0, 9.0, 0.0], [9.0, 9.0, 9.0, 0.0]])
    terms = {
        "timing_surface": rows + [0, 0, 0, 0.5],
        "timing_bottom": rows + [0, 0, 0, 0.7],
        "navigation": rows + [[0, 0, 0, 0.03], [0, 0, 0, 0.0]],
        "wave_slope_x": rows + [[0, 0, 0, 0.04], [0, 0, 0, 0.05]],
        "surface_height": rows.copy(),
    }
    got = nuisance_depth_sigma_m(terms, np.array([1, 0, 1]))
    np.testing.assert_allclose(got, [0.05, math.hypot(0.03, 0.04), 0.05], rtol=1e-12)
