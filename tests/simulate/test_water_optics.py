"""Water optics against independent references: phase-function beta(180) and Gordon's limits.

References written here, not taken from the code: the Fournier-Forand normalisation and its
closed-form backscatter fraction (Mobley, Sundman & Boss 2002: B = 0.0183 for the Petzold fit),
the molecular phase function of sea water, and the two limits of the lidar attenuation found by
Gordon (1982, Appl. Opt. 21:2996): the beam attenuation c for a narrow field of view (c R -> 0),
the diffuse attenuation K_d for a wide one (c R > 5-6).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from scipy.integrate import quad
from waveform_support import clean_scene, common_pe, detector, fresnel_unpolarised_t, make_scene

from pipeline.errors import SceneError
from pipeline.simulate.budget import return_budget
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.waveform import expected_waveform
from pipeline.water_optics import ff_phase_per_sr


def test_petzold_phase_function_is_normalised_with_its_published_backscatter_fraction():
    def solid(lo, hi):
        # in ln(psi): the forward peak spans decades of angle
        def f(u):
            psi = math.exp(u)
            return 2 * math.pi * float(ff_phase_per_sr(psi)) * math.sin(psi) * psi

        return quad(f, math.log(lo), math.log(hi), limit=400)[0]

    total = solid(1e-14, math.pi)
    back = solid(math.pi / 2, math.pi)
    assert total == pytest.approx(1.0, abs=2e-6)  # the part below 1e-14 rad is ~1e-7
    assert back == pytest.approx(0.0183, abs=5e-5)  # Mobley et al. 2002, Petzold average


def test_default_beta_180_follows_c_through_the_named_phase_functions():
    # sea water alone (albedo small enough that b = b_w): b p_w(180), p_w = 1.835 / (4 pi 1.2783)
    c = 0.15
    water = make_scene(water={"single_scattering_albedo": 0.001}).water
    water = replace(water, backscatter_180_per_m_sr=None)
    p_w = (1 + 0.835) / (4 * math.pi * (1 + 0.835 / 3))
    assert water.beta_180_per_m_sr(532.0) == pytest.approx(0.001 * c * p_w, rel=1e-12)
    # coastal water c = 0.15 1/m: Petzold-type phase functions give 4-6e-4 (issue 12), not 2e-3
    for albedo in (0.55, 0.7, 0.8):
        w = replace(water, single_scattering_albedo=albedo)
        assert 4e-4 <= w.beta_180_per_m_sr(532.0) <= 6e-4
    # a user's value wins
    assert replace(water, backscatter_180_per_m_sr=2e-3).beta_180_per_m_sr(532.0) == 2e-3


def test_scene_without_beta_gets_the_phase_function_default():
    from pipeline.scene import DEFAULT_SCENE_PATH, load_scene

    scene = load_scene(DEFAULT_SCENE_PATH)  # c = 0.15 1/m, beta(180) left to its default
    assert scene.water.backscatter_180_per_m_sr is None
    assert 4e-4 <= scene.water.beta_180_per_m_sr(scene.system.wavelength_nm) <= 6e-4


def test_kd_is_a_validated_scene_input():
    scene = make_scene(water={"diffuse_attenuation_per_m": 0.05})
    assert scene.water.kd_per_m == 0.05
    with pytest.raises(SceneError, match="diffuse_attenuation_per_m"):
        make_scene(water={"extinction_per_m": 0.1, "diffuse_attenuation_per_m": 0.2})


def _bottom_decay(scene, h=400.0, depths=(6.0, 18.0)):
    """Decay rate k (1/m) of the nadir bottom return between two depths, geometry removed."""
    paths = flat_paths(2, altitude_m=h, depth_m=list(depths), air_index=1.0)
    b = return_budget(paths, scene, detector())
    n = scene.water.phase_index
    # the rest of the bottom term depends on depth only through A / (n H + D)^2 at nadir
    geo = [-2 * math.log(n * h + d) for d in depths]
    dlog = (b.log_bottom[1, 0] - geo[1]) - (b.log_bottom[0, 0] - geo[0])
    return -dlog / (2 * (depths[1] - depths[0]))


def _fov_scene(fov_mrad, c=0.15, kd=None, beta=0.0):
    """The clean nadir scene with the field-of-view attenuation and a given receiver field."""
    water = {"extinction_per_m": c, "backscatter_180_per_m_sr": beta}
    if kd is not None:
        water["diffuse_attenuation_per_m"] = kd
    scene = clean_scene(returns={"lidar_attenuation": "fov"}, **water)
    scanner = replace(scene.scanner, receiver_fov_mrad=fov_mrad,
                      beam_divergence_mrad=min(fov_mrad, 1.0))  # fmt: skip
    return replace(scene, scanner=scanner)


@pytest.mark.parametrize(("c", "kd"), [(0.15, None), (0.3, 0.09), (0.8, 0.2)])
def test_bottom_decay_runs_from_c_to_kd_with_the_field_of_view(c, kd):
    kd_ref = kd if kd is not None else 0.2 * c + 0.04  # the scene's K_d, or the bridge
    h = 400.0
    # narrow field: c R = c H tan(fov/2) ~ 1e-4 -> the beam attenuation
    assert _bottom_decay(_fov_scene(2e-3, c, kd), h) == pytest.approx(c, rel=2e-3)
    # wide field: c R >= 6 at the surface -> the diffuse attenuation
    wide = 2e3 * math.atan(6.0 / c / h)
    assert _bottom_decay(_fov_scene(wide, c, kd), h) == pytest.approx(kd_ref, rel=2e-3)
    # in between it falls monotonically from c towards K_d as c R grows
    fovs = [2e3 * math.atan(x / c / h) for x in (0.05, 0.3, 1.0, 2.0, 4.0)]
    ks = [_bottom_decay(_fov_scene(f, c, kd), h) for f in fovs]
    assert all(kd_ref < k < c for k in ks)
    assert np.all(np.diff(ks) < 0)


def test_column_decays_at_kd_for_a_wide_field():
    c, kd, h, depth = 0.3, 0.09, 400.0, 15.0
    scene = _fov_scene(2e3 * math.atan(8.0 / c / h), c, kd, beta=1e-3)
    b = return_budget(flat_paths(1, altitude_m=h, depth_m=depth, air_index=1.0), scene, detector())
    got = expected_waveform(b)["column"].sum()
    w = scene.water
    base = common_pe(scene) * math.exp(-2 * scene.atmosphere.extinction_per_m * h)
    t0 = fresnel_unpolarised_t(1.0, w.phase_index, 0.0)

    def dens(z):
        return math.exp(-2 * kd * z) / (w.phase_index * h + z) ** 2

    ref = base * t0**2 * 1e-3 * quad(dens, 0.0, depth, epsabs=0, epsrel=1e-12)[0]
    assert got == pytest.approx(ref, rel=1e-4)  # k at the entry radius: c R = 8, K_d to 1e-5
