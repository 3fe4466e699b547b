"""Depth posteriors of pulses carried to the refraction-corrected seabed point.

The posterior draws of ``(depth, t_s)`` (:func:`pipeline.uncertainty.posterior.sample_batch`)
become round-trip times ``t0 + t_s`` and ``t0 + t_s + tau(depth)`` and go through
:func:`pipeline.process.refraction.seabed_points` (all draws of a pulse in one call), so the
reported posterior is on the 3-D seabed point (and its depth below the fitted surface), with
the processing's own refraction.

Nuisances the waveform does not hold
------------------------------------
The waveform fixes the in-water range; the depth compared at the point's measured position
also moves with what no waveform sees: the navigation and attitude errors (through the seabed
slope), the wave facet's slope that bent the beam, the fitted plane's tilt, the wave height, the
water indices. Those are the TPU's terms (:mod:`pipeline.uncertainty.tpu`) other than the two
timing terms the posterior replaces; given their one-sigma depth changes
(``nuisance_depth_sigma_m``), each draw gets an independent Gaussian nuisance of that sigma,
i.e. the depth posterior is marginalised over them (the convolution of the waveform posterior
with their Gaussian; first order, as the TPU). Without it the intervals held the waveform's
ranging noise alone: about 1 cm, against a few cm of error from the terms above on sloping or
wavy scenes (``benchmarks/RESULTS_posterior.md``).

Cost: see ``benchmarks/RESULTS_posterior.md``.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass
from typing import Any

import numpy as np
from tqdm import tqdm

from pipeline.process.detect import DetectSettings
from pipeline.process.refraction import RefractionSettings, seabed_points
from pipeline.process.returns import DetectedReturns
from pipeline.process.surface_fit import WaterSurface
from pipeline.uncertainty.posterior import interval_summary, sample_batch
from pipeline.uncertainty.posterior_settings import PosteriorFlag, PosteriorSettings
from pipeline.uncertainty.waveform_model import N_PARAMS, WaveformSystem, in_water_delay_s

__all__ = [
    "SeabedPosteriors",
    "water_cosine",
    "take_surface",
    "draws_to_seabed",
    "draws_to_seabed_rows",
    "seabed_posteriors",
]


def water_cosine(direction: Any, normal: Any, air_index: float, phase_index: float) -> np.ndarray:
    """Cosine of the refracted beam's angle to the surface normal, by Snell's law.

    ``direction`` and ``normal`` are (n, 3) unit vectors; grazing or totally reflected beams
    give the smallest positive cosine rather than NaN.
    """
    d = np.asarray(direction, dtype=np.float64)
    n = np.asarray(normal, dtype=np.float64)
    cos_i = np.abs(np.sum(d * n, axis=-1))
    sin_w = air_index / phase_index * np.sqrt(np.maximum(1.0 - cos_i**2, 0.0))
    return np.sqrt(np.maximum(1.0 - sin_w**2, 1e-12))


_SURFACE_ROWS = (
    "entry_m",
    "range_to_entry_m",
    "normal",
    "is_water",
    "is_land",
    "surface_point_m",
    "surface_residual_m",
    "fit_sigma_m",
    "height_sigma_m",
    "normal_sigma_rad",
    "n_used",
    "flags",
    "own_weight",
    "own_shift_m",
    "facet_slope_var",
    "track_xy",
)


def take_surface(surface: WaterSurface, index: Any) -> WaterSurface:
    """The rows ``index`` of a fitted surface (repeats allowed), as a new object."""
    kw = {
        name: None if getattr(surface, name) is None else getattr(surface, name)[index]
        for name in _SURFACE_ROWS
    }
    return WaterSurface(
        **kw,
        global_plane=surface.global_plane,
        global_sigma_m=surface.global_sigma_m,
        air_index=surface.air_index,
        time_window_s=surface.time_window_s,
        sea_correlation=surface.sea_correlation,
    )


@dataclass(frozen=True)
class SeabedPosteriors:
    """Posterior summaries of the refraction-corrected seabed point per sampled pulse.

    Attributes
    ----------
    pulse_id : (n,) int64
    row : (n,) int64
        Row of the pulse in the input arrays.
    depth_m : dict of (n,) ndarray
        :func:`interval_summary` of the depth below the fitted surface (``median``, ``lo68``,
        ``hi68``, ``lo95``, ``hi95``, ``std``), metres.
    xyz_median_m : (n, 3) ndarray
        Per-coordinate posterior median of the seabed point.
    xyz_std_m : (n, 3) ndarray
        Per-coordinate posterior standard deviation.
    sigma_h_m : (n,) ndarray
        Horizontal per-axis (circular) standard deviation ``sqrt((var_x + var_y) / 2)``.
    acceptance, tau_max_steps : (n,) ndarray
    n_steps : (n,) int64
    flags : (n,) uint16
        :class:`PosteriorFlag` bits.
    waveform_depth_m : dict of (n,) ndarray or None
        The same summaries of the waveform posterior alone, before the nuisances; its
        ``std`` (:attr:`waveform_std_m`) replaces the TPU's timing terms in the cells
        (:func:`~pipeline.uncertainty.survey_uncertainty.with_posteriors`).
    theta_median : (n, 9) ndarray or None
        Per-parameter posterior median of the waveform model's parameters (zeros where
        NO_START): with ``cos_water`` it gives the posterior's fitted waveform
        (:func:`~pipeline.uncertainty.waveform_model.expected_waveform`), e.g. for the report.
    cos_water : (n,) ndarray or None
        Cosine of each pulse's in-water angle the model used.
    """

    pulse_id: np.ndarray
    row: np.ndarray
    depth_m: dict[str, np.ndarray]
    xyz_median_m: np.ndarray
    xyz_std_m: np.ndarray
    sigma_h_m: np.ndarray
    acceptance: np.ndarray
    tau_max_steps: np.ndarray
    n_steps: np.ndarray
    flags: np.ndarray
    theta_median: np.ndarray | None = None
    cos_water: np.ndarray | None = None
    waveform_depth_m: dict[str, np.ndarray] | None = None

    @property
    def waveform_std_m(self) -> np.ndarray | None:
        """(n,) depth sigma of the waveform posterior alone (None if not recorded)."""
        return None if self.waveform_depth_m is None else self.waveform_depth_m["std"]

    @property
    def converged(self) -> np.ndarray:
        """(n,) bool: neither NOT_CONVERGED nor ACCEPTANCE (nor NO_START)."""
        bad = PosteriorFlag.NOT_CONVERGED | PosteriorFlag.ACCEPTANCE | PosteriorFlag.NO_START
        return (self.flags & np.uint16(bad)) == 0


def draws_to_seabed(
    chain_draws: np.ndarray,
    row: int,
    t0_s: float,
    returns: DetectedReturns,
    surface: WaterSurface,
    system: WaveformSystem,
    cos_water: float,
    refraction_settings: RefractionSettings | None = None,
):
    """Refraction-corrected seabed points (``Points``) of every posterior draw of one pulse."""
    return draws_to_seabed_rows(
        [chain_draws], np.array([row]), np.array([t0_s]), returns, surface, system,
        np.array([cos_water]), refraction_settings,
    )[0]  # fmt: skip


def draws_to_seabed_rows(
    draws: list,
    rows: np.ndarray,
    t0_s: np.ndarray,
    returns: DetectedReturns,
    surface: WaterSurface,
    system: WaveformSystem,
    cos_water: np.ndarray,
    refraction_settings: RefractionSettings | None = None,
) -> list:
    """:func:`draws_to_seabed` of several pulses in one pass of the refraction.

    ``draws[j]`` (k_j, 9) are pulse ``rows[j]``'s draws, ``t0_s[j]`` its record's start and
    ``cos_water[j]`` its in-water cosine. Every draw is georeferenced on its own (row by row:
    the same points as one pulse at a time); the pass's fixed costs are paid once.

    Returns
    -------
    list of Points
        One per pulse, its draws' points in order.
    """
    if not draws:
        return []
    k = np.array([d.shape[0] for d in draws])
    th = np.concatenate(draws)
    idx = np.repeat(np.asarray(rows), k)
    ts = np.repeat(np.asarray(t0_s, dtype=np.float64), k) + th[:, 1] * 1e-9
    cw = np.repeat(np.asarray(cos_water, dtype=np.float64), k)
    tb = ts + in_water_delay_s(th[:, 0], cw, system.group_index)
    ones = np.ones(idx.size, dtype=bool)
    ret = DetectedReturns(
        pulse_id=returns.pulse_id[idx],
        origin_meas_m=returns.origin_meas_m[idx],
        direction_meas=returns.direction_meas[idx],
        has_surface=ones,
        t_surface_s=ts,
        has_bottom=ones,
        t_bottom_s=tb,
        surface_confidence=np.maximum(returns.surface_confidence[idx], 1e-6),
        bottom_confidence=np.maximum(returns.bottom_confidence[idx], 1e-6),
        flags=returns.flags[idx],
    )
    pts = seabed_points(ret, take_surface(surface, idx), refraction_settings)
    ends = np.cumsum(k)
    return [pts.select(np.arange(e - n, e)) for e, n in zip(ends, k, strict=True)]


def seabed_posteriors(
    samples: Any,
    t0_s: Any,
    returns: DetectedReturns,
    surface: WaterSurface,
    system: WaveformSystem,
    settings: PosteriorSettings | None = None,
    refraction_settings: RefractionSettings | None = None,
    *,
    rows: Any = None,
    seed: int = 0,
    detect_settings: DetectSettings | None = None,
    detect_noise: tuple[int | None, float] | None = None,
    progress: bool = False,
    nuisance_depth_sigma_m: Any = None,
    exposure: Any = None,
    theta0: Any = None,
) -> SeabedPosteriors:
    """Sample the depth posterior of pulses and carry it to the refracted seabed point.

    Parameters
    ----------
    samples : (n_pulses, m) array_like, or sequence of n_pulses 1-D arrays
        Waveforms (photon counting: window histograms, of their own lengths), rows aligned
        with ``returns`` and ``surface``.
    t0_s : (n_pulses,) array_like
        Round-trip time of the centre of each waveform's sample 0, seconds.
    returns : DetectedReturns
        Measured navigation (origin, direction), confidences and flags of the pulses.
    surface : WaterSurface
        The fitted water surface of the same pulses.
    system : WaveformSystem
    settings : PosteriorSettings, optional
    refraction_settings : RefractionSettings, optional
        Water indices for :func:`~pipeline.process.refraction.seabed_points`.
    rows : array_like of int, optional
        Pulses to sample (default: all). Cost is linear in their number (see
        ``benchmarks/RESULTS_posterior.md``).
    seed : int
        Batch ``b`` (``settings.batch_size`` pulses side by side) is seeded ``seed + b0``.
    detect_settings, detect_noise : optional
        The survey detector's, for the starts (see :func:`sample_batch`).
    progress : bool
        A progress bar over the batches (stderr): the stage takes minutes on a large budget.
    nuisance_depth_sigma_m : (n_pulses,) array_like, optional
        One-sigma depth change of the terms the waveform does not hold (see the module
        docstring), rows aligned with ``returns``; each draw's depth gets an independent
        Gaussian of it (seeded per batch). Default: none (the waveform posterior alone).
    exposure : like ``samples``, optional
        Live share of each sample (photon counting's dead time, see
        :mod:`pipeline.uncertainty.photon_posterior`); default 1.
    theta0 : (n_pulses, 9) array_like, optional
        Starting estimates (default: the full-waveform detector's, :func:`sample_batch`).

    Returns
    -------
    SeabedPosteriors
    """
    st = settings or PosteriorSettings()
    rst = refraction_settings or RefractionSettings()
    if rst.forward_scatter is not None:
        # the posterior's symmetric echo model centres a skewed echo where a Gaussian fit
        # does, not where the detector does: its own forward-scattering correction
        fs = dataclasses.replace(rst.forward_scatter, estimator="gaussian_fit")
        rst = dataclasses.replace(rst, forward_scatter=fs)
    if isinstance(samples, np.ndarray) and samples.ndim != 2:
        raise ValueError(f"`samples` must be 2-D or a sequence of rows; got {samples.shape}")
    y = [np.asarray(w, dtype=np.float64) for w in samples]
    ex = None if exposure is None else [np.asarray(e, dtype=np.float64) for e in exposure]
    t0 = np.asarray(t0_s, dtype=np.float64)
    n = len(returns)
    if len(y) != n or t0.shape != (n,) or len(surface) != n or (ex is not None and len(ex) != n):
        raise ValueError(
            f"`samples` ({len(y)}), `t0_s` {t0.shape}, `surface` ({len(surface)}) and "
            f"`exposure` must have one row per pulse of `returns` ({n})"
        )
    rows = np.arange(n) if rows is None else np.asarray(rows, dtype=np.int64)
    nuis = np.zeros(n) if nuisance_depth_sigma_m is None else np.asarray(nuisance_depth_sigma_m)
    if nuis.shape != (n,) or not np.all(np.isfinite(nuis) & (nuis >= 0.0)):
        raise ValueError(f"`nuisance_depth_sigma_m` must be ({n},), finite and >= 0")
    cosw = water_cosine(returns.direction_meas, surface.normal, surface.air_index, rst.phase_index)
    m = len(rows)
    keys = ("median", "lo68", "hi68", "lo95", "hi95", "std")
    depth = {k: np.zeros(m) for k in keys}
    xyz_med, xyz_std, sig_h = np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m)
    acc, tau_max = np.zeros(m), np.zeros(m)
    n_steps, flags = np.zeros(m, dtype=np.int64), np.zeros(m, dtype=np.uint16)
    theta_med, wave = np.zeros((m, N_PARAMS)), {k: np.zeros(m) for k in keys}
    bar = tqdm(total=m, unit="pulse", desc="posteriors", disable=not progress, file=sys.stderr)
    for b0 in range(0, m, st.batch_size):
        part = rows[b0 : b0 + st.batch_size]
        rng = np.random.default_rng([seed, b0])  # the nuisance draws, apart from the chains
        chains = sample_batch(
            [y[i] for i in part],
            system,
            st,
            cos_water=cosw[part],
            seed=seed + b0,
            detect_settings=detect_settings,
            detect_noise=detect_noise,
            exposure=None if ex is None else [ex[i] for i in part],
            theta0=None if theta0 is None else np.asarray(theta0)[part],
        )
        for k, r in enumerate(part):
            j = b0 + k
            acc[j], tau_max[j] = chains.acceptance[k], float(np.max(chains.tau_steps[k]))
            n_steps[j], flags[j] = chains.n_steps[k], chains.flags[k]
            theta_med[j] = np.median(chains.draws[k], axis=0)
            if not surface.is_water[r]:
                flags[j] |= np.uint16(PosteriorFlag.NO_START)
        # the batch's draws onto the seabed in one pass of the refraction
        sampled = [k for k in range(len(part)) if not flags[b0 + k] & PosteriorFlag.NO_START]
        on_seabed = draws_to_seabed_rows(
            [chains.draws[k] for k in sampled], part[sampled], t0[part[sampled]], returns,
            surface, system, cosw[part[sampled]], rst,
        )  # fmt: skip
        for k, pts in zip(sampled, on_seabed, strict=True):
            j, r = b0 + k, part[k]
            for key, v in interval_summary(pts.depth_m).items():
                wave[key][j] = v
            # marginalised over the nuisances: every draw moved by its own Gaussian draw
            d = pts.depth_m + nuis[r] * rng.standard_normal(pts.depth_m.shape)
            summ = interval_summary(d)
            for key in keys:
                depth[key][j] = summ[key]
            xyz_med[j] = np.median(pts.xyz_m, axis=0)
            xyz_std[j] = np.std(pts.xyz_m, axis=0, ddof=1)
            sig_h[j] = math.sqrt(0.5 * (xyz_std[j, 0] ** 2 + xyz_std[j, 1] ** 2))
        bar.update(len(part))
    bar.close()
    return SeabedPosteriors(
        pulse_id=returns.pulse_id[rows],
        row=rows,
        depth_m=depth,
        xyz_median_m=xyz_med,
        xyz_std_m=xyz_std,
        sigma_h_m=sig_h,
        acceptance=acc,
        tau_max_steps=tau_max,
        n_steps=n_steps,
        flags=flags,
        theta_median=theta_med,
        cos_water=cosw[rows],
        waveform_depth_m=wave,
    )
