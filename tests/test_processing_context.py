"""Settings tell the truth: what processing assumes is the user's value when set, and recorded.

`bathy run` used to replace `process.tpu.position_sigma_h_m`, `heading_sigma_deg`,
`beam_divergence_mrad` and `process.surface_fit.air_index` with the simulator's values while the
manifest recorded the user's, and processing assumed the scene's true water indices.
"""

import json
import math
import tomllib

import numpy as np
import pytest

from pipeline.errors import SceneError
from pipeline.process.context import processing_context
from pipeline.run import run_scene
from pipeline.scene import parse_scene

from .conftest import ROOT

UNUSUAL = {
    "tpu": {
        "position_sigma_h_m": 5.0,
        "position_sigma_v_m": 0.7,
        "attitude_sigma_deg": 0.3,
        "heading_sigma_deg": 0.5,
        "beam_divergence_mrad": 3.0,
        "wavelength_nm": 550.0,
    },
    "surface_fit": {"air_index": 1.0003},
    "assumed_phase_index": 1.30,
    "assumed_group_index": 1.32,
}


def _small_survey(process=None):
    data = tomllib.loads((ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml").read_text())
    data["flight"].update(area_m=[0.0, 100.0, 0.0, 100.0], run_in_m=0.0)
    data["scanner"]["prf_hz"] = 5000.0
    data["seabed"]["roughness_rms_m"] = 0.0
    data["process"]["posterior_min_pulses"] = 0
    data["process"].update(process or {})
    return parse_scene(data)


def test_unset_values_come_from_the_scene_records_and_sea_water():
    scene = _small_survey()
    ctx = processing_context(scene)
    nav = scene.navigation
    assert ctx.tpu.position_sigma_h_m == nav.gnss_horizontal_sigma_m
    assert ctx.tpu.position_sigma_v_m == nav.gnss_vertical_sigma_m
    assert ctx.tpu.heading_sigma_deg == nav.ins_heading_sigma_deg
    assert ctx.tpu.beam_divergence_mrad == scene.scanner.beam_divergence_mrad
    assert ctx.surface_fit.air_index == scene.atmosphere.refractive_index
    assert ctx.sources["process.tpu.position_sigma_h_m"] == "navigation.gnss_horizontal_sigma_m"
    # sea water at 532 nm, 35 psu, 20 degC: 1.3415 / 1.3638 (Quan & Fry 1995, published)
    assert ctx.refraction.phase_index == pytest.approx(1.3415, abs=2e-4)
    assert ctx.refraction.group_index == pytest.approx(1.3638, abs=2e-4)


def test_assumed_water_does_not_follow_the_scene_truth():
    scene = _small_survey()
    data = tomllib.loads((ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml").read_text())
    data["water"].update(phase_index=1.33, group_index=1.35)
    other = parse_scene(data)
    a, b = processing_context(scene).refraction, processing_context(other).refraction
    assert (a.phase_index, a.group_index) == (b.phase_index, b.group_index)


def test_user_values_win_in_the_context():
    ctx = processing_context(_small_survey(UNUSUAL))
    for key, value in UNUSUAL["tpu"].items():
        assert getattr(ctx.tpu, key) == value
        assert ctx.sources[f"process.tpu.{key}"] == "user"
    assert ctx.surface_fit.air_index == 1.0003
    assert (ctx.refraction.phase_index, ctx.refraction.group_index) == (1.30, 1.32)
    assert ctx.refraction.position_sigma_h_m == 5.0


def test_a_wavelength_outside_the_water_model_is_one_clear_error():
    scene = _small_survey({"tpu": {"wavelength_nm": 450.0}})
    data = tomllib.loads((ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml").read_text())
    data["system"] = {**data.get("system", {}), "wavelength_nm": 1064.0}
    with pytest.raises(SceneError, match="process.tpu.wavelength_nm"):
        processing_context(parse_scene(data))
    assert processing_context(scene).tpu.wavelength_nm == 450.0


@pytest.mark.slow
def test_bathy_run_uses_and_records_the_users_values(tmp_path):
    scene = _small_survey(UNUSUAL)
    manifest = run_scene(scene, tmp_path, log=lambda _: None)
    ev = json.loads((tmp_path / "evaluation.json").read_text())
    rec = ev["processing_context"]["values"]
    assert rec["tpu"]["position_sigma_h_m"] == 5.0
    assert rec["tpu"]["heading_sigma_deg"] == 0.5
    assert rec["tpu"]["beam_divergence_mrad"] == 3.0
    assert rec["surface_fit"]["air_index"] == 1.0003
    assert rec["refraction"]["group_index"] == 1.32
    assert manifest["scene"]["process"]["tpu"]["position_sigma_h_m"] == 5.0
    from pipeline.outputs.las import read_points_laz

    pts = read_points_laz(tmp_path / "points.laz").points
    # a 0.7 m vertical navigation sigma alone gives a 95 % TVU of 1.96 x 0.7 = 1.37 m, over
    # IHO order 2's sqrt(1 + (0.023 d)^2) = 1.00-1.01 m at these 2-5 m depths: every bottom
    # sounding is rejected (class 7, withheld) and keeps its position, depth and TPU
    assert np.sum(pts.classification == 40) == 0
    b = pts.classification == 7
    assert b.sum() > 1000
    # the TPU received the 5 m navigation sigma: no horizontal uncertainty below it
    assert np.all(pts.uncertainty_h_m[b] >= 5.0)
    # the refraction received n_g = 1.32 and n = 1.30 while the water has 1.3638 / 1.3415:
    # slant range x 1.3638/1.32 and cos of the refracted angle at 20 deg incidence, so every
    # depth is deeper by the same factor (flat water, plane seabed 2 m + tan(5.33 deg) x)
    sin_i = math.sin(math.radians(20.0))
    cos_true = math.sqrt(1 - (sin_i / 1.3415) ** 2)
    cos_used = math.sqrt(1 - (sin_i / 1.30) ** 2)
    factor = 1.3638 / 1.32 * cos_used / cos_true
    truth = 2.0 + math.tan(math.radians(5.33)) * pts.xyz_m[b, 0]
    ratio = np.median(pts.depth_m[b] / truth)
    assert ratio == pytest.approx(factor, abs=0.004)


def test_the_logged_wind_sets_the_facet_slope_and_a_users_value_wins():
    # off by default (it failed the held-out check): no facet slope, no correction
    assert processing_context(_small_survey()).refraction.facet_mss == 0.0
    scene = _small_survey({"wave_facet_correction": True})
    ctx = processing_context(scene)
    u = scene.water.wind_speed_m_s
    # Cox & Munk (1954), clean sea: 0.003 + 5.12e-3 U12.5 (published)
    assert ctx.refraction.facet_mss == pytest.approx(0.003 + 5.12e-3 * u)
    assert ctx.refraction.facet_mss_sigma == pytest.approx(5.12e-3 * 2.0)
    assert ctx.sources["process.wind_speed_m_s"].startswith("water.wind_speed_m_s")
    mine = processing_context(
        _small_survey({"wind_speed_m_s": 7.5, "wind_sigma_m_s": 0.5, "wave_facet_correction": True})
    )
    assert mine.refraction.facet_mss == pytest.approx(0.003 + 5.12e-3 * 7.5)
    assert mine.refraction.facet_mss_sigma == pytest.approx(5.12e-3 * 0.5)
    assert mine.sources["process.wind_speed_m_s"] == "user"
    # recorded: the manifest's processing_context holds the values used
    rec = mine.to_dict()
    assert rec["values"]["refraction"]["facet_mss"] == pytest.approx(0.003 + 5.12e-3 * 7.5)
    # the bottom echo's decay weights the facets' paths: the assumed water's K_d until the
    # survey measures its column (Gordon's bridge K_d = 0.2 c + 0.04)
    c = scene.process.forward_scatter.fallback_attenuation_per_m
    assert ctx.refraction.facet_decay_per_m == pytest.approx(0.2 * c + 0.04)


def test_the_assumed_albedo_follows_the_measured_water_not_the_scene_truth():
    from pipeline.process.context import with_measured_attenuation

    scene = _small_survey()
    ctx = processing_context(scene)
    fs = ctx.refraction.forward_scatter
    # sea water (0.045 1/m absorbed, Pope & Fry; 2.2e-3 scattered at 532 nm) plus Petzold's
    # coastal matter (b/c 0.618) at the fallback c: written here, not read from the code
    b_w = 2.88e-3 * (532.0 / 500.0) ** -4.32
    c0 = scene.process.forward_scatter.fallback_attenuation_per_m
    assert fs.single_scattering_albedo == pytest.approx((b_w + 0.618 * (c0 - 0.045 - b_w)) / c0)
    # the survey measures a clear water's column decay: the albedo follows its c down
    clear = with_measured_attenuation(ctx, 0.06, 400.0).refraction.forward_scatter
    c = clear.beam_attenuation_per_m
    assert c < c0
    assert clear.single_scattering_albedo == pytest.approx((b_w + 0.618 * (c - 0.045 - b_w)) / c)
    # a scene whose true water scatters otherwise does not move the assumption
    other = parse_scene(
        {**tomllib.loads((ROOT / "data_synthetic" / "scenes" / "palmer_survey.toml").read_text())}
        | {"water": {"extinction_per_m": 0.15, "single_scattering_albedo": 0.9}}
    )
    assert processing_context(other).refraction.forward_scatter == fs
