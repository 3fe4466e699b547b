"""The forward-scattering delay of the bottom echo against a brute-force photon Monte Carlo.

The Monte Carlo below is written here from the physics and shares nothing with the model:
photons enter the water as a vertical pencil, travel exponential free paths (scattering
coefficient b), scatter with a Henyey-Greenstein phase function (g = 0.9), are absorbed with
weight exp(-a s), and count when they reach a flat seabed at depth L within the receiver's
field-of-view radius R. Two ways: the up leg is, by reciprocity, the same experiment (the
Lambertian seabed forgets the direction), so the two-way excess path is the sum of two
independent draws. The model (pipeline.forward_scatter with the traced tables of
pipeline.forward_scatter_mc) gets only the phase function and the absorption.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from waveform_support import clean_scene, detector

from pipeline.forward_scatter import ScatterTables, bottom_delay
from pipeline.forward_scatter_mc import TracedTables
from pipeline.simulate.budget import return_budget
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.waveform import expected_waveform

G_HG = 0.9


def _hg_phase(psi):
    return (1 - G_HG**2) / (4 * np.pi * (1 + G_HG**2 - 2 * G_HG * np.cos(psi)) ** 1.5)


def _one_way_mc(n, depth, b, a, radius, rng, max_excess=60.0):
    """Excess path (m) and weight (0 if lost) of ``n`` photons from the surface to the seabed."""
    pos = np.zeros((n, 3))
    d = np.zeros((n, 3))
    d[:, 2] = 1.0
    s = np.zeros(n)
    alive = np.ones(n, dtype=bool)
    landed_r = np.full(n, np.inf)
    while alive.any():
        i = np.flatnonzero(alive)
        step = rng.exponential(1.0 / b, i.size)
        dz = d[i, 2]
        to_bed = np.where(dz > 0, (depth - pos[i, 2]) / np.where(dz > 0, dz, 1.0), np.inf)
        hit = step >= to_bed
        h = i[hit]
        p = pos[h] + d[h] * to_bed[hit, None]
        s[h] += to_bed[hit]
        landed_r[h] = np.hypot(p[:, 0], p[:, 1])
        alive[h] = False
        m, st = i[~hit], step[~hit]
        pos[m] += d[m] * st[:, None]
        s[m] += st
        lost = (pos[m, 2] < 0) | (s[m] > depth + max_excess)
        alive[m[lost]] = False
        m = m[~lost]
        # Henyey-Greenstein deflection by inversion of its CDF, uniform azimuth
        u = rng.random(m.size)
        frac = (1 - G_HG**2) / (1 - G_HG + 2 * G_HG * u)
        mu = (1 + G_HG**2 - frac**2) / (2 * G_HG)
        phi = 2 * np.pi * rng.random(m.size)
        old = d[m]
        ref = np.where(np.abs(old[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
        e1 = np.cross(old, ref)
        e1 /= np.linalg.norm(e1, axis=1)[:, None]
        e2 = np.cross(old, e1)
        sin = np.sqrt(np.maximum(1 - mu * mu, 0.0))
        d[m] = mu[:, None] * old + sin[:, None] * (
            np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
        )
    weight = np.where(landed_r <= radius, np.exp(-a * s), 0.0)
    return s - depth, weight


@pytest.fixture(scope="module")
def hg_tables():
    return TracedTables.from_phase(_hg_phase)


@pytest.mark.parametrize(
    ("depth", "radius"),
    [(5.0, 2.0), (10.0, 2.0), (20.0, 2.0), (20.0, 0.5), (20.0, 5.0), (30.0, 3.0)],
)
def test_bottom_delay_against_brute_force_monte_carlo(depth, radius, hg_tables):
    """R = 2 m is a 10 mrad receiver at ~400 m; 0.5 and 5 m are the narrow and wide extremes."""
    c, albedo = 0.15, 0.8  # clear coastal water
    b, a = albedo * c, (1 - albedo) * c
    rng = np.random.default_rng(int(10 * depth + radius))
    excess, w = _one_way_mc(200_000, depth, b, a, radius, rng)
    keep = w > 0
    excess, w = excess[keep], w[keep] / w[keep].sum()
    n_eff = 1.0 / np.sum(w**2)
    model = bottom_delay(np.array([depth]), np.array([radius]), [b], [hg_tables], a)

    # no accepted scattering on either leg
    p1 = float(np.sum(w * (excess == 0.0)))
    se_p1 = math.sqrt(p1 * (1 - p1) / n_eff)
    assert model.unscattered[0] == pytest.approx(p1**2, abs=3 * 2 * p1 * se_p1)

    # mean two-way excess path (sum of two legs) within the sampling error: 3 sigmas of the
    # difference of two Monte Carlo estimates of the same size (this one and the model's
    # tables, 200 000 photons each). The single-event tables were 5-10 % high at R = 2 m and
    # 43 % low at R = 0.5 m: 3-20 sigmas off.
    mean1 = float(np.sum(w * excess))
    se_mean = math.sqrt(2 * float(np.sum(w * (excess - mean1) ** 2)) / n_eff)
    assert abs(model.mean_m[0] - 2 * mean1) <= 3 * math.sqrt(2.0) * se_mean

    # skew: the share of the echo's photons delayed by less than the mean (0.5 if symmetric)
    pick = rng.choice(excess.size, size=(2, 100_000), p=w)
    two_way = excess[pick[0]] + excess[pick[1]]
    share_mc = float(np.mean(two_way <= two_way.mean()))
    wt, tau, mean = model.tail_weight[0], model.tail_mean_m[0], model.mean_m[0]
    share_model = (1 - wt) + wt * (1 - math.exp(-mean / tau))
    assert share_mc > 0.6 and share_model > 0.6  # skewed late
    if radius >= 2.0:
        # the two-moment mixture's shape; in the narrow field (R / L = 0.025) the delays are
        # heavier-tailed than one exponential (MC 0.77, mixture 0.89: mean and variance right,
        # the shape not; see RESULTS_realism.md)
        assert share_model == pytest.approx(share_mc, abs=0.04 + 3 * math.sqrt(0.25 / 100_000))


def test_traced_tables_tend_to_single_events_when_scattering_is_rare(hg_tables):
    """At b L -> 0 at most one event is accepted: the single-event integrals are exact there."""
    single = ScatterTables.from_phase(_hg_phase)
    rho = np.array([0.05, 0.2, 1.0])
    traced = hg_tables.at(np.full(3, 0.1), rho)  # the first fully traced optical depth
    np.testing.assert_allclose(traced[1], single(rho)[1], rtol=0.08)


def _moments(scene, depth, off_nadir_deg=0.0):
    """Energy, centroid and third central moment (s) of the noise-free bottom echo."""
    det = detector(sample_rate_hz=1e10, window_s=1.2e-6)
    paths = flat_paths(1, altitude_m=400.0, depth_m=depth, air_index=1.0,
                       off_nadir_rad=math.radians(off_nadir_deg))  # fmt: skip
    b = return_budget(paths, scene, det)
    y = expected_waveform(b)["bottom"][0]
    t = b.t0_s[0] + det.sample_interval_s * np.arange(y.size)
    e = y.sum()
    mu = float((y * t).sum() / e)
    return e, mu - b.t_bottom_s[0, 0], float((y * (t - mu) ** 3).sum() / e)


def test_budget_bottom_echo_is_delayed_and_skewed_with_depth_attenuation_and_angle():
    def scene(fs, c=0.15):
        return clean_scene(returns={"forward_scatter": fs}, extinction_per_m=c,
                           backscatter_180_per_m_sr=0.0)  # fmt: skip

    e0, d0, s0 = _moments(scene("none"), 10.0)
    e1, d1, s1 = _moments(scene("small_angle"), 10.0)
    assert e1 == pytest.approx(e0, rel=1e-9)  # scattering in the field of view moves, not loses
    assert abs(d0) < 1e-12 and d1 > 1e-11  # the centroid is late
    assert s1 > 0.0 and s1 > 100 * abs(s0)  # and the echo skewed late
    # more delay deeper, in more turbid water, and further off nadir (longer, refracted path)
    delays = [_moments(scene("small_angle"), z)[1] for z in (5.0, 10.0, 20.0)]
    assert np.all(np.diff(delays) > 0)
    assert _moments(scene("small_angle", c=0.3), 10.0)[1] > d1
    assert _moments(scene("small_angle"), 10.0, off_nadir_deg=20.0)[1] > d1


def test_water_tables_from_the_disk_cache_are_the_traced_ones(tmp_path, monkeypatch):
    """The traced tables kept on disk (``forward_scatter_mc._cached_h``) are the tracing's,
    bit for bit; a damaged, empty or foreign file is traced again and replaced; a cache folder
    that cannot be written costs only the time."""
    import pipeline.forward_scatter_mc as mc
    from pipeline import water_optics as wo

    traced = TracedTables.from_phase(wo.ff_phase_per_sr)
    monkeypatch.setenv("BATHY_CACHE_DIR", str(tmp_path / "cache"))
    calls = []

    def trace():
        calls.append(1)
        return traced.h

    for _ in range(2):  # traced and stored once, then read
        h = mc._cached_h(trace)
        np.testing.assert_array_equal(h, traced.h)
    assert len(calls) == 1
    (stored,) = (tmp_path / "cache").iterdir()
    assert np.array_equal(np.load(stored), traced.h)
    for damage in (stored.read_bytes()[:100], b"", b"PK\x03\x04 not a zip"):
        stored.write_bytes(damage)  # truncated, empty (a crash before its data), foreign
        np.testing.assert_array_equal(mc._cached_h(trace), traced.h)
        assert np.array_equal(np.load(stored), traced.h)
    np.save(stored, traced.h.astype(np.float32))  # right shape, wrong type
    np.testing.assert_array_equal(mc._cached_h(trace), traced.h)
    assert len(calls) == 5
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    monkeypatch.setenv("BATHY_CACHE_DIR", str(blocked / "cache"))
    np.testing.assert_array_equal(mc._cached_h(trace), traced.h)
    # what every run uses: the same tables, whole
    mc.water_tables.cache_clear()
    monkeypatch.setenv("BATHY_CACHE_DIR", str(tmp_path / "cache"))
    got, _ = mc.water_tables()
    np.testing.assert_array_equal(got.h, traced.h)
    np.testing.assert_array_equal(got.log_tau, traced.log_tau)
    probe = (np.array([0.01, 0.3, 4.0]), np.array([0.02, 0.5, 3.0]), np.array([0.0, 0.4, 2.0]))
    np.testing.assert_array_equal(got.at(*probe), traced.at(*probe))
    mc.water_tables.cache_clear()


def test_traced_lookup_is_the_whole_array_trilinear_bit_for_bit():
    # the compiled interpolation (forward_scatter_mc._trilinear) against the trilinear
    # weights written out over whole arrays, at points across and beyond the grids
    from pipeline.forward_scatter_mc import TAU_BLEND, water_tables

    tt, _ = water_tables()
    rng = np.random.default_rng(8)
    n = 5000
    tau, rho = 10.0 ** rng.uniform(-4, 2, n), 10.0 ** rng.uniform(-4, 2, n)
    alpha = rng.uniform(-0.1, 1.2, n)
    lt, lr = np.log(tau), np.log(rho)
    al = np.clip(alpha, tt.alpha[0], tt.alpha[-1])
    ia = np.clip(np.searchsorted(tt.alpha, al, side="right") - 1, 0, tt.alpha.size - 2)
    wa = (al - tt.alpha[ia]) / (tt.alpha[ia + 1] - tt.alpha[ia])
    ft = np.clip((lt - tt.log_tau[0]) / (tt.log_tau[1] - tt.log_tau[0]), 0.0, None)
    fr = (np.clip(lr, tt.log_rho[0], tt.log_rho[-1]) - tt.log_rho[0]) / (
        tt.log_rho[1] - tt.log_rho[0]
    )
    it = np.minimum(ft.astype(np.int64), tt.log_tau.size - 2)
    ir = np.minimum(fr.astype(np.int64), tt.log_rho.size - 2)
    wt, wr = np.clip(ft - it, 0.0, 1.0), fr - ir
    h = tt.h
    traced = 0.0
    for a, wh in ((ia, 1.0 - wa), (ia + 1, wa)):
        traced = traced + wh * (
            (1 - wt) * (1 - wr) * h[:, a, it, ir]
            + wt * (1 - wr) * h[:, a, it + 1, ir]
            + (1 - wt) * wr * h[:, a, it, ir + 1]
            + wt * wr * h[:, a, it + 1, ir + 1]
        )
    blend = np.clip((lt - np.log(TAU_BLEND)) / np.log(2.0), 0.0, 1.0)
    want = blend * traced + (1.0 - blend) * tt.single(rho)
    assert tt.at(tau, rho, alpha).tobytes() == want.tobytes()
