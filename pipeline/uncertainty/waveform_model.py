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
``F``). ``"photon_counting"``: Poisson counts of mean ``mu`` (``offset``, ``G``, ``F`` unused).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.config import setting
from pipeline.constants import FWHM_TO_SIGMA
from pipeline.errors import NumericalError, SceneError
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
    "jacobian",
    "fisher_information",
    "score",
    "depth_crb_m",
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
#: Finite-difference step per parameter, in the parameter's own unit (central differences:
#: error ~ h^2 f''' / 6, far below the noise for these smooth functions).
_FD_STEP = np.array([1e-5, 1e-5, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6])


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


def noise_variance(mu: Any, system: WaveformSystem) -> np.ndarray:
    """Variance per sample of the noise law at mean ``mu`` (Poisson: ``mu`` itself)."""
    mu = np.asarray(mu, dtype=np.float64)
    if system.poisson:
        return mu
    shot = system.excess_noise_factor * system.counts_per_photoelectron
    return system.floor_variance + shot * np.maximum(mu - system.offset_counts, 0.0)


def log_likelihood(
    samples: Any, mu: Any, system: WaveformSystem, valid: Any = None, exposure: Any = None
) -> np.ndarray:
    """Log-likelihood of ``samples`` given means ``mu``, summed over the last axis.

    ``samples`` and ``mu`` broadcast together; only samples where ``valid`` (if given) count;
    ``exposure`` (Poisson law only) scales the mean by each sample's live share (see
    :func:`score`). Constants that depend on the data only (``log y!``, ``log 2 pi``) are
    dropped.
    """
    y = np.asarray(samples, dtype=np.float64)
    mu = np.asarray(mu, dtype=np.float64)
    if exposure is not None and system.poisson:
        mu = mu * np.asarray(exposure, dtype=np.float64)
    if system.poisson:
        pos = mu > 0.0
        term = np.where(pos, y * np.log(np.where(pos, mu, 1.0)) - mu, np.where(y > 0, -np.inf, 0))
    else:
        v = noise_variance(mu, system)
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

    Gaussian draws are not rounded: the quantisation step enters as its variance only.
    """
    mu = expected_waveform(theta, n_samples, system, cos_water)
    if system.poisson:
        return rng.poisson(mu).astype(np.float64)
    return mu + np.sqrt(noise_variance(mu, system)) * rng.standard_normal(mu.shape)


def jacobian(
    theta: Any, n_samples: int, system: WaveformSystem, cos_water: Any = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Mean waveform and its derivatives by central differences (one batched evaluation).

    Parameters
    ----------
    theta : (9,) or (P, 9) array_like
    n_samples : int
    system : WaveformSystem
    cos_water : float or (P,) array_like

    Returns
    -------
    mu : (n_samples,) or (P, n_samples) ndarray
    jac : (n_samples, 9) or (P, n_samples, 9) ndarray
        ``d mu / d theta_j``.
    """
    th, single = _as_2d(theta)
    p = th.shape[0]
    h = _FD_STEP * np.maximum(1.0, np.abs(th) * np.array([1, 0.01, 0, 0, 0, 0, 1, 0, 0]))
    eye = np.eye(N_PARAMS)
    pert = np.concatenate(
        [
            th[:, None, :],
            th[:, None, :] + h[:, :, None] * eye,
            th[:, None, :] - h[:, :, None] * eye,
        ],
        axis=1,
    )  # (P, 19, 9)
    cw = np.repeat(np.broadcast_to(np.asarray(cos_water, dtype=np.float64), (p,)), 2 * N_PARAMS + 1)
    mu = expected_waveform(pert.reshape(-1, N_PARAMS), n_samples, system, cw)
    mu = mu.reshape(p, 2 * N_PARAMS + 1, n_samples)
    jac = (mu[:, 1 : 1 + N_PARAMS] - mu[:, 1 + N_PARAMS :]) / (2.0 * h[:, :, None])
    jac = jac.transpose(0, 2, 1)
    return (mu[0, 0], jac[0]) if single else (mu[:, 0], jac)


def _weights(mu, system):
    """Per-sample Fisher weights and the variance slope ``v'`` (Gaussian) of the noise law."""
    if system.poisson:
        return 1.0 / np.maximum(mu, 1e-300), None
    v = noise_variance(mu, system)
    dv = np.where(
        mu > system.offset_counts, system.excess_noise_factor * system.counts_per_photoelectron, 0.0
    )
    return 1.0 / v + 0.5 * (dv / v) ** 2, (v, dv)


def fisher_information(
    theta: Any, n_samples: int, system: WaveformSystem, cos_water: Any = 1.0, valid: Any = None
) -> np.ndarray:
    """Expected Fisher information (9, 9) (or (P, 9, 9)) of waveform(s) at ``theta``.

    Poisson: ``J^T diag(1/mu) J``. Gaussian with a mean-dependent variance ``v(mu)``:
    ``J^T diag(1/v + v'^2 / (2 v^2)) J`` with ``v' = F G`` above the offset. ``valid``
    (n_samples,) or (P, n_samples) masks padded samples.
    """
    mu, jac = jacobian(theta, n_samples, system, cos_water)
    w, _ = _weights(mu, system)
    if valid is not None:
        w = np.where(valid, w, 0.0)
    info = np.einsum("...mi,...m,...mj->...ij", jac, w, jac)
    if not np.all(np.isfinite(info)):
        raise NumericalError(f"Fisher information is not finite at {th_str(np.ravel(theta))}")
    return info


def score(
    samples: Any,
    theta: Any,
    system: WaveformSystem,
    cos_water: Any = 1.0,
    valid: Any = None,
    exposure: Any = None,
) -> tuple[Any, np.ndarray, np.ndarray]:
    """Log-likelihood, its gradient and the Fisher information at ``theta``.

    ``samples`` (m,) with ``theta`` (9,), or (P, m) with (P, 9); ``valid`` masks padding;
    ``exposure`` (like ``samples``, Poisson law only) the live share of each sample: the
    recorded counts are Poisson of ``exposure * mu`` (photon counting's dead time).
    Returns ``(ll, grad, info)``: a float, (9,), (9, 9), or (P,), (P, 9), (P, 9, 9).
    """
    y = np.asarray(samples, dtype=np.float64)
    mu, jac = jacobian(theta, y.shape[-1], system, cos_water)
    if exposure is not None and system.poisson:
        e = np.asarray(exposure, dtype=np.float64)
        mu, jac = mu * e, jac * e[..., None]
    w, gauss = _weights(mu, system)
    if gauss is None:
        dl = y / np.maximum(mu, 1e-300) - 1.0
    else:
        v, dv = gauss
        res = y - mu
        dl = res / v + 0.5 * (res * res / (v * v) - 1.0 / v) * dv
    if valid is not None:
        w, dl = np.where(valid, w, 0.0), np.where(valid, dl, 0.0)
    grad = np.einsum("...mi,...m->...i", jac, dl)
    info = np.einsum("...mi,...m,...mj->...ij", jac, w, jac)
    ll = log_likelihood(y, mu, system, valid)
    return (float(ll) if np.ndim(ll) == 0 else ll), grad, info


def th_str(theta: Any) -> str:
    """Parameters as ``name=value`` pairs, for error messages."""
    th = np.ravel(np.asarray(theta, dtype=np.float64))
    return ", ".join(f"{n}={v:.6g}" for n, v in zip(PARAM_NAMES, th, strict=False))


def depth_crb_m(
    theta: Any, n_samples: int, system: WaveformSystem, cos_water: float = 1.0
) -> float:
    """Cramér–Rao bound on the depth's standard deviation, ``sqrt((I^-1)_00)``, metres."""
    info = fisher_information(theta, n_samples, system, cos_water)
    return float(math.sqrt(max(covariance(info)[0, 0], 0.0)))


def covariance(info: np.ndarray) -> np.ndarray:
    """Inverse of an information matrix (9, 9), pseudo-inverse if singular.

    Scaled to a unit diagonal first: the parameters have very different units.
    """
    d = np.sqrt(np.maximum(np.diag(info), 1e-300))
    scaled = info / np.outer(d, d)
    inv = np.linalg.pinv(scaled, rcond=1e-12, hermitian=True)
    return inv / np.outer(d, d)
