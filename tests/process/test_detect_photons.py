import dataclasses

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


# --- shallow water: the seabed echo can be brighter than the surface echo ------------------
# Heights are written here: the water surface at z = 0 under a nadir beam from H = 300 m, the
# seabed D below it; in time the bottom lies 2 D n_g / c after the surface (no refraction at
# nadir). The detector places events at z = H - c t / (2 n_air), so the true heights are
# z_surface = 0 and z_bottom = -D n_g / n_air.
@pytest.mark.parametrize("depth_m", [0.3, 0.5, 1.0, 2.0])
def test_surface_is_the_first_return_when_the_seabed_is_brighter(depth_m):
    # 0.5 surface and 1.5 seabed photons per shot: the seabed bin holds 3x the surface's
    offsets, times, o, d, t_s, t_b = _events(
        2000, depth_m, lam_s=0.5, lam_b=1.5, lam_bg=1.0, seed=int(100 * depth_m)
    )
    det = detect_photon_events(offsets, times, o, d, N_AIR, PhotonDetectSettings())
    z_s = 300.0 - C * det.t_surface_s / (2 * N_AIR)
    z_b = 300.0 - C * det.t_bottom_s / (2 * N_AIR)
    assert det.has_surface.all()
    # 100 surface photons of σ 7.5 cm per window: the centroid to ~1 cm; 4 cm allows 3σ and,
    # at 0.3 m (echoes 0.41 m apart in range), the cut of the surface's lower tail at the
    # emptiest bin before the seabed echo (up to ~10 % of its photons: ≤ 2 cm high)
    assert np.abs(z_s).max() < 0.04
    assert det.has_bottom.all()
    assert np.abs(z_b + depth_m * N_G / N_AIR).max() < 0.03
    depth = C * (det.t_bottom_s - det.t_surface_s) / (2 * N_G)
    assert np.abs(depth - depth_m).max() < 0.04


def test_merged_surface_and_bottom_give_no_bottom():
    # D = 0.1 m: 0.14 m apart in range, under 2σ of the 7.5 cm echoes, and within the 0.3 m
    # minimum separation: one merged echo. No bottom is reported rather than a wrong one, and
    # the surface lies within the merged echo, between the true surface and the true bottom
    offsets, times, o, d, *_ = _events(2000, 0.1, lam_s=0.5, lam_b=1.5, seed=5)
    det = detect_photon_events(offsets, times, o, d, N_AIR)
    z_s = 300.0 - C * det.t_surface_s / (2 * N_AIR)
    assert det.has_surface.all() and not det.has_bottom.any()
    assert np.all((z_s < 0.03) & (z_s > -0.1 * N_G / N_AIR - 0.03))


def test_sparse_background_photons_above_the_surface_are_not_a_surface():
    # 0.05 background photons per shot over a 100 m gate: about 0.01 per 0.1 m bin per window,
    # so most bins are empty and a lone photon high above the water must not pass as a return
    offsets, times, o, d, t_s, _ = _events(2000, 2.0, lam_s=0.5, lam_b=1.5, lam_bg=0.05, seed=3)
    rng = np.random.default_rng(4)
    # the gate reaches 50 m above the surface: spread the background over it
    gate = rng.uniform(t_s - 330e-9, t_s + 40e-9, size=times.size)
    times = np.where(rng.random(times.size) < 0.05 / 2.0, gate, times)
    det = detect_photon_events(offsets, times, o, d, N_AIR)
    z_s = 300.0 - C * det.t_surface_s / (2 * N_AIR)
    assert det.has_surface.all()
    assert np.abs(z_s).max() < 0.03


# --- no bottom: down to where the water column is seen, not the end of the range gate ------
def _column_events(n_shots, column_m, lam_col=2.0, seed=0):
    """Surface echo, a water column of uniform return over ``column_m`` of water, background."""
    offsets, times, o, d, t_s, _ = _events(n_shots, 30.0, lam_b=0.0, seed=seed)
    rng = np.random.default_rng(seed + 100)
    t_end = t_s + 2.0 * column_m * N_G / C
    k = rng.poisson(lam_col, n_shots)
    shot = np.repeat(np.arange(n_shots), k)
    extra = rng.uniform(t_s, t_end, k.sum()) if column_m > 0 else np.zeros(0)
    old_shot = np.repeat(np.arange(n_shots), np.diff(offsets))
    all_shot = np.concatenate([old_shot, shot[: extra.size]])
    all_t = np.concatenate([times, extra])
    order = np.lexsort((all_t, all_shot))
    new_offsets = np.r_[0, np.cumsum(np.bincount(all_shot, minlength=n_shots))]
    return new_offsets, all_t[order], o, d, t_s, t_end


def test_no_bottom_limit_is_where_the_column_is_last_seen():
    # 2 column photons a shot spread over 3 m of water (200 a window over ~60 bins of 0.1 m in
    # air range: ~3.3 a bin against 1 background photon per shot over 80 m: ~0.25 a bin)
    offsets, times, o, d, t_s, t_end = _column_events(2000, 3.0, seed=3)
    det = detect_photon_events(offsets, times, o, d, N_AIR)
    assert det.has_surface.all() and not det.has_bottom.any()
    # the last box (±2 bins of 0.67 ns) still significant straddles the column's end (by
    # < 0.4 ns here); the claim stands above it by the echo's reach, at least the box's half
    # (2 bins; no response sigma is given here) and at most two halves (the surface peak's
    # search keeps it within 2 boxes' half of the top box): it never passes the light's end,
    # and lies within 6 bins (4 ns) of it
    short = t_end - det.t_no_bottom_s
    assert np.all((short > 0.0) & (short < 4.0e-9))


def _seabed_under_column(n_shots, depth_m, lam_b, lam_col=2.0, seed=0):
    """A seabed ``depth_m`` under the surface, the column's photons between them (none below
    it: the seabed is opaque), background photons over the whole gate."""
    offsets, times, o, d, t_s, t_b = _events(n_shots, depth_m, lam_s=0.5, lam_b=lam_b, seed=seed)
    rng = np.random.default_rng(seed + 100)
    k = rng.poisson(lam_col * depth_m / 3.0, n_shots)  # _column_events' photons per metre
    shot = np.concatenate(
        [np.repeat(np.arange(n_shots), np.diff(offsets)), np.repeat(np.arange(n_shots), k)]
    )
    t = np.concatenate([times, rng.uniform(t_s, t_b, k.sum())])
    order = np.lexsort((t, shot))
    offsets = np.r_[0, np.cumsum(np.bincount(shot, minlength=n_shots))]
    return offsets, t[order], o, d, t_s, t_b


@pytest.mark.parametrize("depth_m, lam_b", [(0.2, 5.0), (0.25, 1.5)])
def test_no_claim_past_a_seabed_merged_into_the_surface_echo(depth_m, lam_b):
    # a seabed too near the surface to be told apart (0.2-0.25 m: within min_separation_m)
    # ends the run of significant boxes the box's half and its echo's tail below itself: a
    # claim at the run's end said "no bottom" 0.2-0.28 m past it (the code before this test:
    # in 20-100 % of these windows). No window may claim the absence of a bottom it has
    offsets, times, o, d, t_s, t_b = _seabed_under_column(
        4000, depth_m, lam_b, seed=int(1000 * depth_m + 10 * lam_b)
    )
    det = detect_photon_events(offsets, times, o, d, N_AIR, pulse_sigma_s=0.5e-9)
    claimed = det.t_no_bottom_s > 0.0
    assert np.all(det.t_no_bottom_s[claimed] <= t_b)


@pytest.mark.parametrize("depth_m, lam_col", [(0.8, 2.0), (1.2, 2.0), (1.5, 6.0)])
def test_a_seabed_too_dim_to_find_is_claimed_above_itself(depth_m, lam_col):
    # 0.05 seabed photons a shot (10 a window, under the column's level): not found. The
    # column's light ends at the seabed, so every window can claim, but only above it: the
    # code before this test claimed 0.08-0.15 m past it in every window. The claim stands
    # above the seabed by the echo's reach (4 bins of 0.1 m air range, 0.29 m of water)
    # less the last box's straddle: within 0.45 m of it
    offsets, times, o, d, t_s, t_b = _seabed_under_column(
        4000, depth_m, 0.05, lam_col=lam_col, seed=int(1000 * depth_m + 5)
    )
    det = detect_photon_events(offsets, times, o, d, N_AIR, pulse_sigma_s=0.5e-9)
    claimed = det.t_no_bottom_s > 0.0
    assert claimed.mean() >= 0.9
    short_m = (t_b - det.t_no_bottom_s[claimed]) * C / (2 * N_G)
    assert np.all((short_m >= 0.0) & (short_m < 0.45))


def test_opaque_water_establishes_no_bottom_depth():
    # no column photons at all (the column dies inside the surface echo): no limit, where the
    # range gate's end (~50 ns below the 30 m "seabed" here) would claim ~40 m of water
    offsets, times, o, d, *_ = _column_events(2000, 0.0, lam_col=0.0, seed=4)
    det = detect_photon_events(offsets, times, o, d, N_AIR)
    assert det.has_surface.all() and not det.has_bottom.any()
    assert np.all(det.t_no_bottom_s == 0.0)


# --- dead-time pile-up: a surface echo that fires (nearly) every shot is flagged -------------
@pytest.mark.parametrize("lam_s, saturated", [(0.5, False), (1.5, False), (20.0, True)])
def test_surface_pileup_is_flagged_saturated(lam_s, saturated):
    # λ surface photoelectrons a shot on one channel: a shot has a surface event with
    # probability 1 − exp(−λ) (0.39, 0.78, ~1); the flag is set from λ = 3 (95 %) up, where the
    # first photon of nearly every shot comes early in the echo (test_known_failures: at 3,
    # 0.31 ns early)
    from pipeline.process.returns import DetectorFlag

    offsets, times, o, d, *_ = _events(2000, 10.0, lam_s=lam_s, seed=11)
    det = detect_photon_events(offsets, times, o, d, N_AIR)
    assert det.has_surface.all()
    flagged = (det.flags & np.uint16(DetectorFlag.SATURATED)) != 0
    assert flagged.all() if saturated else not flagged.any()


def _join(parts):
    """Concatenate per-shot event lists given as (offsets, times, origin, direction)."""
    offs, times, origins, dirs, base = [np.zeros(1, np.int64)], [], [], [], 0
    for o, t, og, d in parts:
        offs.append(o[1:] + base)
        base += int(o[-1])
        times.append(t)
        origins.append(og)
        dirs.append(d)
    return np.concatenate(offs), np.concatenate(times), np.vstack(origins), np.vstack(dirs)


def test_a_window_detects_the_same_in_any_chunk_of_whole_windows():
    """Windows over shallow water, then over deep water (a longer range gate): the shallow
    windows alone, or chunked with the deep ones, must give the same detections; their
    photons do not change, only the other windows of the chunk do."""
    # faint echoes: their significance (so their confidence) is not saturated
    shallow = _events(600, 3.0, lam_s=0.3, lam_b=0.1, seed=11)[:4]
    deep = _events(400, 30.0, lam_bg=3.0, seed=12)[:4]
    offsets, times, origin, direction = _join([shallow, deep])
    ids = np.arange(1000)
    whole = detect_photon_events(offsets, times, origin, direction, N_AIR, pulse_id=ids)
    alone = detect_photon_events(*shallow, N_AIR, pulse_id=ids[:600])
    assert alone.has_surface.all() and alone.has_bottom.any()
    for f in dataclasses.fields(alone):
        np.testing.assert_array_equal(getattr(whole, f.name)[:600], getattr(alone, f.name), f.name)
