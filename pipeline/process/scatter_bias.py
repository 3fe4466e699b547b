"""Forward-scattering range bias of bottom returns, and the correction processing applies.

Why
---
Photons scattered through small angles on the way to the seabed and back stay in the
receiver's field of view but travel farther than the straight refracted ray, so the bottom echo
is skewed late and the detected bottom is deep (Walker & McLean 1999; Tulldahl & Steinvall
1999; Richter et al. 2021, Remote Sensing 13: a Monte Carlo range-bias uncertainty of 4.6 / 7.0
/ 16 cm at 5 / 10 / 20 m in clear coastal water for a VQ-880-G-class system).

What processing assumes (named settings, :class:`ForwardScatterSettings`)
-------------------------------------------------------------------------
* The delay of the echo's photons: the small-angle compound-Poisson model of
  :mod:`pipeline.forward_scatter` (Petzold-fitted Fournier-Forand particles plus sea water),
  for the in-water path ``L``, the field-of-view radius at the seabed ``R = tan(FOV/2) (r_air +
  L n_air / n_w)`` (the slant air range and the slant path carry the nadir angle) and the
  scattering ``b = omega_0 c``. It gives the mixture ``(1 - w) delta + w Exp(tau)`` of the
  two-way excess path.
* The single-scattering albedo ``omega_0``: the user's, else sea water plus matter of albedo
  ``nonwater_albedo`` at the ``c`` assumed (:func:`pipeline.water_optics.albedo_from_nonwater`):
  clear water scatters little, whatever a coastal prior says.
* The beam attenuation ``c``: the user's, else estimated from the survey's measured column decay
  (:func:`pipeline.water_optics.attenuation_from_column`), else ``fallback_attenuation_per_m``;
  which one is recorded in the manifest's ``processing_context``.
* The detector: a matched filter of the system response (Gaussian, sigma ``s``), so the filtered
  echo is the mixture convolved with a Gaussian of sigma ``s sqrt(2)``, timed by a log-parabola
  through its three highest samples (:func:`peak_shift`, averaged over the sample phase), not
  at the mean delay: photons delayed by much more than the pulse widen the tail without moving
  the peak much.

The correction is half the predicted two-way shift, taken off the in-water path before the
seabed point is placed (:func:`pipeline.process.refraction.seabed_points`); ``scale`` (1) is the
knob the TPU's ``forward_scatter`` term turns by ``relative_sigma``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.interpolate import RegularGridInterpolator
from scipy.ndimage import gaussian_filter1d
from scipy.special import erfc, erfcx

from pipeline import water_optics as wo
from pipeline.config import setting
from pipeline.constants import FWHM_TO_SIGMA
from pipeline.forward_scatter import bottom_delay
from pipeline.forward_scatter_mc import water_tables
from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.detect import flank_trend
from pipeline.process.detect_timing import parabolic_peak
from pipeline.table_cache import cached_table, code_key

__all__ = [
    "ForwardScatterSettings",
    "ScatterBiasModel",
    "peak_shift",
    "range_bias_m",
    "bias_model",
]

_C = SPEED_OF_LIGHT_M_S
_W_GRID = np.linspace(0.0, 1.0, 81)
_LOG_TAU = np.linspace(-3.0, 2.0, 201)  # log10(tau / sigma) of the table
_X = np.linspace(0.0, 4.0, 4001)  # candidate peak offsets (sigma units)


@dataclass(frozen=True, kw_only=True)
class ForwardScatterSettings:
    """What processing assumes about the forward-scattering delay of bottom echoes."""

    model: str = setting(
        "small_angle",
        choices=("small_angle", "none"),
        doc="bottom-echo delay processing corrects (small_angle: pipeline.forward_scatter)",
    )
    beam_attenuation_per_m: float | None = setting(
        None,
        gt=0.0,
        le=100.0,
        doc="beam attenuation c assumed (None: from the measured column decay, else fallback)",
    )
    fallback_attenuation_per_m: float = setting(
        0.15, gt=0.0, le=100.0, doc="c assumed when no column decay was measured"
    )
    single_scattering_albedo: float | None = setting(
        None,
        gt=0.0,
        le=1.0,
        doc="b / c assumed (None: sea water plus matter of nonwater_albedo at the c assumed, "
        "pipeline.water_optics.albedo_from_nonwater)",
    )
    nonwater_albedo: float = setting(
        0.618,
        ge=0.0,
        le=1.0,
        doc="b / c assumed of what is not sea water, when single_scattering_albedo is None: "
        "Petzold's coastal water (his three waters: 0.335, 0.618, 0.850)",
    )
    receiver_fov_mrad: float | None = setting(
        None, gt=0.0, le=1000.0, doc="receiver full field of view (None: scanner.receiver_fov_mrad)"
    )
    # 0.5 is a prior for the model's error in real water, not a figure fitted on simulated
    # scenes: the simulator and this correction share one forward-scattering model and phase
    # function (pipeline/forward_scatter.py, forward_scatter_mc.py), so a simulated scene cannot
    # measure how wrong that model is, and published Monte Carlo range biases differ from ours
    # by ~2x (benchmarks/RESULTS_realism.md). Suite scenes differ from the assumption only by
    # their albedo (drawn over Petzold's three waters, pipeline/suite/generate.py: ~0.3
    # relative in the scattering) and the attenuation estimate. Keep 0.5 until a measurement
    # independent of our own model exists.
    relative_sigma: float = setting(
        0.5,
        ge=0.0,
        le=10.0,
        doc="one-sigma relative error of the correction (TPU term); a prior for the model's "
        "error in real water (~2x between published models), not fitted on simulated scenes, "
        "which share the model",
    )


@dataclass(frozen=True)
class ScatterBiasModel:
    """The resolved correction (JSON-ready: the manifest records it).

    Attributes
    ----------
    beam_attenuation_per_m, single_scattering_albedo : float
        ``c`` and ``omega_0`` assumed.
    fov_half_tan : float
        ``tan`` of half the receiver's field of view.
    system_sigma_s : float
        Sigma of the system response (the detector's matched filter).
    sample_interval_s : float
        The digitiser's (the detector times on its samples); 0: a continuous peak.
    trend_fwhm : float
        The detector's flank-trend length in system FWHMs (``process.detect.trend_fwhm``).
    wavelength_nm : float
        For the sea-water part of the scattering.
    relative_sigma : float
        One-sigma relative error of the correction (the TPU's ``forward_scatter`` term).
    nonwater_albedo : float or None
        The albedo of the matter beside sea water when ``omega_0`` follows ``c``
        (:func:`pipeline.water_optics.albedo_from_nonwater`, :meth:`at_attenuation`); None: a
        fixed ``omega_0`` (the user's).
    scale : float
        Multiplies the correction (1; the TPU perturbs it).
    estimator : str
        Whose bottom time is corrected: ``"detector"`` (points) or ``"gaussian_fit"`` (the
        depth posteriors' symmetric echo model, :mod:`pipeline.uncertainty.seabed_posterior`).
    """

    beam_attenuation_per_m: float
    single_scattering_albedo: float
    fov_half_tan: float
    system_sigma_s: float
    sample_interval_s: float
    trend_fwhm: float
    wavelength_nm: float
    relative_sigma: float = 0.5
    scale: float = 1.0
    estimator: str = "detector"
    nonwater_albedo: float | None = None

    def at_attenuation(self, beam_attenuation_per_m: float) -> ScatterBiasModel:
        """The model at another ``c`` (a measured one), ``omega_0`` following it if it does."""
        c = float(beam_attenuation_per_m)
        albedo = self.single_scattering_albedo
        if self.nonwater_albedo is not None:
            albedo = wo.albedo_from_nonwater(c, self.nonwater_albedo, self.wavelength_nm)
        return dataclasses.replace(
            self, beam_attenuation_per_m=c, single_scattering_albedo=float(albedo)
        )

    def detector(self) -> DetectorTiming | None:
        """The detector's timing in sigma units (None without samples), as detect.py sets it."""
        if self.sample_interval_s <= 0.0:
            return None
        fwhm_samples = self.system_sigma_s / FWHM_TO_SIGMA / self.sample_interval_s
        return DetectorTiming(
            step=round(self.sample_interval_s / self.system_sigma_s, 6),
            gap=max(2, math.ceil(1.5 * fwhm_samples)),
            length=max(3, round(0.5 * self.trend_fwhm * fwhm_samples)),
        )

    def scattering_per_m(self) -> tuple[float, float]:
        """``(b_particles, b_water)`` with ``b = omega_0 c``."""
        b = self.single_scattering_albedo * self.beam_attenuation_per_m
        b_w = min(wo.seawater_scattering_per_m(self.wavelength_nm), b)
        return b - b_w, b_w


def _filtered_mixture(w, tau, x):
    """Mixture ``(1-w) N(0,1) + w (N(0,1) ⊗ Exp(tau))`` at ``x`` (broadcast), sigma = 1."""
    gauss = np.exp(-0.5 * x * x) / math.sqrt(2.0 * math.pi)
    z = (1.0 / tau - x) / math.sqrt(2.0)
    # exponentially modified Gaussian; erfcx keeps it finite for small tau (z >> 0)
    stable = 0.5 / tau * erfcx(np.maximum(z, 0.0)) * np.exp(-0.5 * x * x)
    direct = 0.5 / tau * np.exp(np.minimum(0.5 / tau**2 - x / tau, 700.0)) * erfc(z)
    emg = np.where(z >= 0.0, stable, direct)
    return (1.0 - w) * gauss + w * emg


#: sample phases the detector's estimate is averaged over
_PHASES = (np.arange(16) + 0.5) / 16.0


@dataclass(frozen=True)
class DetectorTiming:
    """How the full-waveform detector times a bottom (:mod:`pipeline.process.detect`).

    ``step`` is the sample interval over the system response's sigma; ``gap`` and ``length``
    (samples) are the flank trend's (:func:`pipeline.process.detect.flank_trend`), subtracted
    before the peak is timed by a log-parabola (:func:`pipeline.process.detect_timing.
    parabolic_peak`).
    """

    step: float
    gap: int
    length: int


def _continuous_peak(f):
    """Peak offsets of the rows of ``f`` on the grid ``_X`` (argmax + parabola)."""
    j = np.clip(np.argmax(f, axis=-1), 1, _X.size - 2)
    fm, f0, fp = (np.take_along_axis(f, (j + d)[..., None], axis=-1)[..., 0] for d in (-1, 0, 1))
    den = fm - 2.0 * f0 + fp
    off = np.where(den < 0.0, 0.5 * (fm - fp) / np.where(den < 0.0, den, -1.0), 0.0)
    return _X[j] + off * (_X[1] - _X[0])


def _detected_peak(w, tau, det: DetectorTiming):
    """Mean over sample phases of the detector's time of a mixture echo (sigma units).

    The echo (the mixture through the system response, sigma 1) is sampled ``det.step``
    apart, filtered with the matched Gaussian, its flank trend subtracted, and its peak timed
    by the log-parabola, as the detector does; on a skewed echo the result depends on where
    the samples fall, so it is averaged over 16 phases.
    """
    margin = det.gap + det.length + 2
    k = np.arange(-margin - math.ceil(8.0 / det.step), margin + math.ceil(10.0 / det.step) + 1)
    x = (k[None, :] + _PHASES[:, None]) * det.step  # (phase, sample)
    y = _filtered_mixture(w[:, None, None], tau[:, None, None], x[None, :, :])
    y = y.reshape(-1, k.size)
    filt = gaussian_filter1d(y, 1.0 / det.step, axis=1, mode="nearest")
    resid = filt - flank_trend(filt, gap=det.gap, length=det.length)
    # the echo's own peak: within a few sigma of the undelayed time
    near = (x[None, :, :] > -3.0) & (x[None, :, :] < 8.0)
    near = np.broadcast_to(near, (w.size, *x.shape)).reshape(-1, k.size)
    i = np.argmax(np.where(near, resid, -np.inf), axis=1)
    t_idx, _, _ = parabolic_peak(resid, i)
    x0 = np.broadcast_to(x[None, :, 0], (w.size, _PHASES.size)).reshape(-1)
    est = x0 + t_idx * det.step
    return est.reshape(w.size, _PHASES.size).mean(axis=1)


def _fitted_centre(w, tau, det: DetectorTiming, iterations: int = 40):
    """Mean over sample phases of the centre of a free-width Gaussian fitted to the echo.

    What the depth posteriors' symmetric echo model (:mod:`pipeline.uncertainty.waveform_model`)
    makes of a skewed echo: weighted least squares, weights ``1 / (y + 1e-3 max y)`` (the
    shot-noise law of a bright echo), Levenberg-Marquardt from the highest sample.
    """
    k = np.arange(-math.ceil(8.0 / det.step), math.ceil(12.0 / det.step) + 1)
    x = ((k[None, :] + _PHASES[:, None]) * det.step)[None, :, :]
    y = _filtered_mixture(w[:, None, None], tau[:, None, None], x).reshape(-1, k.size)
    x = np.broadcast_to(x, (w.size, *x.shape[1:])).reshape(-1, k.size)
    wt = 1.0 / (y + 1e-3 * y.max(axis=1, keepdims=True))
    i = np.argmax(y, axis=1)
    p = np.stack([y[np.arange(y.shape[0]), i], x[np.arange(y.shape[0]), i], np.ones(len(y))], 1)
    lam = np.full(len(y), 1e-3)

    def cost(q):
        e = np.exp(-0.5 * ((x - q[:, 1:2]) / q[:, 2:3]) ** 2)
        return e, np.sum(wt * (q[:, :1] * e - y) ** 2, axis=1)

    e, c0 = cost(p)
    for _ in range(iterations):
        u = (x - p[:, 1:2]) / p[:, 2:3]
        jac = np.stack([e, p[:, :1] * e * u / p[:, 2:3], p[:, :1] * e * u * u / p[:, 2:3]], 2)
        r = p[:, :1] * e - y
        jtj = np.einsum("nki,nk,nkj->nij", jac, wt, jac)
        jtr = np.einsum("nki,nk,nk->ni", jac, wt, r)
        damp = jtj + lam[:, None, None] * np.eye(3) * np.diagonal(jtj, axis1=1, axis2=2)[:, None]
        q = p - np.linalg.solve(damp, jtr[..., None])[..., 0]
        q[:, 2] = np.abs(q[:, 2])
        e_q, c_q = cost(q)
        better = c_q < c0
        p = np.where(better[:, None], q, p)
        e = np.where(better[:, None], e_q, e)
        c0 = np.where(better, c_q, c0)
        lam = np.where(better, lam * 0.3, lam * 10.0)
    return p[:, 1].reshape(w.size, _PHASES.size).mean(axis=1)


#: What the peak-shift tables are computed by: every processing module (hashed at import; an
#: edit anywhere in processing recomputes them, ~1 s, rather than risk a stale table).
_SOURCE_KEY = code_key([Path(__file__).parent])


@lru_cache(maxsize=8)
def _shift_table(
    det: DetectorTiming | None, estimator: str = "detector"
) -> RegularGridInterpolator:
    """Peak offset (sigma units) of the mixture echo on the ``(w, log10 tau)`` grid.

    ``det`` None: the continuous peak of the matched filter's output (sigma sqrt 2). A
    constant of the code and ``det``: kept on disk once computed (:mod:`pipeline.table_cache`).
    """
    coarse = det is not None and estimator == "gaussian_fit"
    # the Gaussian fits are smooth in both; a coarser grid keeps them to ~1 s
    w_grid, log_tau = (_W_GRID[::4], _LOG_TAU[::4]) if coarse else (_W_GRID, _LOG_TAU)
    table = cached_table(
        "peak_shift",
        f"{det!r} {estimator}",
        _SOURCE_KEY,
        lambda: _shift_values(det, estimator, w_grid, log_tau),
        (w_grid.size, log_tau.size),
    )
    return RegularGridInterpolator((w_grid, log_tau), table)


def _shift_values(det, estimator, w_grid, log_tau) -> np.ndarray:
    """:func:`_shift_table`'s values, ``(w_grid.size, log_tau.size)``."""
    tau = 10.0**log_tau
    if det is None:
        table = np.empty((w_grid.size, log_tau.size))
        for i, w in enumerate(w_grid):
            f = _filtered_mixture(w, math.sqrt(0.5) * tau[:, None], _X[None, :])
            table[i] = math.sqrt(2.0) * _continuous_peak(f)
        return table
    ww, tt = np.meshgrid(w_grid, tau, indexing="ij")
    peak = _fitted_centre if estimator == "gaussian_fit" else _detected_peak
    return peak(ww.ravel(), tt.ravel(), det).reshape(ww.shape)


def peak_shift(
    weight, tail_mean, sigma, detector: DetectorTiming | None = None, estimator="detector"
):
    """Where a matched-filter detector times an echo delayed by the mixture (see module).

    Parameters
    ----------
    weight, tail_mean : ndarray
        ``w`` and ``tau`` of the delay mixture (``tau`` in the units of ``sigma``).
    sigma : float
        Sigma of the system response (> 0); the matched filter's output has ``sigma sqrt 2``.
    detector : DetectorTiming, optional
        The sampled detector's timing (sample phase averaged); None: the continuous peak of
        the filter's output.
    estimator : str
        ``"detector"`` (the detector's time) or ``"gaussian_fit"`` (the centre of a symmetric
        Gaussian fitted to the sampled echo, as the depth posteriors' model; needs ``detector``).

    Returns
    -------
    ndarray
        The detected time's offset from the undelayed echo's, same units, broadcast shape.
    """
    w = np.clip(np.asarray(weight, dtype=np.float64), 0.0, 1.0)
    rel = np.asarray(tail_mean, dtype=np.float64) / sigma
    w, rel = np.broadcast_arrays(w, rel)
    has = (w > 0.0) & (rel > 0.0)
    lr = np.log10(np.where(has, rel, 1.0))
    # below the table a short tail moves the peak by its mean (w tau); above it the tail is
    # flat over the pulse and the table's last column holds
    small = lr < _LOG_TAU[0]
    pts = np.stack([w.ravel(), np.clip(lr, _LOG_TAU[0], _LOG_TAU[-1]).ravel()], axis=1)
    est = estimator if detector is not None else "detector"
    tab = _shift_table(detector, est)(pts).reshape(w.shape) if w.size else np.zeros(w.shape)
    out = np.where(small, w * rel, tab) * sigma
    return np.where(has, out, 0.0)


def range_bias_m(
    model: ScatterBiasModel | None, length_m, r_air_m, air_index, phase_index, group_index
):
    """One-way range bias (m, along the in-water path) the detected bottom carries.

    Parameters
    ----------
    model : ScatterBiasModel or None
        None: no correction (zeros).
    length_m, r_air_m : ndarray
        In-water path and slant air range to the water entry, shapes alike ``(n,)``.
    air_index, phase_index, group_index : float
        Indices the refraction uses.

    Returns
    -------
    ndarray
        ``(n,)``, >= 0; 0 where ``length_m <= 0``.
    """
    length = np.asarray(length_m, dtype=np.float64)
    if model is None or length.size == 0:
        return np.zeros(length.shape)
    ok = length > 0.0
    path = np.where(ok, length, 0.0)
    radius = model.fov_half_tan * (np.asarray(r_air_m) + path * air_index / phase_index)
    absorption = (1.0 - model.single_scattering_albedo) * model.beam_attenuation_per_m
    delay = bottom_delay(
        path, np.maximum(radius, 0.0), model.scattering_per_m(), water_tables(), absorption
    )
    # the system response in two-way path units (a delay dt is an excess path dt c / n_g)
    sig_path = model.system_sigma_s * _C / group_index
    two_way = peak_shift(
        delay.tail_weight, delay.tail_mean_m, sig_path, model.detector(), model.estimator
    )
    return np.where(ok, model.scale * 0.5 * two_way, 0.0)


def bias_model(
    settings: ForwardScatterSettings,
    *,
    fov_mrad: float,
    system_fwhm_s: float,
    sample_interval_s: float,
    trend_fwhm: float,
    wavelength_nm: float,
    attenuation_per_m: float,
) -> ScatterBiasModel | None:
    """The correction for resolved assumptions (None when ``model = "none"``)."""
    if settings.model == "none":
        return None
    follows = settings.single_scattering_albedo is None
    nonwater = float(settings.nonwater_albedo) if follows else None
    return ScatterBiasModel(
        beam_attenuation_per_m=float(attenuation_per_m),
        single_scattering_albedo=float(
            wo.albedo_from_nonwater(attenuation_per_m, nonwater, wavelength_nm)
            if follows
            else settings.single_scattering_albedo
        ),
        nonwater_albedo=nonwater,
        fov_half_tan=math.tan(0.5e-3 * fov_mrad),
        system_sigma_s=float(system_fwhm_s * FWHM_TO_SIGMA),
        sample_interval_s=float(sample_interval_s),
        trend_fwhm=float(trend_fwhm),
        wavelength_nm=float(wavelength_nm),
        relative_sigma=float(settings.relative_sigma),
    )
