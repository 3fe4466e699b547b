"""Tests of pipeline.optics against independent references (textbook formulas, brute force)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from pipeline import optics as o

N_WATER = 1.33
# Dense grid of incidence angles that ends exactly at pi/2 (grazing incidence).
THETA = np.linspace(0.0, np.pi / 2, 4001)
# Round-off bound: a handful of float64 operations on O(1) quantities.
TIGHT = 1e-12


def _no_warnings(fn, *args, **kwargs):
    """Call ``fn`` with every warning (not just RuntimeWarning) turned into an error."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return fn(*args, **kwargs)


def _decaying_root(z):
    """The square root of ``z`` whose imaginary part is >= 0, chosen from both roots."""
    root = np.sqrt(np.asarray(z, dtype=complex))
    return np.where(root.imag < 0, -root, root)


# --- energy conservation -------------------------------------------------------------------------
@pytest.mark.parametrize(("n1", "n2"), [(1.0, N_WATER), (N_WATER, 1.0)])
def test_r_plus_t_is_one_for_s_p_and_unpolarised(n1, n2):
    r_s, r_p, t_s, t_p = _no_warnings(o.fresnel_power, n1, n2, THETA)
    r_u, t_u = o.fresnel_unpolarised(n1, n2, THETA)
    for r, t in [(r_s, t_s), (r_p, t_p), (r_u, t_u)]:
        assert np.all(np.isfinite(r)) and np.all(np.isfinite(t))
        np.testing.assert_allclose(r + t, 1.0, rtol=0, atol=TIGHT)  # round-off only
        assert np.all((r >= 0) & (t >= 0))


def test_power_matches_document_eqs_12_to_15_below_critical():
    n1, n2 = 1.0, N_WATER
    th = THETA[:-1]  # eq 14 is 0/0 at exactly 90 degrees
    tt = np.arcsin(n1 * np.sin(th) / n2)
    ci, ct = np.cos(th), np.cos(tt)
    rs = (n1 * ci - n2 * ct) / (n1 * ci + n2 * ct)  # eq 5
    rp = (n2 * ci - n1 * ct) / (n1 * ct + n2 * ci)  # eq 9
    ts = 2 * n1 * ci / (n1 * ci + n2 * ct)  # eq 6
    tp = 2 * n1 * ci / (n1 * ct + n2 * ci)  # eq 10
    a_rs, a_rp, a_ts, a_tp = o.fresnel_amplitude(n1, n2, th)
    for got, want in [(a_rs, rs), (a_rp, rp), (a_ts, ts), (a_tp, tp)]:
        np.testing.assert_allclose(got, want, rtol=0, atol=TIGHT)  # same formula, rearranged
    p_rs, p_rp, p_ts, p_tp = o.fresnel_power(n1, n2, th)
    factor = n2 * ct / (n1 * ci)
    for got, want in [(p_rs, rs**2), (p_rp, rp**2), (p_ts, factor * ts**2), (p_tp, factor * tp**2)]:
        np.testing.assert_allclose(got, want, rtol=0, atol=TIGHT)  # eqs 12-15, round-off only


def test_errata_relations_between_amplitudes():
    n1, n2 = 1.0, N_WATER
    r_s, r_p, t_s, t_p = o.fresnel_amplitude(n1, n2, THETA)
    np.testing.assert_allclose(t_s, 1 + r_s, atol=TIGHT)  # tau_s = 1 + r_s, exact algebra
    np.testing.assert_allclose(t_p, n1 / n2 * (1 + r_p), atol=TIGHT)  # tau_p = (n1/n2)(1 + r_p)


def test_normal_incidence_amplitudes():
    n1, n2 = 1.0, N_WATER
    r_s, r_p, _, _ = o.fresnel_amplitude(n1, n2, 0.0)
    expected = (n1 - n2) / (n1 + n2)
    assert r_s == pytest.approx(expected, abs=TIGHT)  # round-off only
    assert r_p == pytest.approx(-expected, abs=TIGHT)  # eq 9 convention: r_p(0) = -r_s(0)
    assert o.fresnel_unpolarised(n1, n2, 0.0)[0] == pytest.approx(expected**2, abs=TIGHT)


@pytest.mark.parametrize(("n1", "n2"), [(1.0, N_WATER), (N_WATER, 1.0), (1.0, 0.96 + 6.69j)])
def test_grazing_incidence_is_total_reflection_without_warning(n1, n2):
    r_s, r_p, t_s, t_p = _no_warnings(o.fresnel_amplitude, n1, n2, np.pi / 2)
    # cos(theta_i) is exactly 0, so r = -q2/q2: exact for real q2, round-off for complex
    assert abs(r_s + 1) < TIGHT and abs(r_p + 1) < TIGHT
    big_r, big_t = _no_warnings(o.fresnel_unpolarised, n1, n2, np.pi / 2)
    assert big_r == pytest.approx(1.0, abs=TIGHT) and big_t == pytest.approx(0.0, abs=TIGHT)


def test_identical_media_have_no_interface_even_at_grazing():
    r_s, r_p, t_s, t_p = _no_warnings(o.fresnel_power, 1.2, 1.2, THETA)
    np.testing.assert_allclose([r_s, r_p], 0.0, atol=TIGHT)  # no contrast, no reflection
    np.testing.assert_allclose([t_s, t_p], 1.0, atol=TIGHT)


# --- Brewster -----------------------------------------------------------------------------------
def test_brewster_air_water():
    theta_b = o.brewster_angle(1.0, N_WATER)
    assert math.degrees(theta_b) == pytest.approx(53.06, abs=0.01)  # errata value, 2 decimals
    r_p = o.fresnel_amplitude(1.0, N_WATER, theta_b)[1]
    assert abs(r_p) < TIGHT  # round-off only


def test_brewster_general_non_magnetic():
    eps2 = N_WATER**2
    angle_p, exists_p = o.brewster_angle_general(1.0, 1.0, eps2, 1.0, polarisation="p")
    assert exists_p and angle_p == pytest.approx(math.atan(N_WATER), abs=TIGHT)  # round-off
    angle_s, exists_s = _no_warnings(o.brewster_angle_general, 1.0, 1.0, eps2, 1.0, "s")
    assert not exists_s and angle_s == 0.0  # mu1 = mu2: no s Brewster angle


def _magnetic_r(eps1, mu1, eps2, mu2, theta, pol):
    """Textbook Fresnel r with permeabilities (impedance form), evaluated independently."""
    n1, n2 = math.sqrt(eps1 * mu1), math.sqrt(eps2 * mu2)
    ci = math.cos(theta)
    ct = math.sqrt(1 - (n1 * math.sin(theta) / n2) ** 2)
    if pol == "s":
        a, b = n1 * ci / mu1, n2 * ct / mu2
    else:
        a, b = n2 * ci / mu2, n1 * ct / mu1
    return (a - b) / (a + b)


@pytest.mark.parametrize(
    ("eps2", "mu2", "pol"),
    [(2.0, 3.0, "s"), (1.5, 4.0, "s"), (1.2, 0.8, "s"), (3.0, 2.0, "p"), (4.0, 1.5, "p")],
)
def test_brewster_general_magnetic_zero_reflection(eps2, mu2, pol):
    angle, exists = o.brewster_angle_general(1.0, 1.0, eps2, mu2, polarisation=pol)
    assert exists
    assert abs(_magnetic_r(1.0, 1.0, eps2, mu2, float(angle), pol)) < TIGHT  # round-off only


def test_brewster_general_reports_absent_angle_consistently():
    # eps1=mu1=1, eps2=2, mu2=3: eq 19 gives sin^2 < 0 for p; check r_p never vanishes
    _, exists = o.brewster_angle_general(1.0, 1.0, 2.0, 3.0, polarisation="p")
    assert not exists
    r = [abs(_magnetic_r(1.0, 1.0, 2.0, 3.0, t, "p")) for t in THETA[:-1]]
    assert min(r) > 0.01  # far from zero everywhere on the grid
    angles, exists = o.brewster_angle_general([1.0, 1.0], 1.0, [2.0, 1.0], [3.0, 1.0], "s")
    assert exists.tolist() == [True, False] and angles[1] == 0.0  # identical media: none


# --- critical angle and TIR ---------------------------------------------------------------------
def test_critical_angle_and_total_reflection():
    theta_c, exists = o.critical_angle(N_WATER, 1.0)
    assert exists and math.degrees(theta_c) == pytest.approx(48.75, abs=0.01)  # 2 decimals
    beyond = np.linspace(float(theta_c) + 1e-6, np.pi / 2, 500)
    r_s, r_p, t_s, t_p = _no_warnings(o.fresnel_power, N_WATER, 1.0, beyond)
    np.testing.assert_allclose([r_s, r_p], 1.0, rtol=0, atol=TIGHT)  # |r| = 1, round-off
    assert np.all(t_s == 0) and np.all(t_p == 0)  # Re q2 is exactly 0 for imaginary q2
    _, tir = o.refraction_angle(N_WATER, 1.0, beyond)
    assert np.all(tir)


def test_critical_angle_absent_when_n1_not_greater():
    angle, exists = o.critical_angle([1.0, 1.0], [N_WATER, 1.0])
    assert not exists.any() and np.all(angle == np.pi / 2)


def test_refraction_angle_scalar_snell():
    theta_t, tir = _no_warnings(o.refraction_angle, 1.0, N_WATER, THETA)
    assert not tir.any()
    np.testing.assert_allclose(np.sin(theta_t) * N_WATER, np.sin(THETA), atol=TIGHT)
    theta_t, tir = _no_warnings(o.refraction_angle, N_WATER, 1.0, THETA)
    assert np.all(theta_t[tir] == np.pi / 2) and not np.isnan(theta_t).any()


# --- complex index ------------------------------------------------------------------------------
def _boundary_solve(n1, n2, theta, pol):
    """Solve the 2x2 tangential-field continuity system for plane waves (units of k0).

    s (TE): E_y = exp(i q1 z) + r exp(-i q1 z) | t exp(i q2 z); continuity of E_y and of
    H_x ~ dE_y/dz. p (TM): the same with H_y and E_x ~ (1/eps) dH_y/dz; the document's r_p
    is the H-field ratio and its t_p = (n1/n2) t_H.
    """
    eps1, eps2 = n1**2, n2**2
    q1 = n1 * math.cos(theta)
    q2 = complex(_decaying_root(eps2 - eps1 * math.sin(theta) ** 2))
    g1, g2 = (q1, q2) if pol == "s" else (q1 / eps1, q2 / eps2)
    a = np.array([[1.0, -1.0], [-g1, -g2]], dtype=complex)  # unknowns (r, t)
    b = np.array([-1.0, -g1], dtype=complex)
    r, t = np.linalg.solve(a, b)
    return r, (t if pol == "s" else n1 / n2 * t)


@pytest.mark.parametrize("n2", [1.5 + 0.3j, 0.96 + 6.69j, 0.05 + 3.2j, N_WATER + 1.8e-9j])
@pytest.mark.parametrize("theta_deg", [0.0, 20.0, 45.0, 70.0, 89.0])
def test_complex_index_against_boundary_condition_solve(n2, theta_deg):
    theta = math.radians(theta_deg)
    r_s, r_p, t_s, t_p = o.fresnel_amplitude(1.0, n2, theta)
    for pol, r, t in [("s", r_s, t_s), ("p", r_p, t_p)]:
        r_ref, t_ref = _boundary_solve(1.0, n2, theta, pol)
        assert abs(r - r_ref) < TIGHT and abs(t - t_ref) < TIGHT  # LU solve round-off


def test_absorbing_exit_medium_conserves_energy():
    r_s, r_p, t_s, t_p = _no_warnings(o.fresnel_power, 1.0, 1.5 + 0.3j, THETA)
    np.testing.assert_allclose([r_s + t_s, r_p + t_p], 1.0, atol=TIGHT)  # flux continuity


def test_metal_normal_incidence_reflectance():
    n, k = 0.96, 6.69  # aluminium near 532 nm (Rakic 1995)
    r_u, _ = o.fresnel_unpolarised(1.0, n + 1j * k, 0.0)
    textbook = ((n - 1) ** 2 + k**2) / ((n + 1) ** 2 + k**2)
    assert r_u == pytest.approx(textbook, abs=TIGHT)  # round-off only
    assert r_u == pytest.approx(0.92, abs=0.01)  # handbook Al reflectance at 532 nm, ~92 %


def test_power_rejects_absorbing_incidence_medium():
    with pytest.raises(ValueError, match="`n1` must be real"):
        o.fresnel_power(1.0 + 0.1j, 1.33, 0.3)


# --- Jones --------------------------------------------------------------------------------------
def test_jones_polarisations():
    th = THETA[::50]
    r_s, r_p, t_s, t_p = o.fresnel_power(1.0, N_WATER, th)
    r_u, t_u = o.fresnel_unpolarised(1.0, N_WATER, th)
    for jones in [o.jones_linear(np.pi / 4), o.jones_circular("right"), o.jones_circular("left")]:
        r, t = o.fresnel_jones(1.0, N_WATER, th, jones)
        np.testing.assert_allclose([r, t], [r_u, t_u], atol=TIGHT)  # equal s and p weights
    r, t = o.fresnel_jones(1.0, N_WATER, th, [2.0, 0.0])  # unnormalised pure s
    np.testing.assert_allclose([r, t], [r_s, t_s], atol=TIGHT)
    r, t = o.fresnel_jones(1.0, N_WATER, th, o.jones_linear(np.pi / 2))  # pure p
    np.testing.assert_allclose([r, t], [r_p, t_p], atol=TIGHT)
    with pytest.raises(ValueError, match="jones"):
        o.fresnel_jones(1.0, N_WATER, 0.1, [0.0, 0.0])
    with pytest.raises(ValueError, match="handedness"):
        o.jones_circular("up")


# --- vector Snell -------------------------------------------------------------------------------
@pytest.mark.parametrize(("n1", "n2"), [(1.0, N_WATER), (N_WATER, 1.0)])
def test_vector_snell_random(n1, n2):
    rng = np.random.default_rng(12345)
    d = rng.normal(size=(1000, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    normal = rng.normal(size=(1000, 3))
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)  # random orientation too
    t, tir = _no_warnings(o.refract_direction, d, normal, n1, n2)
    assert t.shape == (1000, 3) and tir.shape == (1000,)
    np.testing.assert_allclose(np.linalg.norm(t, axis=-1), 1.0, atol=TIGHT)
    cos_i = np.abs(np.sum(d * normal, axis=-1))
    sin_i = np.sqrt(1 - cos_i**2)
    assert np.array_equal(tir, sin_i > n2 / n1)  # no sample lies on the boundary (seeded)
    ok = ~tir
    np.testing.assert_allclose(  # tangential phase matching, round-off only
        n1 * np.cross(d[ok], normal[ok]), n2 * np.cross(t[ok], normal[ok]), atol=1e-12
    )
    plane_normal = np.cross(d, normal)
    np.testing.assert_allclose(np.sum(t * plane_normal, axis=-1), 0.0, atol=1e-12)  # coplanar
    # transmitted ray continues through the surface: same side as d with respect to normal
    side_t, side_d = np.sum(t[ok] * normal[ok], -1), np.sum(d[ok] * normal[ok], -1)
    assert np.all(np.sign(side_t) == np.sign(side_d))
    theta_t, _ = o.refraction_angle(n1, n2, np.arccos(cos_i[ok]))
    got = np.arccos(np.clip(np.abs(np.sum(t[ok] * normal[ok], -1)), 0, 1))
    np.testing.assert_allclose(got, theta_t, atol=1e-7)  # arccos near 0 amplifies round-off
    np.testing.assert_allclose(t[tir], o.reflect_direction(d[tir], normal[tir]), atol=TIGHT)
    if n1 > n2:
        assert tir.any()


def test_vector_snell_normal_incidence_and_errors():
    t, tir = o.refract_direction([0.0, 0.0, -1.0], [0.0, 0.0, 1.0], 1.0, N_WATER)
    np.testing.assert_allclose(t, [0.0, 0.0, -1.0], atol=TIGHT)
    assert not tir
    with pytest.raises(ValueError, match=r"`d` must have shape \(\.\.\., 3\)"):
        o.refract_direction([1.0, 0.0], [0.0, 0.0, 1.0], 1.0, 1.33)
    with pytest.raises(ValueError, match="`normal norm` must be finite and > 0; got 0.0"):
        o.refract_direction([1.0, 0.0, 0.0], [0.0, 0.0, 0.0], 1.0, 1.33)


# --- absorption, extinction, Beer-Lambert -------------------------------------------------------
def test_document_absorption_example():
    beta = math.log(100.0) / 1e-3  # 1 % transmitted through 1 mm
    n_i = o.index_imag_from_absorption(beta, 500e-9)
    assert float(f"{n_i:.2g}") == 1.8e-4  # the document quotes two significant digits
    assert o.absorption_coefficient_from_index(n_i, 500e-9) == pytest.approx(beta, rel=TIGHT)
    assert o.beer_lambert_transmittance(beta, 1e-3) == pytest.approx(0.01, rel=TIGHT)


def test_penetration_depth():
    assert o.extinction_from_penetration_depth(50.0) == pytest.approx(0.02, rel=TIGHT)
    assert o.penetration_depth_m(0.02) == pytest.approx(50.0, rel=TIGHT)
    assert _no_warnings(o.penetration_depth_m, 0.0) == np.inf
    assert o.extinction_from_penetration_depth(np.inf) == 0.0
    assert o.total_extinction(0.01, 0.0099) == pytest.approx(0.0199, rel=TIGHT)


def test_beer_lambert_huge_extinction():
    log_t = o.log_transmittance(1e4, 1e3)
    assert np.isfinite(log_t) and log_t == -1e7
    with np.errstate(all="raise"):
        assert _no_warnings(o.beer_lambert_transmittance, 1e4, 1e3) == 0.0
    # the document's worked example: beta = 0.0199 /m over D = 50 m leaves "0.37"
    t = o.beer_lambert_transmittance(0.0199, [0.0, 50.0])
    np.testing.assert_allclose(t, [1.0, 0.37], atol=0.005)  # document prints 2 digits


# --- tables, water index, photons ---------------------------------------------------------------
def test_graybody_table():
    assert o.GRAYBODY_AMPLITUDE_PERCENT["fresh_dry_snow"] == (70.0, 90.0)
    assert len(o.GRAYBODY_AMPLITUDE_PERCENT) == 5
    assert o.graybody_power_reflectance(90.0) == pytest.approx(0.81, rel=TIGHT)


@pytest.mark.parametrize(
    ("salinity", "phase", "group"), [(35.0, 1.3415, 1.3638), (0.0, 1.3350, 1.3566)]
)
def test_water_index_errata_values(salinity, phase, group):
    n = o.water_phase_index(532e-9, salinity, 20.0)
    n_g = o.water_group_index(532e-9, salinity, 20.0)
    assert n == pytest.approx(phase, abs=5e-4)  # errata values are quoted to 4 decimals
    assert n_g == pytest.approx(group, abs=5e-4)
    lam, h = 532e-9, 1e-12  # central difference: independent check of the analytic derivative
    dn = (o.water_phase_index(lam + h, salinity) - o.water_phase_index(lam - h, salinity)) / (2 * h)
    assert n_g == pytest.approx(n - lam * dn, abs=1e-7)  # O(h^2) truncation + cancellation


def test_water_index_rejects_out_of_fit_range():
    with pytest.raises(ValueError, match="`wavelength_m` must be in"):
        o.water_phase_index(1064e-9)


def test_photons_per_pulse():
    h, c = 6.62607015e-34, 299792458.0  # exact SI defining constants
    expected = 2.5e-6 / (h * c / 532e-9)  # pulse energy over photon energy h nu
    assert o.photons_per_pulse(2.5e-6, 532e-9) == pytest.approx(expected, rel=TIGHT)
    assert o.SPEED_OF_LIGHT_M_S == c


# --- validation and broadcasting ----------------------------------------------------------------
@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: o.fresnel_power(-1, 1.33, 0.0), "`n1` must be .*; got -1"),
        (lambda: o.fresnel_amplitude(1.0, 1.33 - 0.1j, 0.0), "`n2` must be"),
        (lambda: o.fresnel_unpolarised(1.0, 1.33, [0.0, 2.0]), r"`theta_i_rad` .*; got 2\.0"),
        (lambda: o.refraction_angle(1.0, np.nan, 0.1), "`n2` must be"),
        (lambda: o.log_transmittance(-0.1, 1.0), "`extinction_per_m` must be .*; got -0.1"),
        (lambda: o.penetration_depth_m(-1.0), "`extinction_per_m`"),
        (lambda: o.extinction_from_penetration_depth(0.0), "`depth_m` must be > 0"),
        (lambda: o.graybody_power_reflectance(120.0), "`amplitude_percent`"),
        (lambda: o.brewster_angle_general(1, 1, 2, 1, "x"), "`polarisation`"),
        (lambda: o.photons_per_pulse(1e-6, 0.0), "`wavelength_m`"),
    ],
)
def test_invalid_inputs_raise_clear_errors(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_broadcasting_shapes():
    n2 = np.array([[1.33], [1.5], [2.0 + 0.1j]])
    out = o.fresnel_power(1.0, n2, THETA[:5])
    assert all(a.shape == (3, 5) for a in out)
    assert isinstance(o.fresnel_unpolarised(1.0, 1.33, 0.0)[0], np.floating)
