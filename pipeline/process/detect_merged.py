"""Merged surface and bottom returns: the column-aware two-echo fit (measured data only).

Where the bottom lies closer to the surface than the detector's separation, its echo merges
with the surface echo's. The surface echo is followed by the water column's volume
backscatter, which starts at the surface (a step through the system response) and decays
exponentially with depth (Beer-Lambert down and up); and the surface echo itself is wider than
the system response when the footprint spans a range of heights. A bottom is fitted only
where the waveform needs a second echo beyond these: :func:`fit_merged` models all three, and
:func:`merged_bottoms` accepts a second echo only when its fitted amplitude is significant
against its own standard deviation (the least-squares sandwich covariance, with the matched
filter's noise correlation and the shot noise of what the echo sits on). Without the column
and the free width, a third of the deep-water pulses of a Palmer survey got a "bottom" a few
decimetres under the surface.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

from pipeline.process.merged_lm import lm_fit

__all__ = ["column_decay", "fit_merged", "merged_bottoms"]


def column_decay(filt: np.ndarray, i_surface: np.ndarray, start: int, length: int) -> np.ndarray:
    """Decay rate (per sample) of the water-column return after the surface echo.

    The volume backscatter of a homogeneous column decays as ``exp(-k τ)`` after the surface
    (Beer-Lambert on the way down and up): a straight line in ``ln y``. It is fitted over
    ``[i_surface + start, i_surface + start + length)`` by least squares weighted with ``y²``
    (the variance of ``ln y`` is ``σ²/y²``), so samples near the noise floor hardly count.

    Parameters
    ----------
    filt : (n, m) ndarray
        Matched-filtered, baseline-free waveforms.
    i_surface : (n,) int ndarray
        Sample of the surface peak.
    start, length : int
        Where the fit starts after the surface peak (past the echo itself), and its length.

    Returns
    -------
    (n,) ndarray
        ``k`` ≥ 0 in 1/sample; 0 where the column is too weak to fit (then the column term
        of :func:`fit_merged` is a plain step).
    """
    n, m = filt.shape
    x = np.arange(length, dtype=np.float64)[None, :]
    cols = np.clip(i_surface[:, None] + start + np.arange(length), 0, m - 1)
    y = np.take_along_axis(filt, cols, axis=1)
    w = np.where(y > 0, y * y, 0.0)
    ly = np.log(np.maximum(y, 1e-30))
    sw = w.sum(1)
    safe = np.where(sw > 0, sw, 1.0)
    mx, my = (w * x).sum(1) / safe, (w * ly).sum(1) / safe
    sxx = (w * (x - mx[:, None]) ** 2).sum(1)
    sxy = (w * (x - mx[:, None]) * (ly - my[:, None])).sum(1)
    k = -sxy / np.where(sxx > 0, sxx, 1.0)
    return np.where((sw > 0) & (sxx > 0) & np.isfinite(k), np.maximum(k, 0.0), 0.0)


def fit_merged(
    filt: np.ndarray,
    t_guess: np.ndarray,
    sigma_samples: float,
    iterations: int = 30,
    decay: np.ndarray | None = None,
    noise_corr: np.ndarray | None = None,
):
    """Two Gaussians of the filtered system width, on a column onset, fitted to merged returns.

    With ``decay`` the model is
    ``a_s g_s(t − t_s) + a_b g(t − t_b) + b Φ((t − t_s)/σ) exp(−k (t − t_s))``: surface and
    bottom echoes plus the water-column return, which starts at the surface as a step smoothed
    by the system response and decays at the rate ``k`` measured after the surface
    (:func:`column_decay`); the surface Gaussian ``g_s`` may be wider than the system's (1-3×:
    a footprint spread over a range of heights). Without these terms the column onset and a
    broadened surface echo pass for a bottom just under the surface in a third of deep-water
    pulses. Without ``decay``: two Gaussians of the system width. Batched Levenberg-Marquardt.

    Parameters
    ----------
    filt : (n, m) ndarray
        Matched-filtered, baseline-free waveforms.
    t_guess : (n,) ndarray
        Sample index of the merged peak.
    sigma_samples : float
        σ of the system response in samples (the filtered return has σ √2).
    iterations : int
        Levenberg-Marquardt steps.
    decay : (n,) ndarray, optional
        Column decay rate ``k`` (1/sample). None: no column term (two Gaussians alone).
    noise_corr : (L,) ndarray, optional
        Correlation of the filtered noise at lags 0, 1, ... samples (1 at lag 0); needed for
        ``sd_bottom``.

    Returns
    -------
    t_surface, t_bottom, a_surface, a_bottom : (n,) ndarray
        Sample positions and heights of the two components, ``t_surface < t_bottom``.
    ok : (n,) bool
        Converged with both amplitudes positive and the two centres apart.
    column : (n, 3) ndarray
        Column term ``(b, k)`` of the fit (zeros without ``decay``) and the surface echo's
        filtered σ (samples; the system's without ``decay``).
    sd_bottom : (n,) ndarray
        Standard deviation of ``a_bottom`` per unit filtered-noise σ (inf without
        ``noise_corr``): ``a_bottom / (sd_bottom σ)`` is its significance.
    """
    n, m = filt.shape
    sg = math.sqrt(2.0) * sigma_samples
    use_col = decay is not None
    kk = (np.zeros(n) if decay is None else np.asarray(decay, dtype=np.float64))[:, None]
    # fit only a slice of ±6 σ around the merged peak (cost independent of the window length)
    half = int(math.ceil(6.0 * sg))
    cols = np.clip(
        np.round(t_guess).astype(np.int64)[:, None] + np.arange(-half, half + 1), 0, m - 1
    )
    # column level: what the waveform holds 3 σ after the merged peak (past both echoes)
    after = np.clip(np.round(t_guess + 3.0 * sg).astype(np.int64), 0, m - 1)
    col0 = filt[np.arange(n), after]
    filt = np.take_along_axis(filt, cols, axis=1)
    x = cols.astype(float)
    window = np.abs(x - t_guess[:, None]) <= 6.0 * sg
    peak_h = np.max(np.where(window, filt, -np.inf), axis=1)
    b0 = np.where(use_col, np.clip(col0, 0.0, 0.5 * peak_h), 0.0)
    # parameters: t_s, t_b, a_s, a_b, column b, surface σ (the surface echo of a footprint
    # spread over a range of heights is wider than the system response: a free width keeps a
    # broadened surface from passing as a second return)
    t1, t2, a2 = t_guess - 0.5 * sg, t_guess + 0.5 * sg, 0.3 * peak_h
    if use_col:
        # the surface comes first (from a symmetric start the fit may swap the two and give
        # the column to the bottom): start the bottom at the largest excess over a surface
        # echo of the system width behind the peak
        excess = filt - peak_h[:, None] * np.exp(-0.5 * ((x - t_guess[:, None]) / sg) ** 2)
        behind = window & (x > t_guess[:, None] + 0.5 * sg)
        j = np.argmax(np.where(behind, excess, -np.inf), axis=1)
        t1, t2 = t_guess, x[np.arange(n), j]
        a2 = np.maximum(excess[np.arange(n), j] - b0, 0.1 * peak_h)
    p = np.column_stack([t1, t2, peak_h, a2, b0, np.full(n, sg)])
    act = [0, 1, 2, 3, 4, 5] if use_col else [0, 1, 2, 3]

    def model(p):
        s1 = p[:, 5:6]
        g1 = np.exp(-0.5 * ((x - p[:, 0:1]) / s1) ** 2)
        g2 = np.exp(-0.5 * ((x - p[:, 1:2]) / sg) ** 2)
        tau = x - p[:, 0:1]
        # the column is a physical term only behind the surface: e^{-kτ} grows before it
        decay = np.exp(-kk * np.maximum(tau, 0.0))
        col = ndtr(tau / sg) * decay
        f = p[:, 2:3] * g1 + p[:, 3:4] * g2 + p[:, 4:5] * col
        dcol = -np.exp(-0.5 * (tau / sg) ** 2) / (sg * math.sqrt(2.0 * math.pi)) * decay + (
            kk * col * (tau > 0)
        )
        jac = np.stack(
            [
                p[:, 2:3] * g1 * tau / s1**2 + p[:, 4:5] * dcol,
                p[:, 3:4] * g2 * (x - p[:, 1:2]) / sg**2,
                g1,
                g2,
                col,
                p[:, 2:3] * g1 * tau**2 / s1**3,
            ],
            axis=2,
        )[:, :, act]
        return f, jac * window[:, :, None]

    npar = len(act)
    # the iterations, compiled per pulse (:mod:`pipeline.process.merged_lm`); the model above
    # serves the covariance below
    p, c = lm_fit(
        np.ascontiguousarray(x),
        np.ascontiguousarray(filt, dtype=np.float64),
        np.ascontiguousarray(window),
        np.ascontiguousarray(p, dtype=np.float64),
        np.ascontiguousarray(kk[:, 0]),
        float(sg),
        npar,
        int(iterations),
    )
    lo = np.minimum(p[:, 0], p[:, 1])
    hi = np.maximum(p[:, 0], p[:, 1])
    first_is_0 = p[:, 0] <= p[:, 1]
    a_lo = np.where(first_is_0, p[:, 2], p[:, 3])
    a_hi = np.where(first_is_0, p[:, 3], p[:, 2])
    # σ of the later amplitude per unit filtered-noise σ: the least-squares sandwich
    # (JᵀJ)⁻¹ Jᵀ R J (JᵀJ)⁻¹ with R the filtered noise's correlation. Two components
    # closer than the echo width trade amplitude freely, so a "second return" that is only a
    # broadened surface echo has a large σ here and is not significant.
    sd_hi = np.full(n, np.inf)
    if noise_corr is not None:
        jac = model(p)[1]
        lag = np.abs(np.arange(x.shape[1])[:, None] - np.arange(x.shape[1])[None, :])
        rho = np.asarray(noise_corr, dtype=np.float64)
        corr = np.where(lag < rho.size, rho[np.minimum(lag, rho.size - 1)], 0.0)
        jtj = np.einsum("nmi,nmj->nij", jac, jac) + 1e-12 * np.eye(npar)[None]
        meat = np.einsum("nmi,mk,nkj->nij", jac, corr, jac)
        try:
            inv = np.linalg.inv(jtj)
            cov = inv @ meat @ inv
            var_hi = np.where(first_is_0, cov[:, 3, 3], cov[:, 2, 2])
            sd_hi = np.where(var_hi > 0, np.sqrt(np.abs(var_hi)), np.inf)
        except np.linalg.LinAlgError:
            pass
    near = (np.abs(lo - t_guess) <= 4.0 * sg) & (np.abs(hi - t_guess) <= 4.0 * sg)
    ok = (a_lo > 0) & (a_hi > 0) & (hi - lo > 0.3 * sg) & np.isfinite(c) & near
    if use_col:
        # the column and the free width belong to the surface: it must come first
        ok &= first_is_0
    lo, hi = np.where(ok, lo, t_guess), np.where(ok, hi, t_guess)
    return lo, hi, a_lo, a_hi, ok, np.column_stack([p[:, 4], kk[:, 0], p[:, 5]]), sd_hi


def merged_bottoms(
    filt, i_surface, t_surface, sigma_samples, sep, gap, kernel, noise_f, shot_noise_counts,
    threshold_sigma,
):  # fmt: skip
    """Fit the merged waveforms and keep the significant bottoms.

    Parameters
    ----------
    filt : (n, m) ndarray
        Matched-filtered, baseline-free waveforms of the merged pulses.
    i_surface : (n,) int ndarray
        Sample of each surface peak.
    t_surface : (n,) ndarray
        Surface time (samples): the fit's starting guess.
    sigma_samples : float
        σ of the system response, samples.
    sep, gap : float, int
        The detector's surface-bottom separation and flank-trend gap (samples): the column's
        decay is measured past both.
    kernel : (L,) ndarray
        The matched filter's discrete kernel (its autocorrelation is the filtered noise's).
    noise_f : (n,) ndarray
        Filtered electronic noise σ.
    shot_noise_counts : float
        ``F·G`` (see :func:`~pipeline.process.detect.detect_full_waveform`).
    threshold_sigma : float
        Significance a bottom needs.

    Returns
    -------
    good : (n,) bool
        A significant bottom was separated.
    t_surface, t_bottom, a_surface, a_bottom, snr_bottom : (n,) ndarray
        The fit's times (samples), heights and the bottom's significance.
    """
    k_col = column_decay(filt, i_surface, start=math.ceil(sep) + gap, length=max(4, math.ceil(sep)))
    kernel_sq = float(np.sum(kernel**2))
    corr = np.correlate(kernel, kernel, mode="full")[kernel.size - 1 :] / kernel_sq
    ts, tb, a_s, a_b, ok, col, sd_b = fit_merged(
        filt, t_surface, sigma_samples, decay=k_col, noise_corr=corr
    )
    # significance against the surface echo + column the bottom sits on, with their shot
    # noise (as the separated bottom's), not against the electronic noise alone: the
    # trailing flank of a strong surface echo carries far more noise than the baseline
    sg2 = math.sqrt(2.0) * sigma_samples
    d = np.maximum(tb - ts, 0.0)
    under = a_s * np.exp(-0.5 * (d / col[:, 2]) ** 2) + col[:, 0] * ndtr(d / sg2) * np.exp(
        -col[:, 1] * d
    )
    var_b = noise_f**2 + shot_noise_counts * np.maximum(under, 0.0) * kernel_sq
    snr = np.where(ok, a_b / (sd_b * np.sqrt(var_b)), 0.0)
    snr = np.where(np.isfinite(snr), snr, 0.0)
    return ok & (snr > threshold_sigma), ts, tb, a_s, a_b, snr
