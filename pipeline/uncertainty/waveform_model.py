"""The expected waveform of one pulse from system parameters and measured quantities only.

A process-side forward model for inference (:mod:`pipeline.uncertainty.posterior`): it knows the
instrument (sample clock, system response, noise law, water group index) and the geometry of
the pulse (the in-water angle from the measured beam and the fitted surface), nothing of the
simulated world.

Parameters ``theta`` (:data:`PARAM_NAMES`, last axis of length 9)
-----------------------------------------------------------------
``depth_m``
    Vertical depth of the bottom below the entry point along the refracted ray, metres.
``t_surface_ns``
    Surface-return centre, nanoseconds from the centre of sample 0 (nanoseconds keep every
    parameter of order one for the samplers' fixed-size jitter).
``log_surface_area``, ``log_column_area``, ``log_bottom_area``
    Natural log of each return's total expected counts (area, summed over samples). The
    column is parameterised by its total rather than its height below the surface: a weak
    column constrains its total much better than its shape, which keeps the posterior of
    ``(log area, log k)`` close to a product (no funnel for the sampler).
``log_attenuation_per_m``
    Natural log of the attenuation ``k`` of the water column along the beam (``k`` in 1/m).
``background``
    Background light, counts per sample (photoelectron-equivalent; no digitiser offset).
``log_bottom_width``
    Natural log of the bottom echo's Gaussian sigma over the system response's,
    ``sigma_b = sigma exp(lambda)``. The bottom echo is wider than the system response by
    forward scattering in the water (pulse stretching, growing with depth and turbidity), the
    footprint across a sloping or rough bottom and the beam's spread of incidence, and the
    response itself is known to a few per cent only: the processing knows none of these
    exactly, so the width is a nuisance parameter. A log ratio keeps ``lambda = 0`` (the
    response alone) inside the prior rather than on its edge, where a sampler would pile up.
    The spread is taken symmetric about the centre, which is the depth.
``log_surface_width``
    The same for the surface echo: a beam off nadir meets the water across its footprint
    (a 0.4 m footprint at 20° spreads the echo by ~0.25 ns rms) and waves spread it further.
    The water column's onset keeps the system response (the column is a sum over the path).

Model
-----
Sample ``i`` integrates the signal over ``[(i - 1/2) dt, (i + 1/2) dt)`` (the digitiser and the
simulator convention; the detector's times are ``i dt``). With the system response a Gaussian of
``sigma = FWHM / 2.3548`` and ``Phi`` the standard normal CDF:

* in-water two-way time ``tau = 2 n_g depth / (c cos(theta_w))`` (group speed along a slant
  path of length ``L = depth / cos(theta_w)``), bottom time ``t_b = t_s + tau``;
* surface and bottom: ``A [Phi((hi - t)/sigma_e) - Phi((lo - t)/sigma_e)]`` with each echo's
  own width ``sigma_e``;
* water column: backscatter from path ``l = c x / (2 n_g)`` (``x = t - t_s``) decays as
  ``exp(-2 k l) = exp(-r x)`` with ``r = k c / n_g`` per second, from the surface to the
  bottom, blurred by the system response. Its cumulative counts
  ``C(u) = h / (r dt) [Phi(u/sigma) - psi(u)]``, ``psi(u) = exp(-r u + r^2 sigma^2/2)
  Phi(u/sigma - r sigma)`` (the exponentially modified Gaussian), truncated at the bottom:
  ``C_tau(u) = C(u) - exp(-r tau) C(u - tau)``; the sample is ``C_tau(hi) - C_tau(lo)``, and
  ``h = A_c r dt / (1 - exp(-r tau))`` for a column of total ``A_c`` counts.
  ``psi`` is evaluated as ``exp(-u^2 / (2 sigma^2)) erfcx(a) / 2`` with
  ``a = (r sigma - u/sigma) / sqrt(2)`` where ``a >= 0`` (no overflow: both factors <= 1),
  and by ``erfcx(-x) = 2 exp(x^2) - erfcx(x)`` otherwise (the remaining exponent is
  <= ``-r^2 sigma^2 / 2``). The special functions are evaluated only within 8.5 sigma of each
  return; away from them ``C_tau`` is 0 before the surface, ``1 - exp(-r u + r^2 sigma^2/2)``
  in the water and ``1 - exp(-r tau)`` after the bottom (dropped terms < 1e-16 of the areas);
* mean sample ``mu = offset + background + surface + column + bottom``.

Noise laws (:class:`WaveformSystem` ``receiver``)
--------------------------------------------------
``"full_waveform"``: Gaussian with variance
``sigma_e^2 + q^2/12 + F G (mu - offset)`` (electronic noise, quantisation step ``q``, shot
noise of the photoelectrons with gain ``G`` counts per photoelectron and excess-noise factor
``F``), plus ``(e s)^2`` with ``s`` the surface echo's share of ``mu`` and ``e``
``surface_misfit`` (0 by default). ``"photon_counting"``: Poisson counts of mean ``mu``
(``offset``, ``G``, ``F``, ``e`` unused).

The surface echo's shape misfit
-------------------------------
The model's surface echo is the system response widened by one factor; a real one is not
(the specular glint of the facets under the footprint, the volume backscatter's onset behind
it, and a bright echo clipped flat at the digitiser's top code). Read with only the noise
law's variance, its few samples weigh hundreds of times more than the bottom's, and the
posterior bends the other components to fit the shape: behind a clipped surface the column
turns into a second surface echo (``k`` at its 2 /m bound, the surface at its narrowest,
depths 2-6 cm shallow; ``benchmarks/RESULTS_posterior.md``, "Clipped surface echoes"). A
model-discrepancy variance proportional to the echo (Kennedy & O'Hagan 2001, *J. R. Stat.
Soc. B* 63(3), 425-464) says what the model cannot say: the surface's samples are known to
``e`` of their size. Its derivatives enter the Fisher information and the score
(``J^T diag(1/v) J + J_v^T diag(1/(2 v^2)) J_v``), so the start's Laplace covariance is the
posterior's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.config import setting
from pipeline.constants import FWHM_TO_SIGMA
from pipeline.errors import SceneError
from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.uncertainty.waveform_kernel import expected_rows

__all__ = [
    "PARAM_NAMES",
    "N_PARAMS",
    "WaveformSystem",
    "in_water_delay_s",
    "expected_waveform",
    "noise_variance",
    "log_likelihood",
    "draw_waveform",
    "surface_echo",
    "surface_only",
    "has_misfit",
    "covariance",
]

PARAM_NAMES = (
    "depth_m",
    "t_surface_ns",
    "log_surface_area",
    "log_column_area",
    "log_bottom_area",
    "log_attenuation_per_m",
    "background",
    "log_bottom_width",
    "log_surface_width",
)
N_PARAMS = len(PARAM_NAMES)
_C = SPEED_OF_LIGHT_M_S


@dataclass(frozen=True, kw_only=True)
class WaveformSystem:
    """The instrument as the processing knows it.

    ``sample_interval_s`` and ``pulse_fwhm_s`` are required; the noise law is set by
    ``receiver`` (see the module docstring).
    """

    sample_interval_s: float = setting(gt=0.0, le=1e-6, doc="digitiser / histogram bin width")
    pulse_fwhm_s: float = setting(gt=0.0, le=1e-6, doc="system response FWHM (pulse ⊗ detector)")
    group_index: float = setting(1.3638, ge=1.0, le=2.0, doc="water group index (travel time)")
    receiver: str = setting(
        "full_waveform", choices=("full_waveform", "photon_counting"), doc="noise law"
    )
    offset_counts: float = setting(0.0, doc="digitiser offset with no light (no shot noise)")
    counts_per_photoelectron: float = setting(1.0, gt=0.0, doc="gain G, counts per pe")
    excess_noise_factor: float = setting(1.0, ge=1.0, le=100.0, doc="F of the detector gain")
    electronic_noise_counts: float = setting(0.0, ge=0.0, doc="rms electronic noise per sample")
    quantisation_step_counts: float = setting(
        1.0, ge=0.0, doc="digitiser step; adds step^2/12 to the variance"
    )
    surface_misfit: float = setting(
        0.0,
        ge=0.0,
        le=1.0,
        doc="full waveform: sd of the surface echo's shape misfit, a share of its mean",
    )

    def __post_init__(self) -> None:
        if self.receiver == "full_waveform" and self.floor_variance <= 0.0:
            raise SceneError(
                "`electronic_noise_counts` or `quantisation_step_counts` must be > 0 for a "
                f"full-waveform noise law; got {self.electronic_noise_counts} and "
                f"{self.quantisation_step_counts}."
            )

    @property
    def pulse_sigma_s(self) -> float:
        """Standard deviation of the Gaussian system response, seconds."""
        return self.pulse_fwhm_s * FWHM_TO_SIGMA

    @property
    def floor_variance(self) -> float:
        """Signal-independent variance per sample, counts²: ``sigma_e^2 + q^2 / 12``."""
        return self.electronic_noise_counts**2 + self.quantisation_step_counts**2 / 12.0

    @property
    def poisson(self) -> bool:
        """True for the photon-counting (Poisson) noise law."""
        return self.receiver == "photon_counting"


def in_water_delay_s(depth_m: Any, cos_water: Any, group_index: float) -> np.ndarray:
    """Two-way in-water time ``2 n_g depth / (c cos(theta_w))`` of a bottom at ``depth_m``."""
    return 2.0 * group_index * np.asarray(depth_m) / (_C * np.asarray(cos_water))


def _as_2d(theta: Any) -> tuple[np.ndarray, bool]:
    th = np.asarray(theta, dtype=np.float64)
    if th.shape[-1:] != (N_PARAMS,) or th.ndim > 2:
        raise ValueError(
            f"`theta` must have shape ({N_PARAMS},) or (n, {N_PARAMS}); got {th.shape}"
        )
    return np.atleast_2d(th), th.ndim == 1


def expected_waveform(
    theta: Any, n_samples: int, system: WaveformSystem, cos_water: Any = 1.0
) -> np.ndarray:
    """Mean sample values of the model (compiled: :mod:`~pipeline.uncertainty.waveform_kernel`).

    Parameters
    ----------
    theta : (9,) or (n_walkers, 9) array_like
        Parameters in :data:`PARAM_NAMES` order.
    n_samples : int
        Samples in the window; sample ``i`` is centred at ``i dt``.
    system : WaveformSystem
    cos_water : float or (n_walkers,) array_like
        Cosine of the in-water angle from the vertical, in (0, 1].

    Returns
    -------
    (n_samples,) or (n_walkers, n_samples) ndarray
        Expected counts per sample, offset included.
    """
    th, single = _as_2d(theta)
    cw = np.broadcast_to(np.asarray(cos_water, dtype=np.float64), th.shape[:1])
    mu = expected_rows(
        np.ascontiguousarray(th),
        np.ascontiguousarray(cw),
        int(n_samples),
        system.sample_interval_s,
        system.pulse_sigma_s,
        system.group_index,
        system.offset_counts,
    )
    return mu[0] if single else mu


def noise_variance(mu: Any, system: WaveformSystem, surface: Any = None) -> np.ndarray:
    """Variance per sample of the noise law at mean ``mu`` (Poisson: ``mu`` itself).

    Full waveform: with ``surface`` (the surface echo's share of ``mu``, counts, like ``mu``)
    and ``system.surface_misfit`` > 0, the shape misfit's variance ``(misfit surface)^2`` is
    added.
    """
    mu = np.asarray(mu, dtype=np.float64)
    if system.poisson:
        return mu
    shot = system.excess_noise_factor * system.counts_per_photoelectron
    v = system.floor_variance + shot * np.maximum(mu - system.offset_counts, 0.0)
    if surface is not None and system.surface_misfit > 0.0:
        v = v + (system.surface_misfit * np.asarray(surface, dtype=np.float64)) ** 2
    return v


def surface_only(theta: np.ndarray) -> np.ndarray:
    """A copy of parameter rows ``(..., 9)`` with no column, no bottom and no background.

    Log areas of -745 underflow to 0 in ``exp``: the model of such a row is the surface echo
    on the offset alone (:func:`surface_echo`).
    """
    th = np.array(theta, dtype=np.float64, copy=True)
    th[..., 3] = th[..., 4] = -745.0
    th[..., 6] = 0.0
    return th


def surface_echo(
    theta: Any, n_samples: int, system: WaveformSystem, cos_water: Any = 1.0
) -> np.ndarray:
    """The surface echo's share of the mean samples (counts above the baseline).

    The model with the column and bottom areas and the background at zero, less the offset:
    ``(n_samples,)`` or ``(P, n_samples)``, as :func:`expected_waveform`.
    """
    th, single = _as_2d(theta)
    s = expected_waveform(surface_only(th), n_samples, system, cos_water) - system.offset_counts
    return s[0] if single else s


def log_likelihood(
    samples: Any,
    mu: Any,
    system: WaveformSystem,
    valid: Any = None,
    exposure: Any = None,
    surface: Any = None,
) -> np.ndarray:
    """Log-likelihood of ``samples`` given means ``mu``, summed over the last axis.

    ``samples`` and ``mu`` broadcast together; only samples where ``valid`` (if given) count;
    ``exposure`` (Poisson law only) scales the mean by each sample's live share (see
    :func:`score`); ``surface`` (full waveform) the surface echo's share of ``mu``, for the
    shape misfit's variance (:func:`noise_variance`). Constants that depend on the data only
    (``log y!``, ``log 2 pi``) are dropped.
    """
    y = np.asarray(samples, dtype=np.float64)
    mu = np.asarray(mu, dtype=np.float64)
    if exposure is not None and system.poisson:
        mu = mu * np.asarray(exposure, dtype=np.float64)
    if system.poisson:
        pos = mu > 0.0
        term = np.where(pos, y * np.log(np.where(pos, mu, 1.0)) - mu, np.where(y > 0, -np.inf, 0))
    else:
        v = noise_variance(mu, system, surface)
        term = -0.5 * ((y - mu) ** 2 / v + np.log(v))
    if valid is not None:
        term = np.where(valid, term, 0.0)
    return np.sum(term, axis=-1)


def draw_waveform(
    theta: Any,
    n_samples: int,
    system: WaveformSystem,
    rng: np.random.Generator,
    cos_water: Any = 1.0,
) -> np.ndarray:
    """Noisy samples drawn from the model and its noise law (for tests and calibration).

    Gaussian draws are not rounded: the quantisation step enters as its variance only; the
    surface echo's misfit (``system.surface_misfit``) as independent Gaussian noise per sample.
    """
    mu = expected_waveform(theta, n_samples, system, cos_water)
    if system.poisson:
        return rng.poisson(mu).astype(np.float64)
    surf = surface_echo(theta, n_samples, system, cos_water) if has_misfit(system) else None
    return mu + np.sqrt(noise_variance(mu, system, surf)) * rng.standard_normal(mu.shape)


def has_misfit(system: WaveformSystem) -> bool:
    """True when the full-waveform law carries the surface echo's misfit."""
    return (not system.poisson) and system.surface_misfit > 0.0


def th_str(theta: Any) -> str:
    """Parameters as ``name=value`` pairs, for error messages."""
    th = np.ravel(np.asarray(theta, dtype=np.float64))
    return ", ".join(f"{n}={v:.6g}" for n, v in zip(PARAM_NAMES, th, strict=False))


def covariance(info: np.ndarray) -> np.ndarray:
    """Inverse of an information matrix (9, 9), pseudo-inverse if singular.

    Scaled to a unit diagonal first: the parameters have very different units.
    """
    d = np.sqrt(np.maximum(np.diag(info), 1e-300))
    scaled = info / np.outer(d, d)
    inv = np.linalg.pinv(scaled, rcond=1e-12, hermitian=True)
    return inv / np.outer(d, d)
