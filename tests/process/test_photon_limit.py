"""Photon-counting detection limit: where a bottom of the assumed reflectance sinks under the
threshold, from a column and background written here (truth by formula, not by the detector)."""

import math

import numpy as np
from scipy import stats

from pipeline.process.detect_photons import PhotonDetectSettings, detect_photon_events
from pipeline.process.detection_limit import NoBottomSettings
from pipeline.process.returns import DetectorFlag

C = 299_792_458.0
N_AIR, N_G = 1.000277, 1.3638
H_M = 300.0
T_S = 2 * H_M * N_AIR / C
GATE_M = (-20.0, 180.0)  # range gate around the surface, air-range metres (up, down)


def _events(n_shots, lam_col, col_m, lam_bg, lam_b=0.0, bottom_m=0.0, seed=0):
    """Surface, an exponential column of e-folding ``col_m`` (air range), background, bottom."""
    rng = np.random.default_rng(seed)
    to_t = 2 * N_AIR / C
    shots = []
    for _ in range(n_shots):
        ks, kc, kg, kb = (rng.poisson(x) for x in (0.5, lam_col, lam_bg, lam_b))
        shots.append(
            np.sort(
                np.concatenate(
                    [
                        T_S + 0.3e-9 * rng.standard_normal(ks),
                        T_S + to_t * rng.exponential(col_m, kc),
                        T_S + to_t * rng.uniform(-GATE_M[0], GATE_M[1], kg),
                        T_S + to_t * bottom_m + 0.3e-9 * rng.standard_normal(kb),
                    ]
                )
            )
        )
    offsets = np.r_[0, np.cumsum([len(t) for t in shots])]
    origin = np.column_stack([np.arange(n_shots) * 0.006, np.zeros(n_shots), np.full(n_shots, H_M)])
    return offsets, np.concatenate(shots), origin, np.tile([0.0, 0.0, -1.0], (n_shots, 1))


def _expected_limit_m(n, lam_col, col_m, lam_bg, nb: NoBottomSettings, s: PhotonDetectSettings):
    """The limit by formula: the shallowest air-range depth where ``r C(h) < λ* - mu``.

    ``λ*``: the box's expected count that stands ``z_p √λ*`` above the threshold count ``k*``
    (the assumed bottom detected with probability ``p``; ``λ* = k*`` at one half).
    """
    bin_m, width = s.bin_m, 2 * s.centroid_bins + 1
    h = np.arange(0.0, 60.0, bin_m)
    col = n * lam_col * bin_m / col_m * np.exp(-h / col_m)  # column counts per bin
    bg = n * lam_bg * bin_m / (GATE_M[1] - GATE_M[0])  # background counts per bin
    r = nb.bottom_reflectance / (math.pi * nb.backscatter_180_per_m_sr * bin_m * N_AIR / N_G)
    mu = (col + bg) * width
    n_searched = (GATE_M[1] - GATE_M[0]) / bin_m
    k_star = stats.poisson.isf(stats.norm.sf(s.threshold_sigma) / n_searched, mu) + 1
    z = stats.norm.ppf(nb.detection_probability)
    lam_star = ((z + np.sqrt(z * z + 4.0 * k_star)) / 2.0) ** 2  # λ - z √λ = k*
    return h[np.argmax(r * col < lam_star - mu)]


def test_detection_limit_is_the_depth_a_bottom_would_sink_under_the_threshold():
    s, nb = PhotonDetectSettings(), NoBottomSettings()
    lam_col, col_m, lam_bg = 2.0, 2.0, 2.0
    offsets, times, o, d = _events(10_000, lam_col, col_m, lam_bg, seed=4)
    det = detect_photon_events(offsets, times, o, d, N_AIR, s, no_bottom=nb, group_index=N_G)
    assert not det.has_bottom.any()
    limit_m = (det.t_detection_limit_s - det.t_surface_s) * C / (2 * N_AIR)
    expected = _expected_limit_m(s.shots_per_window, lam_col, col_m, lam_bg, nb, s)
    assert 10.0 < expected < 16.0  # far below where the column itself is seen (~5 m)
    # 50 windows; each fits its column over ~5 m and extrapolates it: the median within 0.5 m
    assert (det.t_detection_limit_s > 0).all()
    assert abs(np.median(limit_m) - expected) < 0.5
    # class 45 claims no more than the limit (and no more than the column shows)
    assert (det.t_no_bottom_s > 0).all() and (det.t_no_bottom_s <= det.t_detection_limit_s).all()


def test_a_weak_bottom_past_the_limit_is_flagged_a_strong_one_is_not():
    s = PhotonDetectSettings()
    # a backscatter assumed 25x the default: the assumed bottom is dim next to the column, so
    # the limit is shallow (~4 m here), and a real bottom at 8 m is past it
    nb = NoBottomSettings(backscatter_180_per_m_sr=0.05)
    lam_col, col_m, lam_bg = 2.0, 2.0, 2.0
    args = (lam_col, col_m, lam_bg)
    limit = _expected_limit_m(s.shots_per_window, *args, nb, s)
    assert limit < 6.0
    bit = np.uint16(DetectorFlag.BEYOND_DETECTION_LIMIT)
    # ~24 bottom photons per window over ~2.8 column + background in its box: ~5.5-9 σ, under
    # twice the threshold
    weak = _events(10_000, *args, lam_b=0.12, bottom_m=8.0, seed=5)
    det = detect_photon_events(*weak, N_AIR, s, no_bottom=nb, group_index=N_G)
    flagged = det.has_bottom & ((det.flags & bit) != 0)
    assert det.has_bottom.mean() > 0.5
    assert flagged.sum() >= 0.8 * det.has_bottom.sum()
    # 60 photons per window: far above the threshold, the bottom is told from anything
    strong = _events(10_000, *args, lam_b=0.3, bottom_m=8.0, seed=6)
    det = detect_photon_events(*strong, N_AIR, s, no_bottom=nb, group_index=N_G)
    assert det.has_bottom.all()
    assert not ((det.flags & bit) != 0).any()
