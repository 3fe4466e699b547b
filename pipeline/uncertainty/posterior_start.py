"""Starting points of the depth posterior's sampler: detector starts, modes, walker balls.

1. Start: the detector's estimate (:func:`pipeline.process.detect.detect_full_waveform`):
   surface and bottom times and amplitudes, the background from the leading samples (a depth
   scan where the detector found the surface but no bottom, flagged START_SCANNED); batched
   damped Fisher scoring then moves every pulse to its posterior mode (from the detector's
   start and from a depth scan; the higher posterior wins).
2. Walkers: the mode plus a small ball of the Laplace covariance (inverse Fisher information
   with the prior widths) times ``init_scale``, redrawn where outside the prior.
"""

from __future__ import annotations

import math
from typing import Any

import numba
import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.detect import DetectSettings, detect_full_waveform
from pipeline.uncertainty.posterior_target import (
    PulseBatch,
    _prior_precision,
    _prior_score,
    log_prob,
    log_prob_blocks,
)
from pipeline.uncertainty.waveform_information import (
    score,
)
from pipeline.uncertainty.waveform_kernel import echo_rows
from pipeline.uncertainty.waveform_model import (
    N_PARAMS,
    WaveformSystem,
    covariance,
    expected_waveform,
)

__all__ = ["start_theta", "posterior_modes"]


_C = SPEED_OF_LIGHT_M_S


def start_theta(
    samples: Any,
    system: WaveformSystem,
    cos_water: float = 1.0,
    detect_settings: DetectSettings | None = None,
) -> np.ndarray | None:
    """The detector's estimate as a parameter vector; None without a surface detection.

    Surface and bottom times from :func:`~pipeline.process.detect.detect_full_waveform`,
    areas from its matched-filter peaks (a Gaussian of area ``A`` and ``s`` samples filtered by
    the unit-sum Gaussian of the same width peaks at ``A / (2 sqrt(pi) s)``), background from
    the leading samples, column area from the samples between the returns, ``k = 0.1``.
    Where the detector found the surface but no bottom, the depth comes from a scan
    (:func:`_scan_start`).
    """
    return _start(samples, system, cos_water, detect_settings)[0]


def _start(samples, system, cos_water, detect_settings=None, detect_noise=None, exposure=None):
    """``(theta or None, scanned)``: see :func:`start_theta`.

    ``detect_noise``: ``(noise_samples, shot_noise_counts)`` of the survey's own detector run
    (leading samples that are noise only, and the shot-noise counts per photoelectron).
    ``exposure``: live share per sample (photon counting): the start reads the live-time
    corrected counts ``samples / exposure`` (the rate), the scan fits the recorded ones.
    """
    y = np.asarray(samples, dtype=np.float64)
    ex = None if exposure is None or not system.poisson else np.asarray(exposure, np.float64)
    if ex is not None:
        y = y / ex
    n_noise, shot = detect_noise if detect_noise is not None else (None, 0.0)
    det = detect_full_waveform(
        y[None, :],
        system.sample_interval_s,
        system.pulse_fwhm_s,
        detect_settings,
        noise_samples=n_noise,
        shot_noise_counts=shot,
    )
    if not det.has_surface[0]:
        return None, False
    dt = system.sample_interval_s
    k_lead = max(4, int((detect_settings or DetectSettings()).noise_fraction * y.size))
    base = float(np.median(y[:k_lead]))
    bg = max(base - (0.0 if system.poisson else system.offset_counts), 1e-3)
    ts = float(det.t_surface_s[0])
    if not det.has_bottom[0]:
        y0 = y if ex is None else y * ex
        th = _scan_start(y0, system, cos_water, ts, bg, ex)
        return th, th is not None
    tb = float(det.t_bottom_s[0])
    to_area = 2.0 * math.sqrt(math.pi) * system.pulse_sigma_s / dt
    a_s = max(float(det.surface_amplitude[0]) * to_area, 1e-2)
    a_b = max(float(det.bottom_amplitude[0]) * to_area, 1e-2)
    i0 = int(math.ceil((ts + 3 * system.pulse_sigma_s) / dt))
    i1 = int(math.floor((tb - 3 * system.pulse_sigma_s) / dt))
    col = float(np.median(y[i0:i1]) - base) * (tb - ts) / dt if i1 > i0 else 0.0
    depth = (tb - ts) * cos_water * _C / (2.0 * system.group_index)
    th = [
        depth,
        ts * 1e9,
        math.log(a_s),
        math.log(max(col, 1e-2)),
        math.log(a_b),
        math.log(0.1),
        bg,
        0.0,
        0.0,
    ]
    return np.array(th), False


def _scan_start(y, system, cos_water, ts, bg, exposure=None):
    """Depth by a scan when the detector missed the bottom (None if nothing fits).

    For every candidate in-water delay on a half-sample grid, the four amplitudes (background,
    surface, column with ``k = 0.1``, bottom) are the linear least-squares fit of the waveform;
    the candidate with the smallest residual and a positive bottom area wins. ``exposure``
    (photon counting, per sample) scales the basis as the likelihood scales the mean.
    """
    dt, s = system.sample_interval_s, system.pulse_sigma_s
    m = y.size
    taus = np.arange(3.0 * s, (m - 1) * dt - ts, 0.5 * dt)
    if taus.size == 0:
        return None
    depths = taus * cos_water * _C / (2.0 * system.group_index)
    off = -700.0  # log area of an absent return
    # (K, m, 4): background, surface, column, bottom, each of unit area
    a = np.empty((taus.size, m, 4))
    a[:, :, 0] = 1.0
    for col, j in ((1, 2), (2, 3), (3, 4)):
        # the surface alone is the same at every depth: one row, broadcast (the absent
        # column and bottom it carries at exp(-700) differ by ~1e-305 between depths, below
        # any sum's last bit: the scan's sums, and so its start, are unchanged)
        rows = 1 if j == 2 else taus.size
        th = np.tile([0.0, ts * 1e9, off, off, off, math.log(0.1), 0.0, 0.0, 0.0], (rows, 1))
        th[:, 0], th[:, j] = depths[:rows], 0.0
        if j == 4:  # the bottom's basis: its column's exp(-700) area left out (echo_rows)
            mu = echo_rows(th, float(cos_water), m, dt, s, system.group_index, system.offset_counts)
        else:
            mu = expected_waveform(th, m, system, cos_water)
        a[:, :, col] = mu - system.offset_counts
    if exposure is not None and system.poisson:
        a *= np.asarray(exposure, dtype=np.float64)[None, :, None]
    rhs = y - system.offset_counts
    gram, proj = _scan_sums(a, rhs)
    ata = gram + 1e-9 * np.eye(4)
    coef = np.linalg.solve(ata, proj[:, :, None])[:, :, 0]
    resid = np.sum((np.einsum("kmi,ki->km", a, coef) - rhs) ** 2, axis=1)
    resid = np.where(coef[:, 3] > 0.0, resid, np.inf)
    if not np.isfinite(resid).any():
        return None
    b = int(np.argmin(resid))
    bgk, a_s, a_c, a_b = coef[b]
    return np.array(
        [
            depths[b],
            ts * 1e9,
            math.log(max(a_s, 1e-2)),
            math.log(max(a_c, 1e-2)),
            math.log(max(a_b, 1e-2)),
            math.log(0.1),
            max(bgk, bg * 1e-3, 1e-3),
            0.0,
            0.0,
        ]
    )


@numba.njit(cache=True, nogil=True)
def _normal_sums(a, rhs):
    """``einsum("kmi,kmj->kij", a, a)`` and ``einsum("kmi,m->ki", a, rhs)`` of ``a`` (K, m, n).

    The same sums as numpy's: each over the samples in order from 0 (einsum's strided loop on
    this layout; ``tests/uncertainty/test_posterior_start.py`` checks it bit for bit), without
    its per-element dispatch (the scan's einsums were most of a long waveform's start).
    """
    n_k, m, n = a.shape
    gram = np.zeros((n_k, n, n))
    proj = np.zeros((n_k, n))
    for k in range(n_k):
        for t in range(m):
            for i in range(n):
                ai = a[k, t, i]
                proj[k, i] += ai * rhs[t]
                for j in range(i, n):
                    gram[k, i, j] += ai * a[k, t, j]
        for i in range(n):
            for j in range(i):
                gram[k, i, j] = gram[k, j, i]  # a_i a_j = a_j a_i exactly
    return gram, proj


@numba.njit(cache=True, nogil=True)
def _scan_sums(a, rhs):
    """:func:`_normal_sums` of the scan's ``a`` (K, m, 4): its columns 0 and 1 shared by all K.

    Columns 0 and 1 (background and surface) are the same for every candidate ``k``: the
    sums among them and with the right-hand side are computed once, for ``k = 0``, and copied
    (the same products in the same order give the same bits). Only the column's and the
    bottom's entries are summed per candidate (7 of the 10 distinct Gram entries, 2 of 4
    projections).
    """
    n_k, m, n = a.shape
    gram = np.zeros((n_k, n, n))
    proj = np.zeros((n_k, n))
    if n_k == 0:
        return gram, proj
    g0, p0 = _normal_sums(a[:1], rhs)
    gram[0], proj[0] = g0[0], p0[0]
    for k in range(1, n_k):
        for i in range(2):
            proj[k, i] = p0[0, i]
            for j in range(2):
                gram[k, i, j] = g0[0, i, j]
        for t in range(m):
            for i in range(2, n):
                ai = a[k, t, i]
                proj[k, i] += ai * rhs[t]
                for j in range(i, n):
                    gram[k, i, j] += ai * a[k, t, j]
            for i in range(2):
                ai = a[k, t, i]
                for j in range(2, n):
                    gram[k, i, j] += ai * a[k, t, j]
        for i in range(n):
            for j in range(i):
                gram[k, i, j] = gram[k, j, i]
    return gram, proj


def _project(th: np.ndarray, data: PulseBatch, i: int, group_index: float) -> np.ndarray:
    """Clip into pulse ``i``'s prior box (with a margin); pull the bottom inside the window."""
    lo, hi = data.lower[i], data.upper[i]
    span = hi - lo
    out = np.clip(th, lo + 1e-12 * span, hi - 1e-12 * span)
    tau_max = data.t_last_s[i] - out[1] * 1e-9
    d_max = tau_max * _C * data.cos_water[i] / (2.0 * group_index)
    out[0] = min(out[0], (1.0 - 1e-6) * d_max)
    return out


def _project_all(th: np.ndarray, data: PulseBatch, group_index: float) -> np.ndarray:
    """:func:`_project` of every pulse's row of ``th`` (P, 9) at once.

    The same operations elementwise (``min`` as ``np.where``, its NaN rule too): the same values.
    """
    span = data.upper - data.lower
    out = np.clip(th, data.lower + 1e-12 * span, data.upper - 1e-12 * span)
    tau_max = data.t_last_s - out[:, 1] * 1e-9
    d_max = tau_max * _C * data.cos_water / (2.0 * group_index)
    out[:, 0] = np.where((1.0 - 1e-6) * d_max < out[:, 0], (1.0 - 1e-6) * d_max, out[:, 0])
    return out


def posterior_modes(
    data: PulseBatch, system: WaveformSystem, theta0: Any, iterations: int = 40
) -> tuple[np.ndarray, np.ndarray]:
    """Damped Fisher scoring (Levenberg–Marquardt) from ``theta0`` to every pulse's mode.

    All pulses step together (one batched model evaluation per iteration), each with its own
    damping; a step is kept only if it raises that pulse's log posterior.

    Parameters
    ----------
    data : PulseBatch
    system : WaveformSystem
    theta0 : (P, 9) array_like
        Starting points.
    iterations : int

    Returns
    -------
    theta : (P, 9) ndarray
        The modes (inside the prior boxes).
    info : (P, 9, 9) ndarray
        Fisher information there.
    """
    p = len(data)
    th = _project_all(np.asarray(theta0, dtype=np.float64), data, system.group_index)
    res = score(data.samples, th, system, data.cos_water, data.valid, data.exposure)
    _, grad, info = _prior_score(res, th, data)
    lp = log_prob_blocks(th.reshape(1, -1), data, system)[0, 1:]
    lam = np.full(p, 1e-3)
    active = np.ones(p, dtype=bool)
    eye = np.eye(N_PARAMS)
    for _ in range(iterations):
        d = np.sqrt(np.maximum(np.diagonal(info, axis1=1, axis2=2), 1e-300))
        a = info / (d[:, :, None] * d[:, None, :]) + lam[:, None, None] * eye
        step = np.linalg.solve(a, (grad / d)[:, :, None])[:, :, 0] / d
        trial = _project_all(th + step, data, system.group_index)
        lp_t = log_prob_blocks(trial.reshape(1, -1), data, system)[0, 1:]
        better = active & (lp_t > lp)
        if better.any():
            gain = np.where(better, lp_t, 0.0) - np.where(better, lp, 0.0)
            th[better] = trial[better]
            sub = (data.samples[better], th[better], system, data.cos_water[better])
            _, grad_n, info_n = score(*sub, data.valid[better], data.exposure[better])
            _, grad_n, info_n = _prior_score((None, grad_n, info_n), th[better], data, better)
            lp[better], grad[better], info[better] = lp_t[better], grad_n, info_n
            active &= ~(better & (gain < 1e-6))
        lam = np.where(better, np.maximum(lam * 0.3, 1e-6), lam * 10.0)
        active &= lam <= 1e8
        if not active.any():
            break
    return th, info


def _best_modes(data: PulseBatch, system: WaveformSystem, starts: np.ndarray):
    """Modes from the detector's starts and from a depth scan; the higher posterior wins.

    A wide or weak bottom can pull the detector's bottom onto a column bump, and Fisher
    scoring only climbs the nearest hill: the scan (:func:`_scan_start`, every depth on a
    half-sample grid with linear amplitudes) supplies a start on the global one. Pulses whose
    detector start already came from a scan are scanned once.
    """
    modes, infos = posterior_modes(data, system, starts)
    alt = starts.copy()
    for i in range(len(data)):
        one = data.pulse(i)
        y = one.samples[0][one.valid[0]]
        ex = one.exposure[0][one.valid[0]]
        th = _scan_start(y, system, float(one.cos_water[0]), starts[i, 1] * 1e-9, starts[i, 6], ex)
        if th is not None:
            alt[i] = th
    modes_b, infos_b = posterior_modes(data, system, alt)
    lp_a = log_prob_blocks(modes.reshape(1, -1), data, system)[0, 1:]
    lp_b = log_prob_blocks(modes_b.reshape(1, -1), data, system)[0, 1:]
    better = lp_b > lp_a + 1e-9
    modes[better], infos[better] = modes_b[better], infos_b[better]
    return modes, infos


def _initial_ball(
    data: PulseBatch, i: int, system, mode, info, n_walkers: int, scale: float, rng
) -> np.ndarray:
    """``n_walkers`` points around ``mode`` from the Laplace covariance, inside the prior."""
    one = data.pulse(i)
    cov = covariance(info + _prior_precision(one, 0))
    chol = np.linalg.cholesky(cov + np.diag(1e-12 * np.diag(cov) + 1e-300))
    p0 = np.empty((n_walkers, N_PARAMS))
    filled = 0
    for _ in range(100):
        cand = mode + scale * rng.standard_normal((n_walkers, N_PARAMS)) @ chol.T
        good = cand[np.isfinite(log_prob(cand, one, system))]
        take = min(len(good), n_walkers - filled)
        p0[filled : filled + take] = good[:take]
        filled += take
        if filled == n_walkers:
            return p0
    # pathological (a mode on a prior edge): a tiny ball, projected inside
    rest = mode + 1e-4 * np.sqrt(np.diag(cov)) * rng.standard_normal((n_walkers - filled, N_PARAMS))
    p0[filled:] = [_project(q, one, 0, system.group_index) for q in rest]
    return p0
