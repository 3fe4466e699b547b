"""Where a pulse that found no bottom stops proving there is none: its detection limit.

A class-45 "no-bottom-found-at" point tells a hydrographer "no bottom down to here". Placed at
the end of the recording window, it claims far more than the pulse saw: past the depth where a
bottom echo would have sunk under the detection threshold, a bottom could be there unseen. So
the point goes to the **detection limit of that pulse**: the depth at which a bottom of the
assumed reflectance would just have been detected, computed from the pulse's own waveform.

Model (single-scattering lidar equation, e.g. Guenther 1985, *Airborne laser hydrography*,
NOAA Prof. Paper 1, ch. 3; the same terms as :mod:`pipeline.lidar_equation`). At time ``t``
after the surface echo, with ``v = c / n_g`` and the in-water path ``l = v t / 2``, the
matched-filtered waveform (a Gaussian of the system σ ``σ_t``, as in
:mod:`pipeline.process.detect`) holds

* the water-column return, per sample: ``C(t) = K β_π (v Δt / 2) T²(l) = C0 exp(−α t)``;
* the peak of a bottom echo of Lambertian reflectance ``ρ`` there (total counts
  ``K (ρ/π) T²(l)`` spread as the system pulse, then filtered by it: peak
  ``total Δt / (2 √π σ_t)``): ``B(t) = r C(t)`` with ``r = ρ / (π^{3/2} β_π v σ_t)``.

``C0`` and ``α`` are **measured**: a weighted least-squares line through the logarithm of the
pulse's own filtered column return (weights ``(C/σ)²``, the inverse variance of ``log C``).
``ρ`` and ``β_π`` are the named assumptions :class:`NoBottomSettings` (the column's level fixes
``K T²`` but not ``β_π``, so the bottom-to-column ratio needs it). The detector declares a bottom
where its residual over the column trend exceeds ``k √(σ_f² + F G C(t) Σg²)``
(:mod:`pipeline.process.detect`); ``B(t)`` meets that threshold where ``C`` solves
``r² C² − k² F G Σg² C − k² σ_f² = 0``, so

``t_lim = ln(C0 / C*) / α`` with ``C* = (k² F G Σg² + √((k² F G Σg²)² + 4 r² k² σ_f²)) / (2 r²)``,

capped at the last sample the detector searches (the window's end less the trend's gap). A pulse
whose column is not measurable (fewer than 3 samples above ``min_column_snr`` σ, or no decay,
or a run that rises: an echo the detector did not report) gets no limit (0): nothing is
established for it.

**A claim at a probability.** At ``k`` the assumed bottom is found half the time, so a bottom
just above the limit is missed as often as found. The limit is drawn at the settings'
``detection_probability`` ``p`` instead: ``k`` becomes ``k + z_p`` (the peak ``z_p`` noise σ
above the threshold), and the pulse's decay ``α + z_p σ_α`` (its fit turned about the centre of
its samples; ``σ_α`` with the filtered noise's correlation), as fast as its own samples allow at
``p``. ``p = 1/2`` is the formula above.

**The bottom fades faster than the column.** Forward scattering stretches a deep bottom echo
(its peak drops as it widens) and the column's apparent decay is slower than the beam's
attenuation (light scattered out of the beam still returns from the column). Both are seen in
the survey's own bottoms: for every well-detected bottom (SNR ≥ 2 × threshold), the log of its
measured peak over ``r C(t_b)`` predicted from its own column falls about linearly with
``t_b``; the slope of a line through them is the extra decay ``δ`` (its intercept, which holds
the unknown ratio of the true to the assumed ``ρ/β_π``, is not used), and the limit becomes
``ln(C0 / C*) / (α + δ)``. Deep down only the bottoms that came out bright pass the selection,
so the line is the truncated-normal one, each loss seen only above its own floor
(:mod:`pipeline.process.truncated_regression`; a least-squares line measured no extra decay
in clear water where the limits lay metres under the seabed). Where the survey found too few
bottoms to fit it (< 20; :func:`pipeline.process.no_bottom.excess_decay_summary`), ``δ`` is
``default_excess_decay_per_m`` of :class:`NoBottomSettings`, not 0 (the weakest fading, which
put the limits of a clear-water survey over a 60 m seabed up to 30 m under it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np
from scipy import special

from pipeline.process.column_level import ColumnBins, column_bins
from pipeline.process.limit_model import (
    DetectorModel,
    bottom_to_column_ratio,
    filtered_waveforms,
    limit_time_s,
    threshold_level,
)
from pipeline.process.no_bottom_settings import NoBottomSettings

__all__ = [
    "NoBottomSettings",
    "DetectorModel",
    "ColumnMargins",
    "bottom_to_column_ratio",
    "column_first_s",
    "column_first_index",
    "column_margins",
    "bottom_losses",
    "filtered_waveforms",
    "limit_after_surface_s",
    "no_bottom_limit_s",
]

#: Waveforms handled at once (bounds the float64 temporaries to a few tens of MB).
BLOCK = 4096


@dataclass(frozen=True)
class ColumnMargins:
    """Per pulse with no bottom, shapes ``(n,)``: what sets its detection limit.

    ``log_margin`` is ``ln(C0 / C*)`` (``C*``: the column level at which ``r C*`` is detected
    with the settings' ``detection_probability`` p) and ``alpha_per_s`` the decay of the line
    the limit is drawn from: the measured column's fit turned about the centre of its samples
    to its decay's upper bound at p (:func:`column_margins`); ``alpha_fit_per_s`` the fitted
    decay itself (the record; None: not kept), ``bins`` its column binned (None: not kept),
    ``rises`` whether its run above the noise rose past its first sample (an echo the detector
    did not report; None: not kept).
    ``t_max_s`` the last searched time after the
    surface, ``ok`` whether the column was measurable; ``t_min_s`` the surface-bottom
    separation the detector resolves.
    """

    log_margin: np.ndarray
    alpha_per_s: np.ndarray
    t_max_s: np.ndarray
    ok: np.ndarray
    t_min_s: float
    alpha_fit_per_s: np.ndarray | None = None
    bins: ColumnBins | None = None
    rises: np.ndarray | None = None


def column_first_s(
    t_surface_s: np.ndarray,
    surface_amplitude: np.ndarray | None,
    det: DetectorModel,
    top_above_baseline: np.ndarray | float | None = None,
) -> np.ndarray:
    """Where each pulse's measurable column starts: past the tail of its surface echo.

    An echo of the system's Gaussian filters to ``(A / √2) exp(−τ² / 4σ²)``: the column is
    read from ``min_separation_fwhm`` FWHM after the surface, where the brightest echo the
    digitiser records (``A`` at its top code) has fallen to ``L = (A_top / √2) exp(−sep² /
    4σ²)``. A clipped echo is brighter than the top code (``A`` from its plateau's edges,
    :mod:`pipeline.process.detect_clipped`); its tail falls to the same ``L`` only
    ``τ = √(sep² + 4σ² ln(A / A_top))`` after its centre (clipping lowers samples, so the
    filtered clipped echo stays below its Gaussian's). Without this, a clipped pulse's column
    was not read at all, and a nadir profiler whose every surface echo clips measured no
    column (suite held-out seeds 1 and 12: no decay, the water's c fell back to 0.15 /m).

    Parameters
    ----------
    t_surface_s, surface_amplitude : (n,) ndarray
        The detector's surface time (s) and filtered peak (``A / √2``; a clipped echo's is
        its plateau's ``A`` over √2; None with ``top_above_baseline`` None).
    det : DetectorModel
    top_above_baseline : (n,) ndarray or float, optional
        The digitiser's top code above each pulse's baseline; None: no echo is clipped.

    Returns
    -------
    (n,) ndarray
        Seconds, on the surface time's clock.
    """
    t_s = np.asarray(t_surface_s, dtype=np.float64)
    sep_s = det.min_separation_fwhm * det.pulse_fwhm_s
    if top_above_baseline is None:
        return t_s + sep_s
    a = math.sqrt(2.0) * np.asarray(surface_amplitude, dtype=np.float64)
    ratio = a / np.maximum(np.asarray(top_above_baseline, dtype=np.float64), 1e-300)
    sigma_s = det.sigma_samples * det.dt_s
    tail = np.sqrt(sep_s**2 + 4.0 * sigma_s**2 * np.log(np.maximum(ratio, 1.0)))
    return t_s + np.where(ratio > 1.0, tail, sep_s)


def _blocks(fn, n: int, *arrays):
    """``fn`` over blocks of ``BLOCK`` pulses (bounds the pulses × samples temporaries)."""
    parts = [fn(*(a[i : i + BLOCK] for a in arrays)) for i in range(0, n, BLOCK)]
    if not parts:
        return fn(*(a[:0] for a in arrays))
    return tuple(np.concatenate([p[j] for p in parts]) for j in range(len(parts[0])))


def column_first_index(t_surface_s, det: DetectorModel, first_s=None) -> np.ndarray:
    """Sample index of each column's start, ``(n,)``.

    ``first_s`` (seconds), else one separation after the surface (:func:`column_first_s` of
    an unclipped echo).
    """
    if first_s is None:
        first_s = column_first_s(t_surface_s, None, det)
    return np.asarray(first_s, dtype=np.float64) / det.dt_s


def _column_fit(samples, t_surface_s, t_end_idx, noise_sigma, det, min_snr, first, filt=None):
    """``(log C0, α, ok, t_mid, σ_α, σ_mid, rises)`` of the filtered column, ``first`` on.

    ``log C0`` is the column carried back to the surface time; ``t_mid`` the samples' weighted
    centre after the surface (s); ``σ_α`` the slope's standard error, its white-noise value
    (``Σw / den``) times the filtered noise's correlation length, ``2 √π σ`` samples (adjacent
    filtered samples share their noise); ``σ_mid`` that of the fitted ``log C`` at ``t_mid``
    (``1 / Σw`` times the same length), independent of the slope's there; ``rises`` the run
    rose past its first sample (an echo). The column runs to ``t_end_idx``; ``filt``: the
    waveforms already filtered (:func:`filtered_waveforms`).
    """
    if filt is None:
        filt = filtered_waveforms(samples, det)
    n = filt.shape[0]
    i_s = np.asarray(t_surface_s, dtype=np.float64) / det.dt_s
    nf = np.maximum(np.asarray(noise_sigma, dtype=np.float64), 1e-300)
    end = np.broadcast_to(np.asarray(t_end_idx, dtype=np.float64), (n,))
    f = np.asarray(first, dtype=np.float64)
    sw, st, sl, stt, stl, count, first_y, top_y = _column_sums(
        np.ascontiguousarray(filt, dtype=np.float64), i_s, f, end, nf, det.dt_s, min_snr
    )
    den = sw * stt - st * st
    ok = (count >= 3) & (den > 0)
    slope = np.where(ok, (sw * stl - st * sl) / np.where(ok, den, 1.0), 0.0)
    log_c0 = np.where(ok, (sl - slope * st) / np.where(sw > 0, sw, 1.0), 0.0)
    ok &= slope < 0.0
    # a column only decays: a run that rises past its first sample holds an echo the detector
    # did not report (a bright bottom a metre under a weak surface echo, suite tuning seed 0:
    # read as a column, it claimed no bottom down to 24 m)
    # (an echo stands the detector's threshold above the column; two samples' noise differ by
    # √2 of one's)
    rises = (count > 0) & (top_y - first_y > det.threshold_sigma * math.sqrt(2.0) * nf)
    ok &= ~rises
    t_mid = np.where(ok, st / np.where(sw > 0, sw, 1.0), 0.0)
    corr = det.correlation_samples  # the filtered noise's correlation
    var = sw / np.where(den > 0, den, 1.0) * corr
    # the fitted log C's own sigma at t_mid (the line's two parameters are independent there)
    var_mid = corr / np.where(sw > 0, sw, 1.0)
    return (
        log_c0,
        np.where(ok, -slope, 1.0),
        ok,
        t_mid,
        np.where(ok, np.sqrt(var), 0.0),
        np.where(ok, np.sqrt(var_mid), 0.0),
        rises,
    )


@numba.njit(cache=True, nogil=True)
def _column_sums(filt, i_surface, first, end, nf, dt_s, min_snr):
    """Per pulse, the weighted sums of the column's log-linear fit over its run of samples.

    The run: the samples after ``first`` (index, exclusive) while each stands above
    ``min_snr`` noise σ (the column's decay, not a later noise excursion), before ``end``;
    weights ``(C/σ)²`` (the inverse variance of ``log C`` under additive noise), times from
    the surface (``i_surface``, samples). Returns ``Σw, Σw t, Σw log C, Σw t², Σw t log C``,
    the run's length, its first sample and its highest (``-inf`` without any), each ``(n,)``.
    """
    n, m = filt.shape
    out = np.zeros((5, n))
    count = np.zeros(n, np.int64)
    first_y = np.zeros(n)
    top_y = np.full(n, -np.inf)
    for p in range(n):
        if not (first[p] < m):  # (past the window, or not a number: no run)
            c0 = m
        else:
            c0 = 0 if first[p] < 0.0 else int(math.floor(first[p])) + 1
        level = min_snr * nf[p]
        sw = st = sl = stt = stl = 0.0
        k = 0
        for c in range(c0, m):
            y = filt[p, c]
            if not (y > level) or not (c < end[p]):
                break
            w = (y / nf[p]) ** 2
            t = (c - i_surface[p]) * dt_s
            lc = math.log(y)
            sw += w
            st += w * t
            sl += w * lc
            stt += w * t * t
            stl += w * t * lc
            if k == 0:
                first_y[p] = y
            if y > top_y[p]:
                top_y[p] = y
            k += 1
        out[0, p], out[1, p], out[2, p], out[3, p], out[4, p] = sw, st, sl, stt, stl
        count[p] = k
        if k == 0:
            first_y[p] = filt[p, 0]
    return out[0], out[1], out[2], out[3], out[4], count, first_y, top_y


def column_margins(
    samples: np.ndarray,
    t_surface_s: np.ndarray,
    noise_sigma: np.ndarray,
    det: DetectorModel,
    settings: NoBottomSettings | None = None,
    first_s: np.ndarray | None = None,
    keep_bins: bool = False,
) -> ColumnMargins:
    """The measured column of waveforms without a bottom, against the assumed bottom's echo.

    Parameters
    ----------
    samples : (n, m) array_like
        Digitised waveforms, baseline included.
    t_surface_s : (n,) ndarray
        Surface echo time from the first sample, seconds.
    noise_sigma : (n,) ndarray
        Noise σ of the matched-filtered waveform (the detector's ``noise_sigma``: the
        threshold it applied is ``threshold_sigma`` times it).
    det : DetectorModel
    settings : NoBottomSettings, optional
    first_s : (n,) ndarray, optional
        Where each column starts (:func:`column_first_s`); default one separation after the
        surface.
    keep_bins : bool
        Also keep each column binned (:func:`pipeline.process.column_level.column_bins`), for
        its level at the survey's decay.

    Returns
    -------
    ColumnMargins
    """
    s = settings or NoBottomSettings()
    samples = np.asarray(samples)
    n, m = samples.shape
    fwhm = det.pulse_fwhm_s / det.dt_s
    # the detector's search range: short of the window's end, where its trend is one-sided
    gap = max(2, math.ceil(1.5 * fwhm))
    t_s = np.asarray(t_surface_s, dtype=np.float64)
    nf = np.asarray(noise_sigma, dtype=np.float64)
    first = column_first_index(t_s, det, first_s)

    def fit(y, ts, noise, f):
        filt = filtered_waveforms(y, det)
        end = np.full(len(ts), m - gap)
        out = _column_fit(y, ts, end, noise, det, s.min_column_snr, f, filt=filt)
        if not keep_bins:
            return out
        b = column_bins(filt, f, end, ts, det)
        return (*out, b.t_first_s, b.count, b.sums)

    log_c0, alpha, ok, t_mid, sigma_alpha, _, rises, *binned = _blocks(
        fit, n, samples, t_s, nf, first
    )
    # "no bottom down to here" is claimed at probability p twice over: the assumed bottom
    # detected with probability p (its peak z_p noise σ above the threshold, r C = (k + z_p)
    # √(σ_f² + F G C Σg²), solved for C), and the column decaying as fast as its fit allows at
    # p (a fit over few noisy samples can be nearly flat and carried its limit to the window's
    # end: palmer_survey at c 0.5, one limit 34.5 m deep over a 16.4 m seabed)
    z = float(special.ndtri(s.detection_probability))
    alpha_claim = alpha + z * sigma_alpha
    # the same line through the same centre of its samples, turned to that decay
    log_c0_claim = log_c0 + (alpha_claim - alpha) * t_mid
    c_star = threshold_level(nf, det, s, z)
    return ColumnMargins(
        log_margin=np.where(ok, log_c0_claim - np.log(c_star), 0.0),
        alpha_per_s=alpha_claim,  # (σ_α is 0 where not ok: the fit's placeholder)
        t_max_s=(m - gap) * det.dt_s - t_s,
        ok=ok,
        t_min_s=det.min_separation_fwhm * det.pulse_fwhm_s,
        alpha_fit_per_s=alpha,
        bins=ColumnBins(*binned) if keep_bins else None,
        rises=rises,
    )


def bottom_losses(
    samples: np.ndarray,
    t_surface_s: np.ndarray,
    t_bottom_s: np.ndarray,
    bottom_amplitude: np.ndarray,
    noise_sigma: np.ndarray,
    det: DetectorModel,
    settings: NoBottomSettings | None = None,
    first_s: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """How much weaker found bottoms are than the model's bottom from their own column.

    Parameters
    ----------
    samples : (n, m) array_like
        Waveforms of pulses with a detected bottom.
    t_surface_s, t_bottom_s : (n,) ndarray
        Echo times from the first sample, seconds.
    bottom_amplitude, noise_sigma : (n,) ndarray
        The detector's bottom peak (over the column trend) and filtered noise σ.
    det : DetectorModel
    settings : NoBottomSettings, optional
    first_s : (n,) ndarray, optional
        Where each column starts (:func:`column_first_s`); default one separation after the
        surface.

    Returns
    -------
    t_after_surface_s, log_loss : (n,) ndarray
        ``t_b − t_s`` and ``ln(A_b / (r C0 e^{−α (t_b − t_s)}))``.
    ok : (n,) bool
        The column before the bottom was measurable, and its fitted log level at the bottom
        is sure to ``max_column_sigma``.
    """
    s = settings or NoBottomSettings()
    samples = np.asarray(samples)
    n = samples.shape[0]
    sep = det.min_separation_fwhm * det.pulse_fwhm_s / det.dt_s
    t_s = np.asarray(t_surface_s, dtype=np.float64)
    t_b = np.asarray(t_bottom_s, dtype=np.float64)
    first = column_first_index(t_s, det, first_s)

    def fit(y, ts, tb, noise, f):
        # the column up to one separation before the bottom echo
        return _column_fit(y, ts, tb / det.dt_s - sep, noise, det, s.min_column_snr, f)

    log_c0, alpha, ok, t_mid, sigma_alpha, sigma_mid, _ = _blocks(
        fit, n, samples, t_s, t_b, np.asarray(noise_sigma, float), first
    )
    r = bottom_to_column_ratio(s, det.group_index, det.sigma_samples * det.dt_s)
    dt = t_b - t_s
    amp = np.asarray(bottom_amplitude, dtype=np.float64)
    ok &= amp > 0
    log_loss = np.where(ok, np.log(np.where(ok, amp, 1.0)) - math.log(r) - log_c0 + alpha * dt, 0.0)
    # the column's own sigma carried to the bottom: a loss is only as sure as its column
    ok &= np.hypot(sigma_mid, sigma_alpha * (dt - t_mid)) <= s.max_column_sigma
    return dt, log_loss, ok


def limit_after_surface_s(margins: ColumnMargins, excess_decay_per_s: float = 0.0) -> np.ndarray:
    """Detection-limit time after the surface echo, ``(n,)``; 0 where not established."""
    m = margins
    decay = m.alpha_per_s + excess_decay_per_s
    return limit_time_s(m.log_margin, decay, m.t_max_s, m.ok, m.t_min_s)


def no_bottom_limit_s(
    samples: np.ndarray,
    t_surface_s: np.ndarray,
    noise_sigma: np.ndarray,
    det: DetectorModel,
    settings: NoBottomSettings | None = None,
    excess_decay_per_s: float = 0.0,
) -> np.ndarray:
    """:func:`column_margins` then :func:`limit_after_surface_s` (seconds after the surface)."""
    return limit_after_surface_s(
        column_margins(samples, t_surface_s, noise_sigma, det, settings), excess_decay_per_s
    )
