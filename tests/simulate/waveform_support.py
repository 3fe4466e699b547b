"""Shared helpers of the waveform tests: scenes, detectors and an independent lidar equation.

The reference formulas here are written from the physics (CODATA constants, textbook Fresnel,
Cox & Munk 1954, Monahan & O'Muircheartaigh 1980, Koepke 1984), never by calling the code under
test, so a test comparing against them checks the implementation, not its echo.
"""

from __future__ import annotations

import dataclasses
import math
import tomllib
from pathlib import Path

import numpy as np

from pipeline.config import from_mapping
from pipeline.scene import parse_scene
from pipeline.simulate.budget import ReturnSettings
from pipeline.simulate.detector import DetectorSettings, load_preset

H_PLANCK = 6.62607015e-34  # J s, exact (SI 2019)
C_LIGHT = 299_792_458.0  # m/s, exact


WAVEFORM_SCENE = Path(__file__).with_name("waveform_scene.toml")


def make_scene(**sections):
    """The default scene with whole-section overrides, e.g. ``water={"extinction_per_m": 0.1}``."""
    data = tomllib.loads(WAVEFORM_SCENE.read_text(encoding="utf-8"))
    for name, values in sections.items():
        data.setdefault(name, {}).update(values)
    return parse_scene(data)


def clean_scene(returns=None, **water):
    """Flat calm-ish water, no sun, air index 1 (for comparisons with nadir_budget).

    The single-scattering lidar equation of the reference document: beam attenuation ``c`` and
    no forward-scattering delay, unless ``returns`` says otherwise (the field-of-view attenuation
    and the delay have their own tests against independent references).
    """
    w = {"extinction_per_m": 0.15, "backscatter_180_per_m_sr": 2e-3, "wind_speed_m_s": 5.0}
    w.update(water)
    rs = {"lidar_attenuation": "beam", "forward_scatter": "none"}
    rs.update(returns or {})
    return make_scene(
        atmosphere={"extinction_per_m": 1.5e-4, "refractive_index": 1.0},
        water=w,
        background={"solar_irradiance_w_m2_nm": 0.0},
        system={"dark_count_rate_hz": 0.0},
        returns=rs,
    )


def detector(**kw):
    """A full-waveform detector with a long window (all returns inside for depths < 60 m)."""
    base = {"window_s": 1.2e-6, "pre_trigger_s": 5e-8, "sample_rate_hz": 1e9}
    base.update(kw)
    return DetectorSettings(**base)


def preset(name):
    """(system table, scanner table, DetectorSettings, ReturnSettings) of a preset."""
    pre = load_preset(name)
    det = from_mapping(DetectorSettings, pre["detector"], "detector")
    rs = from_mapping(ReturnSettings, pre["returns"], "returns")
    return pre["system"], pre["scanner"], det, rs


def replace(obj, **kw):
    return dataclasses.replace(obj, **kw)


# --- independent lidar equation -----------------------------------------------------------------
def fresnel_unpolarised_t(n1, n2, theta1):
    """Unpolarised power transmittance from the textbook Fresnel amplitudes (real indices)."""
    s1 = math.sin(theta1)
    c1 = math.cos(theta1)
    s2 = n1 / n2 * s1
    c2 = math.sqrt(1.0 - s2 * s2)
    rs = (n1 * c1 - n2 * c2) / (n1 * c1 + n2 * c2)
    rp = (n2 * c1 - n1 * c2) / (n2 * c1 + n1 * c2)
    return 1.0 - 0.5 * (rs * rs + rp * rp)


def common_pe(scene):
    """Transmitted photons x efficiencies x aperture x overlap (per unit of the rest)."""
    s = scene.system
    photons = s.pulse_energy_j * s.wavelength_nm * 1e-9 / (H_PLANCK * C_LIGHT)
    aperture = math.pi * s.telescope_diameter_m**2 / 4.0
    eff = s.transmitter_efficiency * s.receiver_efficiency * s.overlap_factor
    return photons * eff * aperture


def surface_sr(scene, theta):
    """Backscatter per sr per incident watt of the sea surface at incidence theta."""
    w = scene.water
    n = w.phase_index / scene.atmosphere.refractive_index
    r0 = ((n - 1.0) / (n + 1.0)) ** 2
    mss = max(0.003 + 5.12e-3 * w.wind_speed_m_s, 0.003)
    cover = min(2.95e-6 * w.wind_speed_m_s**3.52, 1.0)
    c = math.cos(theta)
    glint = (1 - cover) * r0 * math.exp(-(math.tan(theta) ** 2) / mss) / (4 * math.pi * mss * c**5)
    return glint + cover * 0.22 * c / math.pi


def numeric_domega_per_area(air_range, water_path, theta_a, n_a, n_w, h=1e-6):
    """In-water solid angle per unit aperture area, by finite differences of a ray bundle.

    A point source at in-water path ``water_path`` below a flat surface; rays leaving it at
    polar angle ``tw +- h`` and azimuth ``+- h`` are refracted and intersected with the plane
    normal to the central air ray at ``air_range`` beyond the surface.
    """
    tw0 = math.asin(n_a / n_w * math.sin(theta_a))
    depth = water_path * math.cos(tw0)
    axis = np.array([math.sin(theta_a), 0.0, math.cos(theta_a)])
    p0 = np.array([depth * math.tan(tw0), 0.0, 0.0]) + air_range * axis

    def hit(tw, ph):
        d = np.array([math.sin(tw) * math.cos(ph), math.sin(tw) * math.sin(ph), math.cos(tw)])
        s = np.array([0.0, 0.0, -depth]) + depth / math.cos(tw) * d
        sa = n_w / n_a * math.sin(tw)
        da = np.array([sa * math.cos(ph), sa * math.sin(ph), math.sqrt(1 - sa * sa)])
        return s + np.dot(p0 - s, axis) / np.dot(da, axis) * da

    d_tw = (hit(tw0 + h, 0.0) - hit(tw0 - h, 0.0)) / (2 * h)
    d_ph = (hit(tw0, h) - hit(tw0, -h)) / (2 * h)
    return math.sin(tw0) / np.linalg.norm(np.cross(d_tw, d_ph))
