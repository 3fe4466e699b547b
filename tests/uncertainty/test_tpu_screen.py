"""Odd pulses never stop the TPU: a false bottom a few ns after the surface with an absurd
timing sigma, or a sigma reaching the surface, is left out with its reason, and the other
pulses keep the analytic answer; a timing sigma from the scatter is bounded where the depth
hardly depends on the timing (a beam along the local seabed gradient)."""

import dataclasses
import math

import numpy as np
import pytest

from pipeline.uncertainty.tpu import DEPTH, point_tpu, timing_from_scatter
from pipeline.uncertainty.tpu_screen import REASONS
from tests.uncertainty.test_tpu import N_AIR, N_G, N_W, RST, C, survey

SIGMA_S = 1e-10  # the well-behaved pulses' timing sigma
ODD_GAP = 4e-9  # false bottoms 4 ns after the surface
ODD_SIGMA = [0.5e-6, 50e-6]  # timing sigmas from the scatter as the survey had (0.4-612 µs)


def _without_bottoms(ret, rows):
    """``ret`` in which the pulses ``rows`` have no bottom return."""
    keep = np.ones(len(ret), bool)
    keep[rows] = False
    zero = {k: np.where(keep, getattr(ret, k), 0.0) for k in ("t_bottom_s", "t_bottom_sigma_s")}
    conf = np.where(keep, ret.bottom_confidence, 0.0)
    return dataclasses.replace(ret, has_bottom=keep, bottom_confidence=conf, **zero)


def test_odd_pulses_are_left_out_and_the_others_keep_the_analytic_answer():
    ret, surf = survey(n_side=6)  # flat water at z = 0 over a flat 12 m seabed
    n = len(ret)
    # false bottoms 4 ns after the surface: two with an absurd sigma, one whose surface and
    # bottom sigmas of 3 ns reach the surface (hypot 4.2 ns), one whose 2 ns do not (2.8 ns)
    absurd, reaching, short = np.array([5, 17]), 23, 29
    false_bottom = np.array([5, 17, 23, 29])
    t_b = ret.t_bottom_s.copy()
    t_b[false_bottom] = ret.t_surface_s[false_bottom] + ODD_GAP
    sig = np.full(n, SIGMA_S)
    sig[reaching], sig[short] = 3e-9, 2e-9
    sig_b = sig.copy()
    sig_b[absurd] = ODD_SIGMA
    ret = dataclasses.replace(ret, t_bottom_s=t_b, t_surface_sigma_s=sig, t_bottom_sigma_s=sig_b)
    tpu = point_tpu(ret, surf, RST)  # before the fix: ValueError (t_bottom_s <= t_surface_s)

    odd = [5, 17, 23]
    np.testing.assert_array_equal(np.sort(tpu.left_out.pulse_id), odd)
    assert {REASONS[r] for r in tpu.left_out.reason} == {"timing_sigma_reaches_surface"}
    assert tpu.left_out.counts() == {"timing_sigma_reaches_surface": 3, "term_not_finite": 0}
    good = np.setdiff1d(np.arange(n), odd)
    np.testing.assert_array_equal(tpu.pulse_id, good)
    np.testing.assert_array_equal(tpu.row, good)
    assert all(np.all(np.isfinite(v)) for v in tpu.terms.values())

    # analytic: over a flat seabed the bottom's timing moves the depth along the refracted
    # beam by c dt cos(theta_w) / (2 n_g), theta_w from Snell's law of each beam's incidence;
    # the surface's (the fit was made without detector sigmas: the pulse enters at its own
    # echo) moves the entry down the beam by c dt / (2 n_air) and the path back by
    # c dt / (2 n_g): the depth below the unmoved plane by c dt (cos i / n_air - cos w / n_g) / 2
    cos_inc = -ret.direction_meas[good, 2]
    sin_w = N_AIR * np.sqrt(1.0 - cos_inc**2) / N_W
    cos_w = np.sqrt(1.0 - sin_w**2)
    per_return = C * sig[good] * cos_w / (2.0 * N_G)
    np.testing.assert_allclose(np.abs(tpu.terms["timing_bottom"][:, DEPTH]), per_return, rtol=2e-3)
    # (a difference of two near-equal paths: the noisy fitted plane's tilt shows at ~0.2 %)
    per_surface = C * sig[good] * (cos_inc / N_AIR - cos_w / N_G) / 2.0
    np.testing.assert_allclose(
        np.abs(tpu.terms["timing_surface"][:, DEPTH]), per_surface, rtol=1e-2
    )
    # and unchanged: the same pulses' TPU without the odd bottoms at all
    ref = point_tpu(_without_bottoms(ret, odd), surf, RST)
    for name in ("sigma_v_m", "sigma_h_m", "sigma_depth_m"):
        np.testing.assert_allclose(getattr(tpu, name), getattr(ref, name), rtol=1e-12)
    assert len(ref.left_out) == 0


def test_scatter_timing_is_bounded_where_the_beam_runs_along_the_seabed_gradient():
    """One sounding's seabed gradient (as false bottoms among its neighbours make it) lies
    along its refracted beam: its depth at the measured position hardly moves with the
    timing, so its neighbours' 5 cm of scatter would need a timing sigma longer than the
    recorded window (~460 ns unbounded)."""
    ret, surf = survey(n_side=6)
    n = len(ret)
    # a calm sea: no wave scatter about the planes (the TPU's wave height is 0 whatever the
    # timing sigmas), so the plane carries the entry (own-echo weight 0) and the surface's
    # timing moves nothing: the bottom's alone sets the derivative the bound is about
    surf = dataclasses.replace(surf, own_weight=np.zeros(n), fit_sigma_m=np.zeros(n))
    k = int(np.argmax(np.hypot(ret.direction_meas[:, 0], ret.direction_meas[:, 1])))
    d = ret.direction_meas[k]
    u = d[:2] / np.hypot(d[0], d[1])  # the beam's horizontal direction
    sin_w = N_AIR * np.hypot(d[0], d[1]) / N_W
    tan_w = sin_w / math.sqrt(1.0 - sin_w**2)
    grad = np.zeros((n, 2))
    # depth at the measured position moves by dL (cos w - g . u sin w): 1e-6 of it is left
    grad[k] = u / tan_w * (1.0 - 1e-6)
    scatter = np.full(n, 0.05)
    window_s = 3e-7
    bound = window_s / math.sqrt(12.0)
    out = timing_from_scatter(
        ret, surf, RST, depth_scatter_m=scatter, seabed_gradient=grad, max_sigma_s=bound
    )
    assert out.t_bottom_sigma_s[k] == pytest.approx(bound)
    assert out.t_surface_sigma_s[k] == pytest.approx(bound)
    others = np.arange(n) != k
    assert np.all(out.t_bottom_sigma_s[others] < 1e-9)  # 5 cm of depth is ~0.5 ns
    # 12 m of water is ~110 ns: a sigma of sqrt(2) x 87 ns reaches the surface, left out
    tpu = point_tpu(out, surf, RST, seabed_gradient=grad)
    assert tpu.left_out.pulse_id.tolist() == [k]
    assert tpu.left_out.counts()["timing_sigma_reaches_surface"] == 1
    # the others' random depth sigma is the scatter they were given
    np.testing.assert_allclose(tpu.sigma_depth_random_m, scatter[others], rtol=1e-3)
