"""Weak surface echoes told from noise: the detector's null shifts and the survey's test.

Truth is the flat water's own geometry: a beam of the light-wind cube scene (suite tuning seed
7102, 20° off nadir from 246 m) meets level water at the air range ``R`` of its axis, so its
surface echo starts ``2 n_air R / c`` after emission. The waveforms are the simulator's (its
Cox-Munk glint at the scene's wind, its column, its receiver noise); the detector and the
survey's test see only the samples.
"""

import dataclasses
import math

import numpy as np
import pytest
from scipy import constants

from pipeline.process.context import instrument
from pipeline.process.detect import detect_full_waveform
from pipeline.process.surface_echo_mix import echo_weight, weak_echo_test
from pipeline.scene import load_scene
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.waveform import simulate_waveforms
from pipeline.suite.cubes import cube_draws
from pipeline.suite.scene_file import write_scene

N_AIR = 1.000277
N_PULSES = 3000


@pytest.fixture(scope="module")
def light_wind_scene(tmp_path_factory):
    (draw,) = [d for d in cube_draws() if d.seed == 7102]
    return load_scene(write_scene(draw, tmp_path_factory.mktemp("scene")))


def _flat_detections(scene, n, seed, wind_m_s=None, every=None, first_pulse_id=0):
    """The detector on ``n`` simulated flat-water beams of ``scene`` (its wind, or
    ``wind_m_s``; its resampling period, or ``every``): detections, waveforms, paths."""
    ds = scene.process.detect
    if every is not None:
        ds = dataclasses.replace(ds, surface_echo_null_every=every)
    water = scene.water
    if wind_m_s is not None:
        water = dataclasses.replace(water, wind_speed_m_s=wind_m_s)
    scene = dataclasses.replace(
        scene, water=water, process=dataclasses.replace(scene.process, detect=ds)
    )
    rng = np.random.default_rng(seed)
    paths = flat_paths(
        n,
        altitude_m=scene.flight.altitude_m,
        depth_m=rng.uniform(4.0, 6.0, n),
        off_nadir_rad=math.radians(scene.scanner.off_nadir_deg),
        azimuth_rad=rng.uniform(0.0, 2.0 * math.pi, n),
        divergence_rad=scene.scanner.beam_divergence_mrad * 1e-3,
        first_pulse_id=first_pulse_id,
    )
    wf = simulate_waveforms(paths, scene, scene.detector, scene.returns)
    ins = instrument(scene, N_AIR)

    def detect(rows):
        return detect_full_waveform(
            wf.samples[rows],
            wf.sample_interval_s,
            ins.system_fwhm_s,
            ds,
            noise_samples=ins.noise_samples,
            shot_noise_counts=ins.shot_noise_counts,
            top_code=ins.amplitude_full_scale - 1.0,
            pulse_id=wf.pulse_id[rows],
        )

    return detect, wf, paths, ds


def _surface_errors_ns(scene, wind_m_s, every=1):
    """The detector on simulated flat water at ``wind_m_s``: the test's verdict and figures,
    and the mean error (ns) of the onset-alone, echo-kept and survey-mixed surface times of
    the ambiguous echoes."""
    detect, wf, paths, ds = _flat_detections(scene, N_PULSES, 1, wind_m_s, every)
    det = detect(np.arange(N_PULSES))
    t_true_s = 2.0 * N_AIR * paths.air_range_m[:, 0] / constants.c - wf.t0_s
    mix = det.surface_echo_state < 0
    pair = mix & np.isfinite(det.surface_echo_null_shift_s)
    weak, fig = weak_echo_test(
        det.surface_echo_shift_s[pair],
        det.surface_echo_null_shift_s[pair],
        ds.surface_echo_null_z,
        ds.surface_echo_null_excess,
    )
    n_clear = int(np.count_nonzero(det.surface_echo_state == 1))
    w = echo_weight(n_clear, int(mix.sum()), ds.surface_echo_prevalence_half)
    if weak and n_clear < ds.surface_echo_null_max_clear * (n_clear + int(mix.sum())):
        w = 1.0
    t_on = det.t_surface_onset_s[mix]
    shift = det.surface_echo_shift_s[mix]
    err = {
        "onset": t_on - t_true_s[mix],
        "echo": t_on + shift - t_true_s[mix],
        "mixed": t_on + w * shift - t_true_s[mix],
    }
    return weak, fig, {k: 1e9 * float(np.mean(v)) for k, v in err.items()}, pair


def test_light_wind_glints_are_told_from_calm_water_noise(light_wind_scene):
    """Calm (1 m/s: the glint at 20° is exp(-16) of nadir's): no echoes found, the mixed
    time is the onset's, unbiased; 2.7 m/s (every footprint holds a weak glint, none clear):
    found, and the mixed time is the echo-kept fit's, not the onset's 0.4 ns early one.

    Tolerances: the verdict is the survey's own rule (the shifts beyond 1.2 times the null's,
    3 standard errors). Every pulse is resampled (3000 pairs). Calm water here reads an
    excess of -4 % (the harness, 4000 pulses: benchmarks/surface_glint.py), 20 points and
    ~7 standard errors below the margin; 2.7 m/s reads +42 %, ~22 points and ~8 standard
    errors above it. The mean surface errors of ~3000 pulses scatter by 0.15 ns / sqrt(3000)
    = 0.003 ns, far inside 0.1 ns.
    """
    weak, fig, err, pair = _surface_errors_ns(light_wind_scene, 1.0)
    assert pair.sum() > 500
    assert not weak and fig["z"] < 3.0 and fig["excess"] < 0.20, fig
    assert abs(err["mixed"]) < 0.1, err  # the onset alone: right in calm water
    assert err["echo"] > 0.15, err  # the echo-kept fit, on noise: late
    weak, fig, err, _ = _surface_errors_ns(light_wind_scene, 2.7)
    assert weak and fig["z"] > 3.0 and fig["excess"] > 0.20, fig
    assert err["onset"] < -0.3, err  # what the clear-echo share alone left
    assert abs(err["mixed"]) < 0.1, err


def test_the_null_subset_and_its_noise_follow_the_pulse_numbers(light_wind_scene):
    """The resampled pulses and their null shifts are each pulse's own: the same pulses cut
    into other blocks give the same values (the survey's test reads them in any order)."""
    n = 400
    detect, wf, _, ds = _flat_detections(light_wind_scene, n, 2, first_pulse_id=1000)

    def null(rows):
        return detect(rows).surface_echo_null_shift_s

    whole = null(np.arange(n))
    parts = np.concatenate([null(np.arange(0, 137)), null(np.arange(137, n))])
    np.testing.assert_array_equal(whole, parts)
    every = ds.surface_echo_null_every
    assert np.all(np.isnan(whole[wf.pulse_id % every != 0]))
    assert np.isfinite(whole).sum() > 0


def test_the_weak_echo_test_reads_its_pairs_in_any_order():
    """Exact sums: the figures do not depend on the pulses' order; a shift that equals its
    null plus a constant c with scatter s reads z = c sqrt(k) / s (analytic)."""
    rng = np.random.default_rng(0)
    null = rng.uniform(0.1, 0.5, 2000)
    d = rng.normal(0.0, 1.0, 2000)
    d = (d - d.mean()) / d.std(ddof=1) * 0.2 + 0.05  # mean 0.05, sd 0.2 exactly
    shift = null + d
    weak, fig = weak_echo_test(shift, null, 3.0, 0.15)
    assert fig["z"] == pytest.approx(0.05 * math.sqrt(2000) / 0.2, rel=1e-12)
    assert fig["excess"] == pytest.approx(0.05 / null.mean(), rel=1e-12)
    perm = rng.permutation(2000)
    assert weak_echo_test(shift[perm], null[perm], 3.0, 0.15) == (weak, fig)
    # the verdict tests the excess beyond the margin: shifts 1.2 times the null's plus the
    # same d read z_excess = c sqrt(k) / s at a margin of 20 %, and no more than that margin
    # is not echoes
    weak2, fig2 = weak_echo_test(1.2 * null + d, null, 3.0, 0.20)
    assert weak2 and fig2["z_excess"] == pytest.approx(0.05 * math.sqrt(2000) / 0.2, rel=1e-9)
    assert weak_echo_test(1.2 * null + d - 0.05, null, 3.0, 0.20)[0] is False
    # too few pairs: no verdict
    assert weak_echo_test(shift[:10], null[:10], 3.0, 0.15)[0] is False


def test_the_survey_mix_takes_the_echoes_in_any_chunking_and_drops_the_null(light_wind_scene):
    """Through the detection store as ``bathy run`` uses it: at 2.7 m/s the survey's times are
    the echo-kept ones (weight 1), the same for 1 and 7 chunks, and the null field is gone;
    with clear echoes in more than ``surface_echo_null_max_clear`` of the pulses (the same
    pulses, a few marked clear) the verdict is not taken and the clear share's weight stands."""
    from pipeline.detection_store import DetectionStore
    from pipeline.process.surface_echo_mix import NULL_FIELD, mix_stored_echoes

    n = 3000
    detect, wf, _, ds = _flat_detections(light_wind_scene, n, 3, wind_m_s=2.7, every=1)
    det = detect(np.arange(n))
    part = {f.name: getattr(det, f.name) for f in dataclasses.fields(det)}
    part.update(
        pulse_id=wf.pulse_id,
        origin_meas_m=np.zeros((n, 3)),
        direction_meas=np.tile([0.0, 0.0, -1.0], (n, 1)),
    )
    mix = det.surface_echo_state < 0

    def run(tmp, chunks, state=None):
        p = dict(part) if state is None else {**part, "surface_echo_state": state}
        with DetectionStore(tmp, N_AIR) as st:
            for rows in np.array_split(np.arange(n), chunks):
                st.append({k: v[rows] for k, v in p.items()})
            w, summary = mix_stored_echoes(
                st,
                ds.surface_echo_prevalence_half,
                log=lambda *a: None,
                null_z=ds.surface_echo_null_z,
                null_excess=ds.surface_echo_null_excess,
                null_max_clear=ds.surface_echo_null_max_clear,
            )
            t = np.concatenate(
                [st.load_chunk(c, ["t_surface_s"])["t_surface_s"] for c in range(len(st.chunks))]
            )
            left = set().union(*(st.fields(c) for c in range(len(st.chunks))))
        assert summary["weight"] == w and summary["weak_echoes"]["pairs"] > 30
        return w, t, left

    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as a, tempfile.TemporaryDirectory() as b:
        w1, t1, left = run(Path(a), 1)
        w7, t7, _ = run(Path(b), 7)
    assert w1 == w7 == 1.0
    np.testing.assert_array_equal(t1, t7)
    echo_kept = det.t_surface_onset_s + det.surface_echo_shift_s
    np.testing.assert_array_equal(t1[mix], echo_kept[mix])
    assert NULL_FIELD not in left
    # 2 % of the pulses marked clear: a wave sea's mixture, the clear share's weight stands
    state = det.surface_echo_state.copy()
    marked = np.flatnonzero(mix)[::50]
    state[marked] = 1.0
    with tempfile.TemporaryDirectory() as c:
        w, _, _ = run(Path(c), 3, state)
    clear, ambiguous = int(np.sum(state == 1.0)), int(np.sum(state < 0))
    assert clear > ds.surface_echo_null_max_clear * (clear + ambiguous)
    assert w == pytest.approx(echo_weight(clear, ambiguous, ds.surface_echo_prevalence_half))


def test_the_share_of_clear_echoes_is_counted_per_off_nadir_band(tmp_path):
    """A scan over a light sea: at nadir 40 % of the judged echoes are clear (glints), at
    18 degrees none are. An ambiguous echo at 18 degrees is the onset's noise (its time the
    onset's), one at nadir is most likely a weak glint (the echo-kept time): one share for the
    survey (band 90 degrees) gave both the echo-kept weight, 18 degrees' too. The same times
    for any chunking."""
    from pipeline.detection_store import DetectionStore
    from pipeline.process.surface_echo_mix import mix_stored_echoes

    n = 4000
    rng = np.random.default_rng(5)
    off = np.radians(np.where(np.arange(n) % 2 == 0, 0.5, 18.0))  # nadir, 18 degrees
    az = rng.uniform(0.0, 2.0 * np.pi, n)
    d = np.column_stack([np.sin(off) * np.cos(az), np.sin(off) * np.sin(az), -np.cos(off)])
    nadir = off < np.radians(1.0)
    state = np.where(nadir & (rng.random(n) < 0.4), 1, -1).astype(np.int8)
    onset, shift = np.full(n, 1.0e-6), np.full(n, 1.0e-9)
    part = {
        "pulse_id": np.arange(n),
        "origin_meas_m": np.zeros((n, 3)),
        "direction_meas": d,
        "t_surface_s": onset + shift,
        "has_surface": np.ones(n, bool),
        "has_bottom": np.zeros(n, bool),
        "t_bottom_s": np.zeros(n),
        "surface_echo_state": state,
        "t_surface_onset_s": onset,
        "surface_echo_shift_s": shift,
    }

    def times(chunks, band_deg):
        with DetectionStore(tmp_path, N_AIR) as st:
            for rows in np.array_split(np.arange(n), chunks):
                st.append({k: v[rows] for k, v in part.items()})
            _, summary = mix_stored_echoes(
                st, 0.02, log=lambda *a: None, band_deg=band_deg, prior_pulses=1.0
            )
            t = np.concatenate(
                [st.load_chunk(c, ["t_surface_s"])["t_surface_s"] for c in range(len(st.chunks))]
            )
        return (t - onset) / shift, summary  # the echo-kept weight each pulse took

    w, summary = times(1, 2.0)
    amb = state < 0
    assert np.all(w[amb & ~nadir] < 0.05) and np.all(w[amb & nadir] > 0.9)
    assert np.all(w[~amb] == pytest.approx(1.0))  # a clear echo keeps its time
    assert [b["from_deg"] for b in summary["bands"]] == [0.0, 18.0]
    np.testing.assert_array_equal(times(7, 2.0)[0], w)
    one, _ = times(3, 90.0)
    assert np.all(one[amb] > 0.9)  # one share: 18 degrees' noise read as echoes
