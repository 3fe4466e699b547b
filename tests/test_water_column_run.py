"""A scattering layer at 4 m over a 10 m seabed, from the simulator to points.laz (class 64)."""

import json
import math
import tomllib

import laspy
import numpy as np

from pipeline.outputs.las import write_points_laz
from pipeline.process.classify import BATHYMETRIC_POINT, WATER_COLUMN, WATER_SURFACE
from pipeline.process.detect import detect_full_waveform
from pipeline.process.refraction import RefractionSettings, georeference
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_fit import SurfaceFitSettings
from pipeline.process.water_column import add_water_column_points
from pipeline.run import run_scene
from pipeline.scene import parse_scene
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.waveform import simulate_waveforms

from .conftest import ROOT

SCENE = ROOT / "data_synthetic" / "scenes" / "water_column_layer.toml"
# the survey run passes the detector's column returns on to processing only once
# `simulate_detections` forwards them (DetectedReturns.COLUMN_FIELDS)


def _scene():
    return parse_scene(tomllib.loads(SCENE.read_text()))


def _check_laz(path, n_pulses):
    las = laspy.read(str(path))
    cls = np.asarray(las.classification)
    depth = np.asarray(las.depth_m)
    col, bot = cls == WATER_COLUMN, cls == BATHYMETRIC_POINT
    # a layer echo ~half the bottom's at SNR > 10: found in nearly every pulse
    assert col.sum() > 0.95 * n_pulses and bot.sum() > 0.95 * n_pulses
    # refracted at the group speed: the layer's centre 4 m down (the echo's exp(-2 c l)
    # weighting moves its mean up by 2 c T^2 / 12 = 1.9 mm), the seabed at 10 m
    assert abs(np.median(depth[col]) - 4.0) < 0.03
    assert abs(np.median(depth[bot]) - 10.0) < 0.03
    (lookup,) = las.header.vlrs.get("ClassificationLookupVlr")
    assert lookup.lookups[WATER_COLUMN] == "water column"
    assert lookup.lookups[BATHYMETRIC_POINT] == "bathymetry"
    assert lookup.lookups[WATER_SURFACE] == "water surface"
    # surface, column, bottom: returns 1, 2, 3 of 3
    rn, nr = np.asarray(las.return_number), np.asarray(las.number_of_returns)
    assert np.all(rn[col] == 2) and np.all(nr[col] == 3)
    assert np.mean(rn[bot] == 3) > 0.95
    return depth[col]


def test_layer_from_waveforms_to_laz(tmp_path):
    # the simulator, the detector and processing without the ray tracer or the survey run:
    # flat water, 20 deg off nadir in every azimuth, 7 sub-rays, the scene's system and noise
    scene = _scene()
    n = 3000
    rng = np.random.default_rng(5)
    paths = flat_paths(
        n, altitude_m=400.0, depth_m=10.0, off_nadir_rad=math.radians(20.0),
        azimuth_rad=rng.uniform(0, 2 * np.pi, n), n_sub=7, divergence_rad=1e-3,
        air_index=scene.atmosphere.refractive_index, water_phase_index=scene.water.phase_index,
    )  # fmt: skip
    det = scene.detector
    wf = simulate_waveforms(paths, scene, det, scene.returns)
    fwhm = math.hypot(scene.system.pulse_fwhm_s, det.impulse_response_fwhm_s)
    found = detect_full_waveform(
        wf.samples, wf.sample_interval_s, fwhm, scene.process.detect,
        noise_samples=int((det.pre_trigger_s - 2 * fwhm) / wf.sample_interval_s),
        shot_noise_counts=det.excess_noise_factor * det.counts_per_photoelectron,
    )  # fmt: skip
    assert found.has_column.mean() > 0.95

    def shift(mask, t):
        return np.where(mask, t + wf.t0_s, 0.0)  # detector times are from sample 0

    d = paths.direction[:, 0, :]  # the beam axis: sub-ray 0 of the sunflower pattern
    ret = DetectedReturns(
        pulse_id=paths.pulse_id, origin_meas_m=paths.origin_m,
        direction_meas=d / np.linalg.norm(d, axis=1)[:, None],
        has_surface=found.has_surface, t_surface_s=shift(found.has_surface, found.t_surface_s),
        has_bottom=found.has_bottom, t_bottom_s=shift(found.has_bottom, found.t_bottom_s),
        surface_confidence=found.surface_confidence, bottom_confidence=found.bottom_confidence,
        flags=found.flags, has_column=found.has_column,
        t_column_s=shift(found.has_column, found.t_column_s),
        column_confidence=found.column_confidence, column_amplitude=found.column_amplitude,
    )  # fmt: skip
    refr = RefractionSettings(
        phase_index=scene.water.phase_index, group_index=scene.water.group_index
    )
    fit = SurfaceFitSettings(air_index=scene.atmosphere.refractive_index)
    done = georeference(
        ret,
        surface_settings=fit,
        refraction_settings=refr,
        classify_settings=scene.process.classify,
    )
    done = add_water_column_points(done, ret, refr, scene.process.classify)
    path = write_points_laz(tmp_path / "points.laz", done.points, crs="EPSG:32631")
    _check_laz(path, n)


def test_layer_scene_end_to_end(tmp_path):
    data = tomllib.loads(SCENE.read_text())
    data["flight"]["area_m"] = [0.0, 60.0, 0.0, 60.0]
    data["flight"]["run_in_m"] = 0.0
    data["scanner"]["prf_hz"] = 5000.0
    data["run"] = {"chunk_pulses": 3000}
    run_scene(parse_scene(data), tmp_path, log=lambda _: None)
    ev = json.loads((tmp_path / "evaluation.json").read_text())
    depths = _check_laz(tmp_path / "points.laz", ev["pulses"])
    # the bottoms are as good as without a layer
    assert ev["error"]["points"]["rmse_m"] < 0.06
    wc = ev["water_column"]
    assert wc["n"] == depths.size and abs(wc["median_error_m"]) < 0.03
    # the posterior's waveform model has no layer echo: those pulses are not sampled, and said
    post = ev["posterior_against_truth"]
    assert post["n"] == 0 and post["skipped_in_column_return"] > 0
