"""The reference profiling bathymeter: transmittance, photon budget, ideal ranges, histograms.

Rebuilds Figures 14-17 of the reference document from the lidar equation
(:mod:`pipeline.lidar_equation`) for a nadir beam over flat water and a flat floor.

Photon histograms are simulated in the photon domain: per shot, each return's photoelectron
count is Poisson with the lidar-equation mean, arrival times follow the return's time shape
(the Gaussian transmitted pulse, and for the water column the backscatter profile), and
background (solar + dark) events are uniform over the range gate. Counts accumulated over N
shots are then histogrammed. No dead time is modelled here: the budget reports where a
single-photon detector would be pile-up limited instead.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import ndtr

from pipeline import lidar_equation as le
from pipeline import optics
from pipeline.constants import FWHM_TO_SIGMA

__all__ = [
    "TransmittanceProfile",
    "transmittance_profile",
    "budget_vs_depth",
    "ideal_times",
    "RangeGate",
    "range_gate",
    "expected_histogram",
    "simulate_histogram",
]

#: σ of a Gaussian pulse = FWHM / (2 √(2 ln 2)).
C_M_S = optics.SPEED_OF_LIGHT_M_S


@dataclass(frozen=True)
class TransmittanceProfile:
    """One-way transmittance along the nadir path (Figure 14).

    Attributes
    ----------
    path_m : ndarray, shape (n,)
        Distance from the instrument along the beam, metres; the surface is at ``altitude_m``.
    log_transmittance : ndarray, shape (n,)
        ln of the fraction of transmitted photons reaching ``path_m`` (air, surface, water).
    altitude_m, depth_m : float
    """

    path_m: np.ndarray
    log_transmittance: np.ndarray
    altitude_m: float
    depth_m: float


def transmittance_profile(scene, n_points: int = 400) -> TransmittanceProfile:
    """One-way transmittance from the instrument to the floor, through the surface."""
    h = scene.profiler.altitude_m
    d = scene.seabed.depth_m
    s = np.linspace(0.0, h + d, n_points)
    s = np.union1d(s, [h])  # the surface itself, so the Fresnel step is drawn sharply
    r0, _ = optics.fresnel_unpolarised(
        scene.atmosphere.refractive_index, scene.water.phase_index, 0.0
    )
    in_air = s <= h
    log_t = np.where(
        in_air,
        optics.log_transmittance(scene.atmosphere.extinction_per_m, np.minimum(s, h)),
        optics.log_transmittance(scene.atmosphere.extinction_per_m, h)
        + math.log1p(-float(r0))
        + optics.log_transmittance(scene.water.extinction_per_m, np.maximum(s - h, 0.0)),
    )
    return TransmittanceProfile(path_m=s, log_transmittance=log_t, altitude_m=h, depth_m=d)


def budget_vs_depth(scene, depths_m) -> dict[str, np.ndarray]:
    """Expected photoelectrons per shot against depth (Figure 15).

    Returns
    -------
    dict
        ``depth_m`` (n,), ``surface`` (n,), ``floor`` (n,) and ``column`` (n,): the water
        column integrated from the surface to each depth.
    """
    h = scene.profiler.altitude_m
    depths = np.asarray(depths_m, dtype=float)
    floor_log = np.array([le.nadir_budget(scene, h, float(d)).floor_log_photons for d in depths])
    surface = le.nadir_budget(scene, h, float(depths[0])).surface_photons
    # cumulative trapezoid of the column density on a fine grid, read at each depth
    z = np.linspace(0.0, float(depths.max()), 4001)
    dens = np.exp(le.column_log_photons_per_m(scene, h, z))
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(z))])
    return {
        "depth_m": depths,
        "surface": np.full_like(depths, surface),
        "floor": np.exp(floor_log),
        "floor_log": floor_log,
        "column": np.interp(depths, z, cum),
    }


def ideal_times(scene, depths_m) -> dict[str, np.ndarray]:
    """Noise-free times of flight and the ranges retrieved from them (Figure 16).

    The surface range uses the air index; the depth uses the group index of water, because the
    pulse travels at the group velocity. ``depth_if_phase_index_m`` shows the bias of using the
    phase index instead.
    """
    h = scene.profiler.altitude_m
    depths = np.asarray(depths_m, dtype=float)
    n_air = scene.atmosphere.refractive_index
    t_surface = 2.0 * h * n_air / C_M_S
    t_floor = t_surface + 2.0 * depths * scene.water.group_index / C_M_S
    dt = t_floor - t_surface
    return {
        "depth_m": depths,
        "t_surface_s": np.full_like(depths, t_surface),
        "t_floor_s": t_floor,
        "surface_range_m": np.full_like(depths, C_M_S * t_surface / (2.0 * n_air)),
        "depth_from_tof_m": C_M_S * dt / (2.0 * scene.water.group_index),
        "depth_if_phase_index_m": C_M_S * dt / (2.0 * scene.water.phase_index),
    }


@dataclass(frozen=True)
class RangeGate:
    """Histogram bins and the per-shot expected rates of each return.

    Attributes
    ----------
    edges_s : ndarray, shape (n_bins + 1,)
        Bin edges, seconds after the shot.
    t_surface_s, t_floor_s, sigma_s : float
        Return centres and the Gaussian pulse σ.
    surface_photons, floor_photons, column_photons : float
        Expected photoelectrons per shot of each return.
    background_rate_hz : float
        Solar background plus dark counts, per second.
    column_z_m, column_weight : ndarray, shape (m,)
        Depth grid of the column return and the probability of each grid cell.
    """

    edges_s: np.ndarray
    t_surface_s: float
    t_floor_s: float
    sigma_s: float
    surface_photons: float
    floor_photons: float
    column_photons: float
    background_rate_hz: float
    column_z_m: np.ndarray
    column_weight: np.ndarray

    @property
    def duration_s(self) -> float:
        """Length of the range gate, seconds."""
        return float(self.edges_s[-1] - self.edges_s[0])


def range_gate(scene) -> RangeGate:
    """Bins and per-return expectations for the scene's profiler at its seabed depth."""
    prof = scene.profiler
    h = prof.altitude_m
    d = scene.seabed.depth_m
    times = ideal_times(scene, [d])
    t_s = float(times["t_surface_s"][0])
    t_f = float(times["t_floor_s"][0])
    start = t_s - prof.gate_before_surface_s
    n_bins = max(1, math.ceil((t_f + prof.gate_after_floor_s - start) / prof.bin_width_s))
    edges = start + prof.bin_width_s * np.arange(n_bins + 1)
    budget = le.nadir_budget(scene, h, d)
    z = np.linspace(0.0, d, 2001)[1:] - d / 4000.0  # cell centres
    dens = np.exp(le.column_log_photons_per_m(scene, h, z))
    cell = dens * (d / 2000.0)
    total = float(cell.sum())
    weight = cell / total if total > 0 else np.zeros_like(cell)
    bg = le.solar_background_rate_hz(scene, h) + scene.system.dark_count_rate_hz
    return RangeGate(
        edges_s=edges,
        t_surface_s=t_s,
        t_floor_s=t_f,
        sigma_s=scene.system.pulse_fwhm_s * FWHM_TO_SIGMA,
        surface_photons=budget.surface_photons,
        floor_photons=budget.floor_photons,
        column_photons=total,
        background_rate_hz=bg,
        column_z_m=z,
        column_weight=weight,
    )


def _gauss_bin_fraction(edges_s: np.ndarray, centre_s, sigma_s: float) -> np.ndarray:
    """Fraction of a Gaussian pulse centred at ``centre_s`` falling in each bin."""
    c = np.atleast_1d(np.asarray(centre_s, dtype=float))[:, None]
    cdf = ndtr((edges_s[None, :] - c) / sigma_s)
    return np.diff(cdf, axis=1)


def expected_histogram(scene, gate: RangeGate) -> dict[str, np.ndarray]:
    """Expected photoelectrons per shot in each bin, by return (analytic: erf integrals).

    Returns
    -------
    dict of ndarray, shape (n_bins,)
        ``surface``, ``floor``, ``column``, ``background`` and ``total``.
    """
    e = gate.edges_s
    surface = gate.surface_photons * _gauss_bin_fraction(e, gate.t_surface_s, gate.sigma_s)[0]
    floor = gate.floor_photons * _gauss_bin_fraction(e, gate.t_floor_s, gate.sigma_s)[0]
    t_col = gate.t_surface_s + 2.0 * gate.column_z_m * scene.water.group_index / C_M_S
    column = gate.column_photons * (
        gate.column_weight @ _gauss_bin_fraction(e, t_col, gate.sigma_s)
    )
    background = gate.background_rate_hz * np.diff(e)
    total = surface + floor + column + background
    return {
        "surface": surface,
        "floor": floor,
        "column": column,
        "background": background,
        "total": total,
    }


def simulate_histogram(
    scene,
    gate: RangeGate,
    n_shots: int,
    rng: np.random.Generator,
    chunk_shots: int = 20000,
    max_events: float = 2e7,
    expected_total: np.ndarray | None = None,
) -> np.ndarray:
    """Photon counts per bin accumulated over ``n_shots`` simulated shots.

    Parameters
    ----------
    n_shots : int
        Shots to accumulate.
    rng : numpy.random.Generator
        Source of every random draw.
    chunk_shots : int
        Shots drawn at once; bounds memory to O(chunk_shots × photons per shot).
    max_events : float
        Above this many expected events in all, the per-bin sums are drawn directly.
    expected_total : (n_bins,) ndarray, optional
        ``expected_histogram(scene, gate)["total"]`` if already computed.

    Returns
    -------
    ndarray of int64, shape (n_bins,)
    """
    if n_shots < 1:
        raise ValueError(f"`n_shots` must be >= 1; got {n_shots}.")
    e = gate.edges_s
    lam_bg = gate.background_rate_hz * gate.duration_s
    per_shot = gate.surface_photons + gate.floor_photons + gate.column_photons + lam_bg
    if n_shots * per_shot > max_events:
        # without dead time, counts summed over shots are Poisson with the summed mean in
        # every bin: drawing them directly is exact in distribution and O(bins), not O(events)
        if expected_total is None:
            expected_total = expected_histogram(scene, gate)["total"]
        return rng.poisson(n_shots * expected_total).astype(np.int64)
    counts = np.zeros(e.size - 1, dtype=np.int64)
    n_g = scene.water.group_index
    done = 0
    while done < n_shots:
        m = min(chunk_shots, n_shots - done)
        # per-shot Poisson counts of each return, then one arrival time per photoelectron
        k_s = int(rng.poisson(gate.surface_photons, m).sum())
        k_f = int(rng.poisson(gate.floor_photons, m).sum())
        k_c = int(rng.poisson(gate.column_photons, m).sum())
        k_b = int(rng.poisson(lam_bg, m).sum())
        t_parts = [
            gate.t_surface_s + gate.sigma_s * rng.standard_normal(k_s),
            gate.t_floor_s + gate.sigma_s * rng.standard_normal(k_f),
            e[0] + gate.duration_s * rng.random(k_b),
        ]
        if k_c:
            z = rng.choice(gate.column_z_m, size=k_c, p=gate.column_weight)
            t_parts.append(
                gate.t_surface_s + 2.0 * z * n_g / C_M_S + gate.sigma_s * rng.standard_normal(k_c)
            )
        counts += np.histogram(np.concatenate(t_parts), bins=e)[0]
        done += m
    return counts
