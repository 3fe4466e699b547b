"""The timing terms split into the detector's share and the measured excess.

Reference: the TPU propagated from the detector's sigmas alone (its timing terms are what the
split must leave as the detector's share: the Jacobian is the same), and the totals of the TPU
propagated from the raised sigmas (which the split must not change).
"""

import dataclasses

import numpy as np

from pipeline.uncertainty.survey_posterior import nuisance_depth_sigma_m
from pipeline.uncertainty.tpu import point_tpu, timing_from_scatter
from pipeline.uncertainty.tpu_settings import DEPTH
from pipeline.uncertainty.tpu_timing import EXCESS_TERMS, split_timing_excess
from tests.uncertainty.test_tpu import RST, survey


def _detector_and_raised(n_side=5):
    ret, surf = survey(n_side=n_side)
    n = len(ret)
    surf = dataclasses.replace(surf, fit_sigma_m=np.zeros(n))
    det = dataclasses.replace(
        ret,
        t_surface_sigma_s=np.full(n, 2e-11),
        t_bottom_sigma_s=np.linspace(2e-11, 1.5e-10, n),
        surface_amplitude=np.full(n, 100.0),
        bottom_amplitude=np.linspace(20.0, 2000.0, n),
    )
    # a measured scatter above the detector's own for most soundings, below for a few
    scatter = np.linspace(0.0, 0.08, n)
    raised = timing_from_scatter(
        det, surf, RST, depth_scatter_m=scatter, max_sigma_s=1e-8, raise_only=True
    )
    return det, raised, surf


def test_the_detector_share_is_the_tpu_of_the_detector_sigmas():
    det, raised, surf = _detector_and_raised()
    assert np.any(raised.t_bottom_sigma_s > det.t_bottom_sigma_s)  # the scatter raised some
    assert np.any(raised.t_bottom_sigma_s == det.t_bottom_sigma_s)  # and left some
    full = point_tpu(raised, surf, RST)
    split = split_timing_excess(full, det, raised)
    own = point_tpu(det, surf, RST)
    for name, excess in EXCESS_TERMS.items():
        # the TPU's terms are differences at each sigma: linear in it to ~5e-9
        np.testing.assert_allclose(split.terms[name], own.terms[name], rtol=1e-7, atol=1e-15)
        # own and excess add up to the propagated term, component by component
        np.testing.assert_allclose(
            split.terms[name] ** 2 + split.terms[excess] ** 2, full.terms[name] ** 2, rtol=1e-9
        )
    # where the scatter did not raise a sigma there is no excess
    same = raised.t_bottom_sigma_s == det.t_bottom_sigma_s
    assert np.all(split.terms["timing_bottom_excess"][same] == 0.0)
    # the totals are the propagated ones, untouched
    np.testing.assert_array_equal(split.sigma_depth_m, full.sigma_depth_m)
    np.testing.assert_array_equal(split.sigma_v_m, full.sigma_v_m)


def test_the_posterior_nuisance_keeps_the_excess():
    det, raised, surf = _detector_and_raised()
    full = point_tpu(raised, surf, RST)
    split = split_timing_excess(full, det, raised)
    idx = np.arange(len(split))
    before = nuisance_depth_sigma_m(full.terms, idx)
    after = nuisance_depth_sigma_m(split.terms, idx)
    excess2 = sum(split.terms[k][:, DEPTH] ** 2 for k in EXCESS_TERMS.values())
    np.testing.assert_allclose(after**2, before**2 + excess2, rtol=1e-9, atol=1e-18)
    # and nuisance plus the detector's timing is the whole TPU (the posterior stands for the
    # detector's share alone)
    own2 = sum(split.terms[k][:, DEPTH] ** 2 for k in EXCESS_TERMS)
    np.testing.assert_allclose(after**2 + own2, full.sigma_depth_m**2, rtol=1e-6)


def test_without_detector_sigmas_nothing_is_split():
    ret, surf = survey(n_side=4)
    scatter = np.full(len(ret), 0.03)
    raised = timing_from_scatter(ret, surf, RST, depth_scatter_m=scatter)
    full = point_tpu(raised, surf, RST)
    split = split_timing_excess(full, ret, raised)
    assert set(split.terms) == set(full.terms)
    for k in full.terms:
        np.testing.assert_array_equal(split.terms[k], full.terms[k])
