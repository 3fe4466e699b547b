"""Time shapes, event-time distributions, settings validation and the documented presets."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats
from scipy.integrate import quad
from scipy.special import ndtr
from waveform_support import preset

from pipeline.config import describe, from_mapping
from pipeline.errors import SceneError
from pipeline.simulate import photon
from pipeline.simulate.budget import ReturnSettings
from pipeline.simulate.detector import PRESETS_DIR, DetectorSettings, load_preset
from pipeline.simulate.shapes import (
    column_bin_integrals,
    column_cdf,
    column_depth_time,
    fast_ndtr,
)


def _reference_column_cdf(x, r, w, s):
    """P(E + Z <= x), E truncated exponential on [0, w], Z ~ N(0, s^2), by quadrature."""
    if r * w < 1e-9:
        return quad(lambda e: ndtr((x - e) / s) / w, 0.0, w, epsabs=1e-15, epsrel=1e-12)[0]
    hi = min(w, 60.0 / r)  # beyond, the exponential weight is below e^-60
    edges = np.linspace(0.0, hi, 41)
    norm = -np.expm1(-r * w)
    return sum(
        quad(lambda e: r * np.exp(-r * e) / norm * ndtr((x - e) / s), a, b, epsabs=0, epsrel=1e-12)[
            0
        ]
        for a, b in zip(edges[:-1], edges[1:], strict=True)
    )


@pytest.mark.parametrize(
    ("r", "w", "s"),
    [
        (3.3e7, 9e-8, 9e-10),
        (1e10, 1e-6, 7e-10),
        (1e3, 3e-8, 1e-9),
        (2.2e10, 5e-9, 2e-9),
        (0.0, 4e-9, 1e-9),
    ],
)
def test_column_cdf_against_quadrature(r, w, s):
    for x in np.array([-12, -9, -3, 0, 2, 8.9, 9.1, 30, 100]) * s + np.array(
        [0, 0, 0, 0, 0, 0, 0, 0, w]
    ):
        # 1e-9: quadrature tolerance; the closed form is exact to rounding
        assert column_cdf(x, r, w, s) == pytest.approx(_reference_column_cdf(x, r, w, s), abs=1e-9)


def test_column_bins_equal_cdf_differences_and_telescope():
    rng = np.random.default_rng(3)
    k, m, dt = 300, 400, 1e-9
    r = 10 ** rng.uniform(5, 10.5, k)
    w = 10 ** rng.uniform(-10, -6.6, k)
    s = 10 ** rng.uniform(-10, -8.5, k)
    x0 = rng.uniform(-60, 5, k) * dt
    got = column_bin_integrals(x0, dt, m, r, w, s)
    ref = np.diff(
        column_cdf(x0[:, None] + dt * np.arange(m + 1), r[:, None], w[:, None], s[:, None])
    )
    # 1e-8: both forms lose eps/(r w) near the uniform limit; elsewhere they agree to 1e-12
    np.testing.assert_allclose(got, ref, atol=1e-8)
    inside = x0 + m * dt > w + 10 * s
    np.testing.assert_allclose(got[inside].sum(axis=1), column_cdf(x0[inside] + m * dt, r[inside],
                               w[inside], s[inside]) - column_cdf(x0[inside], r[inside], w[inside],
                               s[inside]), atol=1e-8)  # fmt: skip


def test_fast_ndtr_matches_scipy():
    z = np.linspace(-15, 15, 300_001)
    # 1e-12: cubic Hermite bound h^4 max|phi'''|/384 = 8e-13 on a 1/256 grid
    assert np.max(np.abs(fast_ndtr(z) - ndtr(z))) < 1e-12


def test_column_depth_time_inverts_the_truncated_exponential():
    u = np.linspace(1e-6, 1 - 1e-6, 1001)
    for r, w in [(3e7, 1e-7), (1e-3, 1e-7), (0.0, 5e-8), (1e12, 1e-6)]:
        x = column_depth_time(u, r, w)
        cdf = (-np.expm1(-r * x) / -np.expm1(-r * w)) if r * w > 5e-8 else x / w
        # 1e-9: double-precision inversion (log1p/expm1)
        np.testing.assert_allclose(cdf, u, atol=1e-9)


def test_drawn_event_times_follow_the_component_shapes():
    n = 4000
    keys = photon.pulse_keys(11, 5, np.arange(n))
    kinds = np.array([photon.KIND_GAUSS, photon.KIND_COLUMN, photon.KIND_UNIFORM], dtype=np.int8)
    comps = photon.Components(
        expected=np.tile([3.0, 4.0, 2.0], (n, 1)),
        kind=np.broadcast_to(kinds, (n, 3)),
        centre_s=np.tile([1e-6, 1.01e-6, 0.9e-6], (n, 1)),
        sigma_s=np.tile([1e-9, 1.5e-9, 1.0], (n, 1)),
        rate_per_s=np.tile([0.0, 5e7, 0.0], (n, 1)),
        width_s=np.tile([0.0, 8e-8, 3e-7], (n, 1)),
    )
    counts, pulse, times, comp, _, _ = photon.draw_events(keys, comps)
    # 3 sigma on the mean count (Poisson 9 per pulse)
    assert abs(counts.mean() - 9.0) < 3 * np.sqrt(9.0 / n)
    g = times[comp == 0]
    c = times[comp == 1]
    b = times[comp == 2]
    # KS at 1e-3 (fixed seed): Gaussian, column, uniform shapes
    assert stats.kstest((g - 1e-6) / 1e-9, "norm").pvalue > 1e-3
    assert stats.kstest(c - 1.01e-6, lambda x: column_cdf(x, 5e7, 8e-8, 1.5e-9)).pvalue > 1e-3
    assert stats.kstest((b - 0.9e-6) / 3e-7, "uniform").pvalue > 1e-3
    # component shares: 3:4:2
    share = np.bincount(comp, minlength=3) / comp.size
    np.testing.assert_allclose(share, [3 / 9, 4 / 9, 2 / 9], atol=3 * np.sqrt(0.25 / comp.size))


def test_detector_settings_validate_with_named_keys():
    with pytest.raises(SceneError, match="baseline_counts"):
        DetectorSettings(bit_depth=8, baseline_counts=300.0)
    with pytest.raises(SceneError, match="window_s"):
        DetectorSettings(window_s=1e-4, sample_rate_hz=1e11)
    with pytest.raises(SceneError, match="detector.mode"):
        from_mapping(DetectorSettings, {"mode": "geiger"}, "detector")
    with pytest.raises(SceneError, match="Unknown preset"):
        load_preset("nonexistent")
    assert any(
        line.startswith("detector.dead_time_s") for line in describe(DetectorSettings, "detector")
    )


@pytest.mark.parametrize("name", ["topobathy_full_waveform", "photon_counting"])
def test_presets_validate_and_cite_a_source_for_every_value(name):
    system, scanner, det, rs = preset(name)
    assert isinstance(det, DetectorSettings) and isinstance(rs, ReturnSettings)
    assert det.mode == ("full_waveform" if "waveform" in name else "photon_counting")
    text = (PRESETS_DIR / f"{name}.toml").read_text(encoding="utf-8")
    for line in text.splitlines():
        stripped = line.strip()
        if "=" in stripped and not stripped.startswith("#") and not stripped.startswith("mode"):
            assert "#" in stripped, f"{name}: no source comment on `{stripped}`"
    assert system["wavelength_nm"] == 532.0 and scanner["prf_hz"] > 0
