import numpy as np
import pytest

from pipeline.process.detect_photons import PhotonDetectSettings, detect_photon_events

C = 299_792_458.0
N_AIR, N_G = 1.000277, 1.3638


def _events(n_shots, depth_m, lam_s=3.0, lam_b=0.2, lam_bg=1.0, h_m=300.0, seed=0):
    """Photon times written here: surface and bottom Gaussians, uniform background."""
    rng = np.random.default_rng(seed)
    t_s = 2 * h_m * N_AIR / C
    t_b = t_s + 2 * depth_m * N_G / C
    sig = 0.5e-9
    gate0, gate1 = t_s - 50e-9, t_b + 50e-9
    per_shot = []
    for _ in range(n_shots):
        ks, kb, kg = rng.poisson(lam_s), rng.poisson(lam_b), rng.poisson(lam_bg)
        t = np.concatenate(
            [
                t_s + sig * rng.standard_normal(ks),
                t_b + sig * rng.standard_normal(kb),
                rng.uniform(gate0, gate1, kg),
            ]
        )
        per_shot.append(np.sort(t))
    offsets = np.r_[0, np.cumsum([len(t) for t in per_shot])]
    origin = np.column_stack([np.arange(n_shots) * 0.006, np.zeros(n_shots), np.full(n_shots, h_m)])
    direction = np.tile([0.0, 0.0, -1.0], (n_shots, 1))
    return offsets, np.concatenate(per_shot), origin, direction, t_s, t_b


@pytest.mark.parametrize("depth_m", [2.0, 10.0, 25.0])
def test_surface_and_bottom_times_from_accumulated_photons(depth_m):
    offsets, times, o, d, t_s, t_b = _events(4000, depth_m, seed=int(depth_m))
    det = detect_photon_events(offsets, times, o, d, N_AIR, PhotonDetectSettings())
    assert det.has_surface.all() and det.has_bottom.all()
    # 200 shots × 0.2 bottom photons = 40 photons of σ 7.5 cm: centroid to ~2 cm; 0.3 ns = 4 cm
    assert np.abs(det.t_surface_s - t_s).max() < 0.3e-9
    assert np.abs(det.t_bottom_s - t_b).max() < 0.5e-9
    depth = C * (det.t_bottom_s - det.t_surface_s) / (2 * N_G)
    assert np.sqrt(np.mean((depth - depth_m) ** 2)) < 0.05


def test_no_bottom_photons_means_no_bottom():
    offsets, times, o, d, *_ = _events(2000, 10.0, lam_b=0.0, seed=9)
    det = detect_photon_events(offsets, times, o, d, N_AIR)
    assert det.has_surface.all()
    assert not det.has_bottom.any()


def test_no_photons_at_all():
    o = np.tile([0.0, 0.0, 300.0], (10, 1))
    d = np.tile([0.0, 0.0, -1.0], (10, 1))
    det = detect_photon_events(np.zeros(11, np.int64), np.zeros(0), o, d, N_AIR)
    assert not det.has_surface.any() and np.all(np.isfinite(det.t_surface_s))
