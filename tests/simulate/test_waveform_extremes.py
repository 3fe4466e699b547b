"""Extreme cases: every output finite, and flagged where the data are unusable."""

from __future__ import annotations

import math

import numpy as np
import pytest
from waveform_support import detector, make_scene, replace

from pipeline.simulate import detector as D
from pipeline.simulate import paths as P
from pipeline.simulate import waveform as W
from pipeline.simulate.budget import return_budget
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.geometry import LOG_ZERO


def _grazing(paths):
    # incidence exactly 90 degrees on the surface (a facet seen edge-on)
    half_pi = np.full_like(paths.incidence_rad, 0.5 * math.pi)
    return replace(paths, incidence_rad=half_pi, bottom_incidence_rad=half_pi)


def _missing(paths):
    z = np.zeros_like(paths.air_range_m)
    return replace(paths, flags=np.full_like(paths.flags, P.MISS), air_range_m=z, water_path_m=z,
                   transmittance_down=z, transmittance_up=z)  # fmt: skip


CASES = {
    # name: (scene overrides, flat_paths kwargs, paths transform, detector kwargs, required flags)
    "zero_photons": ({"system": {"pulse_energy_j": 1e-30}}, {}, None, {}, D.NO_SIGNAL),
    "zero_extinction": (
        {"water": {"extinction_per_m": 0.0}, "atmosphere": {"extinction_per_m": 0.0}},
        {"depth_m": 30.0},
        None,
        {},
        0,
    ),
    "huge_extinction": (
        {"water": {"extinction_per_m": 100.0}},
        {"depth_m": 100.0},
        None,
        {},
        D.BOTTOM_BELOW_NOISE | D.BOTTOM_OUTSIDE_WINDOW,
    ),
    "grazing_incidence": ({}, {"off_nadir_rad": 1.5}, _grazing, {}, D.NO_SIGNAL),
    "near_horizontal_beam": ({}, {"off_nadir_rad": math.radians(89.9)}, None, {}, D.NO_SIGNAL),
    "depth_5_cm": ({}, {"depth_m": 0.05}, None, {}, D.MERGED_SURFACE_BOTTOM),
    "depth_100_m": (
        {},
        {"depth_m": 100.0},
        None,
        {},
        D.BOTTOM_BELOW_NOISE | D.BOTTOM_OUTSIDE_WINDOW,
    ),  # fmt: skip
    "saturation": ({"system": {"pulse_energy_j": 1.0}}, {}, None, {}, D.SATURATED),
    "black_bottom": ({"seabed": {"reflectance": 0.0}}, {}, None, {}, D.BOTTOM_BELOW_NOISE),
    "land": ({}, {"depth_m": -3.0}, None, {}, D.LAND_RETURN),
    "all_subrays_miss": ({}, {}, _missing, {}, D.NO_SIGNAL | D.PARTIAL_FOOTPRINT),
    # the seabed drops at 1.35 rad, steeper than the refracted ray (1.21 rad below horizontal)
    "steep_seabed_no_bottom": (
        {},
        {"seabed_slope_rad": 1.35, "off_nadir_rad": 0.5},
        None,
        {},
        D.PARTIAL_FOOTPRINT,
    ),  # fmt: skip
    "one_sample_window": ({}, {}, None, {"window_s": 1e-9}, D.BOTTOM_OUTSIDE_WINDOW),
    "whitecaps_40_m_s": ({"water": {"wind_speed_m_s": 40.0}}, {}, None, {}, 0),
    "dark_and_sun": (
        {"background": {"solar_irradiance_w_m2_nm": 2.5}, "system": {"dark_count_rate_hz": 1e7}},
        {},
        None,
        {},
        0,
    ),  # fmt: skip
}


#: the frozen scene's single-scattering physics, and the field-of-view attenuation with the
#: forward-scattering delay (issue 12)
PHYSICS = {
    "single": {},
    "fov_delay": {"returns": {"lidar_attenuation": "fov", "forward_scatter": "small_angle"}},
}


@pytest.mark.parametrize("physics", list(PHYSICS))
@pytest.mark.parametrize("name", list(CASES))
def test_extreme_case_is_finite_and_flagged(name, physics):
    sections, kw, transform, det_kw, required = CASES[name]
    scene = make_scene(**sections, **PHYSICS[physics])
    args = {"altitude_m": 300.0, "depth_m": 8.0}
    args.update(kw)
    paths = flat_paths(4, n_sub=1, **args)
    if transform is not None:
        paths = transform(paths)
    dkw = {"window_s": 3e-7, "pre_trigger_s": 2e-8, "electronic_noise_counts": 1.0}
    dkw.update({"counts_per_photoelectron": 0.5, **det_kw})
    det = detector(**dkw)
    b = return_budget(paths, scene, det)
    for name_, val in vars(b).items():
        if isinstance(val, np.ndarray):
            assert np.all(np.isfinite(val)), name_
            if name_.startswith("log"):
                assert np.all(val >= LOG_ZERO), name_
    exp = W.expected_waveform(b)
    assert all(np.all(np.isfinite(v)) and np.all(v >= 0) for v in exp.values())
    noisy = W.simulate_waveforms(paths, scene, det)
    clean = W.simulate_waveforms(paths, scene, det, noise=False)
    events = W.simulate_photon_events(
        paths, scene, replace(det, mode="photon_counting", dead_time_s=1e-9)
    )
    for wf in (noisy, clean):
        assert wf.samples.dtype == np.float32
        assert np.all(np.isfinite(wf.samples))
        assert np.all((wf.samples >= 0) & (wf.samples <= det.top_code))
        assert np.all(wf.flags & required == required), (name, D.describe_pulse_flags(wf.flags))
    assert np.all(np.isfinite(events.times_s)) and np.all(np.isfinite(events.gate_start_s))
    assert events.offsets[-1] == events.times_s.size


def test_unflagged_reference_case_has_no_flags():
    scene = make_scene()
    paths = flat_paths(4, altitude_m=300.0, depth_m=8.0)
    det = detector(window_s=3e-7, pre_trigger_s=2e-8, counts_per_photoelectron=0.5)
    wf = W.simulate_waveforms(paths, scene, det)
    assert np.all(wf.flags == 0), D.describe_pulse_flags(wf.flags)


def test_saturated_samples_sit_at_the_top_code():
    scene = make_scene(system={"pulse_energy_j": 1.0})
    det = detector(window_s=2e-7, bit_depth=8, baseline_counts=10.0)
    wf = W.simulate_waveforms(flat_paths(2, altitude_m=300.0, depth_m=8.0), scene, det)
    assert wf.samples.max() == 255.0
    assert np.all(wf.flags & D.SATURATED)


def test_photon_counting_caps_strong_returns_and_flags_them():
    scene = make_scene(system={"pulse_energy_j": 1e-3})
    det = detector(mode="photon_counting", window_s=2e-7, strong_return_photoelectrons=500.0)
    ev = W.simulate_photon_events(flat_paths(3, altitude_m=300.0, depth_m=8.0), scene, det)
    assert np.all(np.diff(ev.offsets) <= 500)
    assert np.all(ev.flags & D.SATURATED)


def test_land_window_opens_before_the_land_echo():
    scene = make_scene()
    det = detector(window_s=2e-7, pre_trigger_s=2e-8)
    paths = flat_paths(1, altitude_m=300.0, depth_m=-20.0)
    b = return_budget(paths, scene, det)
    gap = b.t_surface_s[0, 0] - b.t0_s[0]
    # the window opens pre_trigger (rounded down to the clock) before the first echo
    assert 2e-8 <= gap < 2e-8 + 1e-9
