"""The TPU's timing terms when the detector gives per-return sigmas that the timing does not
reach: the scatter of successive soundings raises them, never lowers them. Truth is analytic:
flat water at z = 0 over a flat seabed 12 m deep (:func:`tests.uncertainty.test_tpu.survey`),
with bottom-time noise of a known sigma added here."""

import dataclasses

import numpy as np

from pipeline.process.refraction import seabed_points
from pipeline.uncertainty.tpu import pair_scatter, point_tpu, timing_from_scatter
from tests.uncertainty.test_tpu import RST, survey

TRUE_DEPTH_M = 12.0


def _noisy(sigma_b_s, detector_b_s, seed=7):
    ret, surf = survey(n_side=36, seed=seed)
    n = len(ret)
    rng = np.random.default_rng(seed)
    ret = dataclasses.replace(
        ret,
        t_bottom_s=ret.t_bottom_s + rng.normal(0.0, sigma_b_s, n),
        # survey() puts 0.1 ns of noise on the surface times; the detector knows that one
        t_surface_sigma_s=np.full(n, 1e-10),
        t_bottom_sigma_s=np.full(n, detector_b_s),
    )
    pts = seabed_points(ret, surf, RST)
    scatter = pair_scatter(pts.xyz_m[:, :2], pts.depth_m, order=ret.pulse_id)
    return ret, surf, pts, scatter


def test_scatter_raises_a_detector_sigma_the_timing_does_not_reach():
    """The detector claims 0.02 ns on the bottom, the times scatter by 0.4 ns (~4.4 cm of
    depth): the TPU intervals must hold the true depth at their nominal rates."""
    ret, surf, pts, scatter = _noisy(4e-10, 2e-11)
    err = pts.depth_m - TRUE_DEPTH_M
    own = point_tpu(ret, surf, RST)
    z_own = np.abs(err) / own.sigma_depth_m
    assert np.mean(z_own <= 1.96) < 0.5  # the detector's sigma alone: far too small
    raised = timing_from_scatter(ret, surf, RST, depth_scatter_m=scatter, raise_only=True)
    tpu = point_tpu(raised, surf, RST)
    z = np.abs(err) / tpu.sigma_depth_m
    # 1296 points: the coverage is known to ~1.3 % (68 %) and ~0.6 % (95 %), the scatter
    # estimate (64 pairs each) to ~9 %
    assert 0.62 <= np.mean(z <= 1.0) <= 0.75
    assert 0.92 <= np.mean(z <= 1.96) <= 0.975


def test_a_detector_sigma_above_the_scatter_is_kept():
    ret, surf, _, scatter = _noisy(1e-11, 2e-9)
    out = timing_from_scatter(ret, surf, RST, depth_scatter_m=scatter, raise_only=True)
    np.testing.assert_array_equal(out.t_bottom_sigma_s, ret.t_bottom_sigma_s)
    np.testing.assert_array_equal(out.t_surface_sigma_s, ret.t_surface_sigma_s)
    # without raise_only the scatter replaces them (the photon-counting path)
    set_ = timing_from_scatter(ret, surf, RST, depth_scatter_m=scatter)
    assert np.median(set_.t_bottom_sigma_s) < 0.5 * 2e-9
