"""Dead time: first-photon bias and the blind gap after a saturated surface (photon counting).

Photon times are drawn here from echoes of known shape and thinned by a non-paralyzable dead
time written in the test; the truth is the echoes' own centres and the first-photon formula.
"""

import numpy as np
from scipy import integrate, stats

from pipeline.process.detect_photons import PhotonDetectSettings, detect_photon_events

C = 299_792_458.0
N_AIR = 1.000277
H_M = 300.0
T_S = 2 * H_M * N_AIR / C  # surface echo centre, s
SIG_S = 0.3e-9  # echo sigma: a 0.7 ns FWHM pulse
TAU_S = 1.6e-9  # dead time per channel


def _dead_time(times_per_shot, tau_s):
    """Non-paralyzable dead time of one channel: keep an event only ``tau`` after the last kept."""
    out = []
    for t in times_per_shot:
        kept, last = [], -np.inf
        for ti in np.sort(t):
            if ti - last >= tau_s:
                kept.append(ti)
                last = ti
        out.append(np.array(kept))
    return out


def _shots(n_shots, lam_s, seed, lam_col=0.0, col_scale_s=10e-9, lam_b=0.0, t_b=0.0, lam_bg=0.2):
    """Surface Gaussian, exponential water column below it, optional bottom, uniform background."""
    rng = np.random.default_rng(seed)
    gate0, gate1 = T_S - 50e-9, T_S + 150e-9
    shots = []
    for _ in range(n_shots):
        ks, kc, kb, kg = (rng.poisson(x) for x in (lam_s, lam_col, lam_b, lam_bg))
        shots.append(
            np.concatenate(
                [
                    T_S + SIG_S * rng.standard_normal(ks),
                    T_S + rng.exponential(col_scale_s, kc),
                    t_b + SIG_S * rng.standard_normal(kb),
                    rng.uniform(gate0, gate1, kg),
                ]
            )
        )
    shots = _dead_time(shots, TAU_S)
    offsets = np.r_[0, np.cumsum([len(t) for t in shots])]
    origin = np.column_stack([np.arange(n_shots) * 0.006, np.zeros(n_shots), np.full(n_shots, H_M)])
    direction = np.tile([0.0, 0.0, -1.0], (n_shots, 1))
    return offsets, np.concatenate(shots), origin, direction


def _first_photon_mean_s(lam):
    """Mean recorded time of a Gaussian echo of ``lam`` photoelectrons per shot when only the
    first is recorded (dead time >> echo): density ``lam f(t) exp(-lam F(t)) / (1 - e^-lam)``."""
    f = stats.norm(T_S, SIG_S)

    def g(t):
        return lam * f.pdf(t) * np.exp(-lam * f.cdf(t))

    lo, hi = T_S - 8 * SIG_S, T_S + 8 * SIG_S
    # integrate (t - T_S) for precision
    num = integrate.quad(lambda t: (t - T_S) * g(t), lo, hi, points=[T_S])[0]
    return T_S + num / -np.expm1(-lam)


def test_dead_time_first_photon_bias_is_corrected():
    lam = 2.0
    offsets, times, o, d = _shots(20_000, lam, seed=1)
    s = PhotonDetectSettings()
    biased = detect_photon_events(offsets, times, o, d, N_AIR, s)
    fixed = detect_photon_events(offsets, times, o, d, N_AIR, s, dead_time_s=TAU_S)
    assert biased.has_surface.all() and fixed.has_surface.all()
    t_first = _first_photon_mean_s(lam)
    # the formula's bias: ~ -0.55 sigma = -0.17 ns (2.5 cm of range) at 2 photoelectrons
    assert t_first - T_S < -0.15e-9
    # uncorrected: the detector reproduces the first-photon formula (100 windows of 200 shots:
    # ~0.03 ns standard error of the mean)
    assert abs(biased.t_surface_s.mean() - t_first) < 0.03e-9
    # live-time corrected: the echo's true centre, within 0.03 ns (0.45 cm)
    assert abs(fixed.t_surface_s.mean() - T_S) < 0.03e-9


def test_column_after_a_saturated_surface_is_no_bottom():
    # 5 photoelectrons at the surface: nearly every shot's channel fires there and is blind for
    # the next 1.6 ns (0.24 m); the column resumes below that gap. No seabed in the gate.
    offsets, times, o, d = _shots(20_000, 5.0, seed=2, lam_col=1.5)
    det = detect_photon_events(offsets, times, o, d, N_AIR, dead_time_s=TAU_S)
    assert det.has_surface.all()
    assert not det.has_bottom.any()


def test_bottom_below_a_saturated_surface_is_found():
    depth_range_m = 6.0  # apparent (air-range) depth of the seabed echo
    t_b = T_S + 2 * depth_range_m * N_AIR / C
    offsets, times, o, d = _shots(20_000, 5.0, seed=3, lam_col=1.5, lam_b=0.4, t_b=t_b)
    det = detect_photon_events(offsets, times, o, d, N_AIR, dead_time_s=TAU_S)
    assert det.has_bottom.mean() > 0.95
    # the bottom echo's centre: ~80 photons of 0.3 ns per window over the column's slope
    err = det.t_bottom_s[det.has_bottom] - t_b
    assert abs(err.mean()) < 0.05e-9 and np.abs(err).max() < 0.3e-9


def test_piled_up_surface_is_timed_at_its_centre():
    # a nadir water surface: 20 photoelectrons per shot on one channel whose dead time (1.6 ns)
    # outlasts the echo (0.3 ns sigma), so each shot records only its first surface photon, on
    # average ~1.9 sigma early (the formula below). The live share is ~e^-10 at the echo's centre:
    # the live-time correction cannot restore the echo's later half, the pulse's known shape can.
    lam = 20.0
    offsets, times, o, d = _shots(4000, lam, seed=4, lam_col=0.5)
    assert _first_photon_mean_s(lam) - T_S < -0.5e-9  # what the recorded events' mean says
    s = PhotonDetectSettings()
    det = detect_photon_events(
        offsets, times, o, d, N_AIR, s, dead_time_s=TAU_S, pulse_sigma_s=SIG_S
    )
    assert det.has_surface.all()
    # 20 windows of 200 shots, a few hundred leading-edge events each: the echo's true centre
    # within 0.03 ns (4.5 mm of range); the live-time corrected centroid lies ~0.25 ns early
    assert abs(det.t_surface_s.mean() - T_S) < 0.03e-9
    assert np.abs(det.t_surface_s - T_S).max() < 0.1e-9


def test_piled_up_bright_bottom_is_timed_at_its_centre():
    # a bright shallow seabed: 10 photoelectrons per shot 2 m (air range) under a 20 pe
    # surface, over a water column: the live share falls to ~e^-5 at the echo's centre and the
    # live-time corrected centroid lies ~0.15 ns early (2.2 cm shallow in range)
    t_b = T_S + 2 * 2.0 * N_AIR / C
    offsets, times, o, d = _shots(4000, 20.0, seed=5, lam_col=1.0, lam_b=10.0, t_b=t_b)
    det = detect_photon_events(offsets, times, o, d, N_AIR, dead_time_s=TAU_S, pulse_sigma_s=SIG_S)
    assert det.has_bottom.all()
    assert abs(det.t_bottom_s.mean() - t_b) < 0.03e-9
    assert abs(det.t_surface_s.mean() - T_S) < 0.03e-9
