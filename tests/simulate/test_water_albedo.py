"""The single-scattering albedo from sea water plus other matter, against written references.

References written here: pure water's absorption near 532 nm (Pope & Fry 1997, ~0.045 1/m), sea
water's scattering (Morel 1974: 2.88e-3 (lambda/500)^-4.32 1/m), and Petzold's (1972) three
waters at 530 nm (Mobley 1994, *Light and Water*, table 3.10: b, c = 0.037, 0.151 / 0.219,
0.398 / 1.824, 2.19 1/m).
"""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from pipeline.process.scatter_bias import ForwardScatterSettings, bias_model
from pipeline.suite.generate import NONWATER_ALBEDO_RANGE, draw
from pipeline.suite.scene_file import scene_toml
from pipeline.water_optics import PETZOLD_NONWATER_ALBEDOS, albedo_from_nonwater

A_W = 0.045  # Pope & Fry 1997, 1/m near 532 nm
PETZOLD = ((0.151, 0.037), (0.398, 0.219), (2.19, 1.824))  # (c, b) 1/m at 530 nm


def _b_w(nm: float) -> float:
    return 2.88e-3 * (nm / 500.0) ** -4.32


def test_petzold_waters_get_their_own_scattering_back():
    for (c, b), w_nw in zip(PETZOLD, PETZOLD_NONWATER_ALBEDOS, strict=True):
        assert albedo_from_nonwater(c, w_nw, 530.0) * c == pytest.approx(b, rel=2e-3)


def test_pure_sea_water_scatters_only_as_sea_water_does():
    c_w = A_W + _b_w(532.0)
    for w_nw in (0.0, 0.5, 1.0):
        assert albedo_from_nonwater(c_w, w_nw, 532.0) == pytest.approx(_b_w(532.0) / c_w)
    # below sea water's own c (not a natural water): all of it may scatter, never more
    assert albedo_from_nonwater(0.001, 0.6, 532.0) == pytest.approx(1.0)
    assert albedo_from_nonwater(0.0, 0.6, 532.0) == 0.0


@given(
    c=st.floats(0.0473, 100.0),
    w_nw=st.floats(0.0, 1.0),
)
def test_absorption_never_falls_below_pure_water(c, w_nw):
    w0 = albedo_from_nonwater(c, w_nw, 532.0)
    assert 0.0 <= w0 <= 1.0
    assert (1.0 - w0) * c >= A_W * (1.0 - 1e-12)
    # all matter scattering: the albedo approaches 1 - a_w / c
    if w_nw == 1.0:
        assert w0 == pytest.approx(1.0 - A_W / c, rel=1e-12)


def test_processing_assumes_clear_water_scatters_little_and_a_users_albedo_wins():
    kw = dict(
        fov_mrad=12.0,
        system_fwhm_s=3e-9,
        sample_interval_s=1e-9,
        trend_fwhm=8.0,
        wavelength_nm=532.0,
    )
    clear = bias_model(ForwardScatterSettings(), attenuation_per_m=0.05, **kw)
    # c = 0.05 is nearly pure water: b <= b_w + (c - c_w), omega_0 < 0.1 (not a coastal 0.55)
    assert clear.single_scattering_albedo < 0.1
    coastal = bias_model(ForwardScatterSettings(), attenuation_per_m=0.398, **kw)
    assert coastal.single_scattering_albedo * 0.398 == pytest.approx(0.219, rel=0.01)
    user = bias_model(
        ForwardScatterSettings(single_scattering_albedo=0.55), attenuation_per_m=0.05, **kw
    )
    assert user.single_scattering_albedo == 0.55
    # the survey's measured c replaces the fallback one: the albedo follows it, a user's stays
    fallback = bias_model(ForwardScatterSettings(), attenuation_per_m=0.15, **kw)
    measured = fallback.at_attenuation(0.05)
    assert measured.beam_attenuation_per_m == 0.05
    assert measured.single_scattering_albedo == clear.single_scattering_albedo
    assert user.at_attenuation(0.4).single_scattering_albedo == 0.55


def test_suite_waters_are_physical_and_span_petzolds():
    lo, hi = NONWATER_ALBEDO_RANGE
    seen = []
    for seed in range(60):
        d = draw(seed)
        text = scene_toml(d)
        line = next(s for s in text.splitlines() if s.startswith("single_scattering_albedo"))
        w0 = float(line.split("=")[1])
        # a clear scene (c 0.05) no longer absorbs less than pure water (0.55 did: a = 0.0225)
        assert (1.0 - w0) * d.attenuation_per_m >= A_W * (1.0 - 1e-3)
        assert lo <= d.nonwater_albedo <= hi
        seen.append(d.nonwater_albedo)
    assert min(seen) < lo + 0.1 and max(seen) > hi - 0.1
