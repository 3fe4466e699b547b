"""Derivatives of the waveform model: Jacobian, score and Fisher information, Cramér–Rao.

The model and its noise laws are :mod:`pipeline.uncertainty.waveform_model`'s; this module
gives what the posterior's start (damped Fisher scoring, the Laplace covariance) and the
Cramér–Rao bound need. Derivatives by central differences in one batched model evaluation.
With the surface echo's shape misfit (``WaveformSystem.surface_misfit``, the model module's
docstring) the variance depends on the parameters through the echo too, and both the score
and the information carry that dependence.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pipeline.errors import NumericalError
from pipeline.uncertainty.waveform_model import (
    N_PARAMS,
    WaveformSystem,
    _as_2d,
    covariance,
    expected_waveform,
    has_misfit,
    log_likelihood,
    noise_variance,
    surface_only,
    th_str,
)

__all__ = ["jacobian", "fisher_information", "score", "depth_crb_m"]

#: Finite-difference step per parameter, in the parameter's own unit (central differences:
#: error ~ h^2 f''' / 6, far below the noise for these smooth functions).
_FD_STEP = np.array([1e-5, 1e-5, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6, 1e-6])


def jacobian(
    theta: Any,
    n_samples: int,
    system: WaveformSystem,
    cos_water: Any = 1.0,
    _surface_only: bool = False,
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
    if _surface_only:
        # the surface echo alone: its derivatives in the zeroed parameters vanish, as they
        # should
        pert = surface_only(pert)
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


def _misfit_terms(theta, n_samples, system, cos_water, mu, jac):
    """Variance ``v`` and its Jacobian ``dv/dtheta`` with the surface echo's shape misfit.

    ``v = F + S max(mu - O, 0) + (e s)^2`` (:func:`noise_variance`), ``s`` the surface echo
    (:func:`surface_echo`), whose derivatives come by the same central differences as
    ``jac`` (:func:`jacobian`). Returns ``(v, jac_v, s)`` shaped like ``mu``, ``jac``, ``mu``.
    """
    s, jac_s = jacobian(theta, n_samples, system, cos_water, _surface_only=True)
    s = s - system.offset_counts
    e2 = system.surface_misfit**2
    slope = np.where(
        mu > system.offset_counts, system.excess_noise_factor * system.counts_per_photoelectron, 0.0
    )
    v = noise_variance(mu, system, s)
    jac_v = slope[..., None] * jac + (2.0 * e2 * s)[..., None] * jac_s
    return v, jac_v, s


def fisher_information(
    theta: Any, n_samples: int, system: WaveformSystem, cos_water: Any = 1.0, valid: Any = None
) -> np.ndarray:
    """Expected Fisher information (9, 9) (or (P, 9, 9)) of waveform(s) at ``theta``.

    Poisson: ``J^T diag(1/mu) J``. Gaussian with a mean-dependent variance ``v(mu)``:
    ``J^T diag(1/v + v'^2 / (2 v^2)) J`` with ``v' = F G`` above the offset. ``valid``
    (n_samples,) or (P, n_samples) masks padded samples.
    """
    mu, jac = jacobian(theta, n_samples, system, cos_water)
    if has_misfit(system):
        v, jac_v, _ = _misfit_terms(theta, n_samples, system, cos_water, mu, jac)
        ok = np.ones(mu.shape, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
        info = _gauss_info(jac, jac_v, v, ok)
    else:
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
    if has_misfit(system):
        v, jac_v, s = _misfit_terms(theta, y.shape[-1], system, cos_water, mu, jac)
        ok = np.ones(mu.shape, dtype=bool) if valid is None else np.asarray(valid, dtype=bool)
        res = y - mu
        # d log N(y; mu, v) = res / v dmu + (res^2 / v^2 - 1 / v) dv / 2
        grad = np.einsum("...mi,...m->...i", jac, np.where(ok, res / v, 0.0))
        grad += np.einsum(
            "...mi,...m->...i", jac_v, np.where(ok, 0.5 * (res * res / (v * v) - 1.0 / v), 0.0)
        )
        info = _gauss_info(jac, jac_v, v, ok)
        ll = log_likelihood(y, mu, system, valid, surface=s)
        return (float(ll) if np.ndim(ll) == 0 else ll), grad, info
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


def _gauss_info(jac, jac_v, v, ok):
    """Fisher information of independent ``N(mu, v)`` samples, ``v`` depending on theta.

    ``J^T diag(1/v) J + J_v^T diag(1 / (2 v^2)) J_v`` over the samples where ``ok``.
    """
    w = np.where(ok, 1.0 / v, 0.0)
    wv = np.where(ok, 0.5 / (v * v), 0.0)
    return np.einsum("...mi,...m,...mj->...ij", jac, w, jac) + np.einsum(
        "...mi,...m,...mj->...ij", jac_v, wv, jac_v
    )


def depth_crb_m(
    theta: Any, n_samples: int, system: WaveformSystem, cos_water: float = 1.0
) -> float:
    """Cramér–Rao bound on the depth's standard deviation, ``sqrt((I^-1)_00)``, metres."""
    info = fisher_information(theta, n_samples, system, cos_water)
    return float(math.sqrt(max(covariance(info)[0, 0], 0.0)))
