"""Photon-counting depth posteriors: window histograms, dead time, and ``bathy run``.

The truth of the model tests is written here: a surface and a bottom at known times on a
nadir beam, photons drawn per shot from Gaussian echoes and a uniform background, and the
detector's non-paralyzable dead time applied shot by shot in the test itself.
"""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pytest

from pipeline.optics import SPEED_OF_LIGHT_M_S as C
from pipeline.process.photon_livetime import dead_height_m
from pipeline.process.photon_windows import PhotonWindows
from pipeline.scene import parse_scene
from pipeline.uncertainty.photon_exposure import MIN_WEIGHTED_LIVE
from pipeline.uncertainty.photon_posterior import (
    KeptPhotons,
    photon_starts,
    photon_system,
    window_candidates,
    window_histograms,
)
from pipeline.uncertainty.posterior import PosteriorSettings, interval_summary, sample_batch

ROOT = Path(__file__).resolve().parents[2]
N_AIR, N_G = 1.0003, 1.34
ALT_M, DEPTH_M = 300.0, 5.0
DEAD_S = 1.6e-9
SIGMA_S = 0.3e-9  # system response sigma (0.7 ns FWHM)


def _record(rng, n_shots, surface_pe, bottom_pe, bg_per_ns, dead_s):
    """Recorded event times per shot: echoes + background, then the dead time (in the test).

    Returns ``(offsets, times_s, t_surface_s, t_bottom_s)``.
    """
    t_s = 2.0 * N_AIR * ALT_M / C
    t_b = t_s + 2.0 * N_G * DEPTH_M / C
    gate = (t_s - 40e-9, t_b + 40e-9)
    times, offsets = [], [0]
    for _ in range(n_shots):
        ts = [
            t_s + SIGMA_S * rng.standard_normal(rng.poisson(surface_pe)),
            t_b + SIGMA_S * rng.standard_normal(rng.poisson(bottom_pe)),
            rng.uniform(*gate, rng.poisson(bg_per_ns * (gate[1] - gate[0]) * 1e9)),
        ]
        t = np.sort(np.concatenate(ts))
        kept, last = [], -np.inf
        for x in t:  # non-paralyzable: blind for dead_s after each recorded event
            if x >= last + dead_s:
                kept.append(x)
                last = x
        times.extend(kept)
        offsets.append(len(times))
    return np.array(offsets), np.array(times), t_s, t_b


def _kept(offsets, times, n_shots, dead_s):
    """One window of a nadir beam from ALT_M: the events as the chunk loop keeps them."""
    z = ALT_M - C * times / (2.0 * N_AIR)
    return KeptPhotons(
        window=np.array([0]),
        n_shots=np.array([n_shots]),
        offsets=np.array([0, z.size]),
        z_m=z,
        tau_h_m=dead_height_m(dead_s, N_AIR, np.full(z.size, -1.0)),
    )


def _posterior(kept, t_s, t_b, live=True, seed=0):
    system = photon_system(0.05, N_AIR, 2.3548 * SIGMA_S, N_G)
    y, ex, t0 = window_histograms(
        kept, np.array([0]), np.array([ALT_M]), np.array([-1.0]), [t_s], [t_b], system, N_AIR
    )
    th0 = photon_starts(y, ex, t0, [t_s], [t_b], np.ones(1), system)
    ch = sample_batch(y, system, PosteriorSettings(), exposure=ex if live else None, theta0=th0)
    return interval_summary(ch.draws[0, :, 0]), ch


def test_histogram_keeps_every_event_of_the_crop_and_the_dead_share():
    """Counts are conserved; after an event in every shot the next dead time is blind."""
    n = 50
    t_s = 2.0 * N_AIR * ALT_M / C
    t_b = t_s + 2.0 * N_G * DEPTH_M / C
    # every shot records exactly one event at the surface, and one at the bottom
    times = np.tile([t_s, t_b], n)
    kept = _kept(np.arange(0, 2 * n + 1, 2), times, n, DEAD_S)
    system = photon_system(0.05, N_AIR, 0.7e-9, N_G)
    y, ex, t0 = window_histograms(
        kept, np.array([0]), np.array([ALT_M]), np.array([-1.0]), [t_s], [t_b], system, N_AIR
    )
    assert y[0].sum() == 2 * n
    dt = system.sample_interval_s
    j_s = int(np.floor((t_s - t0[0]) / dt + 0.5))
    # samples wholly within (t_s, t_s + dead time) are blind in every shot: the floor
    blind = np.arange(m := y[0].size)
    centre = t0[0] + blind * dt
    inside = (centre - dt / 2 > t_s) & (centre + dt / 2 < t_s + DEAD_S)
    assert inside.sum() >= 2
    np.testing.assert_allclose(ex[0][inside], MIN_WEIGHTED_LIVE)
    # before the surface every channel is live
    np.testing.assert_allclose(ex[0][: j_s - 1], 1.0)
    assert m > j_s


def test_dead_time_posterior_covers_the_true_depth_the_naive_one_does_not():
    """Surface pile-up (2 pe per shot in a 1.6 ns dead time): the surface recorded early.

    With each sample's live share the posterior holds the true 5 m depth; read as plain
    Poisson counts the early surface makes the depth too deep by several sigma.
    """
    rng = np.random.default_rng(11)
    n = 2000
    off, times, t_s, t_b = _record(rng, n, 2.0, 0.15, 0.02, DEAD_S)
    kept = _kept(off, times, n, DEAD_S)
    good, ch = _posterior(kept, t_s, t_b)
    assert ch.converged[0]
    assert good["lo95"] <= DEPTH_M <= good["hi95"], good
    assert abs(good["median"] - DEPTH_M) < 2.5 * good["std"]
    naive, _ = _posterior(kept, t_s, t_b, live=False)
    assert (naive["median"] - DEPTH_M) > 3.0 * naive["std"], naive


def test_one_candidate_per_window_the_shot_nearest_its_centre():
    kept = KeptPhotons(
        np.array([3, 7]), np.array([10, 10]), np.array([0, 0, 0]), np.zeros(0), np.zeros(0)
    )
    pid = np.array([30, 34, 35, 36, 41, 70, 79, 51])
    # window 3 (30-39): centre 35; window 7 (70-79): centre 75, 70 and 79 are 5 and 4 away
    np.testing.assert_array_equal(window_candidates(pid, kept, PhotonWindows(10)), [2, 6])


def test_a_cell_windows_candidate_is_its_point_nearest_the_points_mean():
    kept = KeptPhotons(
        np.array([5, 9]), np.array([4, 3]), np.array([0, 0, 0]), np.zeros(0), np.zeros(0)
    )
    pid = np.arange(8)
    win = np.array([5, 5, 5, 5, 9, 9, 9, 2])
    xy = np.array([[0, 0], [4, 0], [1.9, 0.2], [2, 4], [0, 0], [0, 3], [0, 1.1], [0, 0]], float)
    # window 5: mean (1.975, 1.05), nearest point 2; window 9: mean (0, 1.367), nearest 6
    got = window_candidates(pid, kept, PhotonWindows(100, 10.0), win, xy)
    np.testing.assert_array_equal(got, [2, 6])


def _photon_scene(chunk_pulses):
    path = ROOT / "data_synthetic" / "scenes" / "photon_profiler.toml"
    data = tomllib.loads(path.read_text())
    data["flight"].update(area_m=[-1.0, 1.0, 0.0, 40.0])
    data.setdefault("run", {})["chunk_pulses"] = chunk_pulses
    data.setdefault("process", {}).update(posterior_pulses_per_km2=0.0, posterior_min_pulses=4)
    return parse_scene(data)


@pytest.mark.slow
def test_photon_run_reports_posteriors_the_same_for_any_whole_window_chunking(tmp_path):
    from pipeline.run import run_scene

    spw = _photon_scene(400).process.photon_detect.shots_per_window
    post = {}
    for chunk in (2 * spw, 5 * spw):
        out = tmp_path / f"c{chunk}"
        run_scene(_photon_scene(chunk), out, log=lambda _: None)
        ev = json.loads((out / "evaluation.json").read_text())["posterior_against_truth"]
        assert ev["n"] >= 2 and ev["converged_fraction"] is not None, ev
        with np.load(out / "evaluation_points.npz") as d:
            post[chunk] = {k: d[k] for k in d.files if k.startswith("post_")}
        assert post[chunk]["post_median_m"].size == ev["n"]
    a, b = post.values()
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
