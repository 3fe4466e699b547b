"""Detect the water surface and the bottom in photon-counting data (measured data only).

A single shot holds a handful of photons, mostly background; returns emerge only when shots are
accumulated along track. Each event is placed on its measured beam at the range of its time of
flight (``r = c t / (2 n_air)``, no refraction yet), and its height is histogrammed over a window
of ``shots_per_window`` consecutive shots:

1. **Background** per window (:func:`~pipeline.process.photon_histogram.background`): the
   larger of the mean of the bins below the 90th percentile and the Poisson rate of the share
   of empty bins, both over the range gate; the second keeps a sparse background (most bins
   empty) from being taken as zero.
2. **Surface**: the FIRST significant return from above, not the strongest: at 532 nm a
   shallow, bright seabed returns more photons than the water surface (off nadir, or with a
   calm surface, many times more). A return is significant when the counts over its
   ``2 centroid_bins + 1`` bins beat the background: counts are Poisson, the p-value is
   ``P(X >= k | b)``, and it must beat the one-sided normal tail of ``threshold_sigma``
   divided by the number of bins searched (a Bonferroni look-elsewhere correction). The peak
   is then reached by climbing down from that box to the first local maximum, never past a
   dip (which would lead into a seabed echo just below).
   **Bottom**: the most significant return at least ``min_separation_m`` (and the surface's
   box) below the surface peak, tested against its local level: the larger flank mean of the
   water-column return (surface box left out), and the emptiest bin between it and the
   surface, so the falling tail of the surface echo is never a bottom. Closer than that, in
   very shallow water (echoes under ~2 σ of their width apart, with no emptier bin between
   them: below ~0.15-0.2 m for 0.1 m bins and sub-ns pulses), surface and seabed merge:
   no bottom is reported rather than a split of the merged echo, and the surface is that
   echo's centroid, pulled toward the brighter seabed (by up to the apparent depth). The
   significance is reported back in normal σ.
3. **Sub-bin height**: the background-subtracted centroid of the events within ±``centroid_bins``
   of the peak bin; with a bottom, surface and bottom centroids stop short of the emptiest bin
   between them. Then (``echo_ml``, given the system pulse's sigma) each echo's
   maximum-likelihood height under the dead time (:mod:`pipeline.process.photon_echo_ml`):
   of a piled-up echo only the leading edge is recorded and the centroid lies early.
Dead time: every count is live-time corrected first (:mod:`pipeline.process.photon_livetime`),
and the bins the dead time left blind are neither a level nor a dip. A window's detection limit
(:mod:`pipeline.process.photon_limit`) places its class-45 point and flags bottoms past it.

4. Back to **per-shot times**: each shot of the window gets the time at which its own measured
   beam reaches the detected heights (``t = 2 n_air r / c``), so refraction correction then runs
   exactly as for full waveforms.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline import optics
from pipeline.config import setting
from pipeline.process.detect import WaveformDetections, flank_trend
from pipeline.process.detection_limit import NoBottomSettings
from pipeline.process.photon_carry import second_pass
from pipeline.process.photon_echo_ml import surface_and_bottom_ml
from pipeline.process.photon_histogram import background, echo_reach_bins, gate_span, significance
from pipeline.process.photon_limit import photon_detection_limit
from pipeline.process.photon_livetime import (
    bin_live_fraction,
    dead_height_m,
    event_heights_m,
    event_live_fraction,
    surface_pileup_pe,
)
from pipeline.process.photon_windows import PhotonWindows
from pipeline.process.returns import DetectorFlag

__all__ = ["PhotonDetectSettings", "detect_photon_events"]

#: live share of a bin's shot-channels from which its counts measure the rate: below it the
#: dead time after a strong echo has blinded most shots, and an empty bin shows no dip
MEASURED_LIVE_FRACTION = 0.5


@dataclass(frozen=True, kw_only=True)
class PhotonDetectSettings:
    """Along-track accumulation and thresholds of the photon-counting detector."""

    shots_per_window: int = setting(
        200,
        ge=1,
        le=10_000_000,
        doc="shots accumulated per window: consecutive shots, or about as many per cell of a "
        "scan (window_cell_m)",
    )
    window_cell_m: float | None = setting(
        None,
        ge=0.0,
        le=1000.0,
        doc="side of the square cells (where the beam meets z = 0) that group a scan's shots "
        "into windows; 0: windows of consecutive shots; default: 0 under a profiler, under a "
        "scanner the side holding about shots_per_window shots of one look at the plan's shot "
        "density (pipeline.process.photon_windows)",
    )
    bin_m: float = setting(0.1, gt=0.0, le=10.0, doc="height histogram bin")
    threshold_sigma: float = setting(
        5.0, gt=0.0, le=100.0, doc="surface and bottom significance, Poisson σ"
    )
    min_separation_m: float = setting(0.3, ge=0.0, le=100.0, doc="bottom below the surface by")
    centroid_bins: int = setting(2, ge=0, le=50, doc="bins each side used for the centroid")
    trend_bins: int = setting(20, ge=2, le=1000, doc="flank length of the column trend, bins")
    echo_ml: bool = setting(
        True,
        doc="time surface and bottom by a maximum-likelihood fit of the system pulse under the "
        "dead time (pipeline.process.photon_echo_ml): a piled-up echo's live-time corrected "
        "centroid lies early by up to a pulse sigma; False: that centroid",
    )
    saturation_pe: float = setting(
        3.0,
        gt=0.0,
        le=100.0,
        doc="surface photoelectrons per shot and channel, -ln(1 - share of shots with an "
        "event in the surface box) / n_channels, from which the window is flagged SATURATED "
        "(dead-time pile-up: the first photon of nearly every shot, early in the echo)",
    )


def detect_photon_events(
    offsets: np.ndarray,
    times_s: np.ndarray,
    origin_m: np.ndarray,
    direction: np.ndarray,
    n_air: float,
    settings: PhotonDetectSettings | None = None,
    pulse_id: np.ndarray | None = None,
    n_channels: int = 1,
    dead_time_s: float = 0.0,
    no_bottom: NoBottomSettings | None = None,
    group_index: float | None = None,
    pulse_sigma_s: float = 0.0,
    windows: PhotonWindows | None = None,
    _detrend: tuple[np.ndarray, np.ndarray] | bool | None = None,
) -> WaveformDetections:
    """Surface and bottom per shot from photon events accumulated along track.

    Parameters
    ----------
    offsets : (n_shots + 1,) int
        Events of shot ``i`` are ``times_s[offsets[i]:offsets[i + 1]]``.
    times_s : (n_events,) float64
        Event times after emission, seconds.
    origin_m, direction : (n_shots, 3) float64
        Measured laser position and unit beam direction of each shot.
    n_air : float
        Phase index of air (ranges from times of flight).
    settings : PhotonDetectSettings, optional
    pulse_id : (n_shots,) int, optional
        Global shot numbers; windows are then ``pulse_id // shots_per_window`` (or cells of
        slabs: ``windows``), so a survey split into chunks (of whole windows or slabs) gives
        the same windows as one piece.
    n_channels : int
        Detector channels per beam (the datasheet's): each records one event per dead time.
    dead_time_s : float
        Dead time per channel (the datasheet's). Histograms and centroids are live-time
        corrected (:mod:`pipeline.process.photon_livetime`): each event counts ``1 / L``, ``L``
        the window's share of channels live at its height, and the significance of a box
        compares its recorded counts with the expected rate times the box's live share.
    no_bottom : NoBottomSettings, optional
        With ``group_index`` (the water's, processing's assumption): each window's detection
        limit (:mod:`pipeline.process.photon_limit`, ``t_detection_limit_s``). A window without
        a bottom states "no bottom" (``t_no_bottom_s``) down to the shallower of it and the
        column's extent (the run of significant boxes from the surface, less the reach of an
        echo past its reflector: a seabed merged into the surface echo ends the run that far
        below itself), and a bottom found deeper than it, under
        twice the threshold, is flagged BEYOND_DETECTION_LIMIT (a bottom of the assumed
        reflectance would not be seen there: it cannot be told from an upward fluctuation).
    pulse_sigma_s : float
        Sigma of the system's response (pulse and detector; processing's assumption of the
        instrument). With ``settings.echo_ml``, surface and bottom are the maximum-likelihood
        heights of that pulse under the dead time (:mod:`pipeline.process.photon_echo_ml`); 0:
        the live-time corrected centroids.

    windows : PhotonWindows, optional
        How the shots are grouped (the survey's, :func:`~pipeline.process.photon_windows.
        resolve_windows`); default ``settings.shots_per_window`` consecutive shots, split by
        ``settings.window_cell_m`` cells if given.

    Returns
    -------
    WaveformDetections
        Round-trip times per shot (absolute, after emission); amplitudes are window counts.

    Notes
    -----
    A scan's cell windows are detected twice (:mod:`pipeline.process.photon_carry`): the
    first pass gives each window's bottom height, from which each window's seabed slope is
    fitted over its neighbours; the second histograms the events below the surface with
    that slope taken out (a cell over a sloping seabed spreads its bottom echo over the
    slope times the cell: 1.9 m for 12 m cells at 9°, where a pulse fitted to it finds a
    peak anywhere in that band), and carries each window's bottom to its shots along it.
    """
    s = settings or PhotonDetectSettings()
    n = origin_m.shape[0]
    c = optics.SPEED_OF_LIGHT_M_S
    ids = np.arange(n) if pulse_id is None else np.asarray(pulse_id)
    if windows is None:  # the settings' own: cells (if given) of slabs of shots_per_window
        cell = s.window_cell_m or 0.0
        windows = PhotonWindows(s.shots_per_window, cell, s.shots_per_window)
    args = (offsets, times_s, origin_m, direction, n_air, s, ids, n_channels, dead_time_s)
    kw = {"no_bottom": no_bottom, "group_index": group_index, "pulse_sigma_s": pulse_sigma_s}
    kw["windows"] = windows
    if windows.cell_m > 0.0 and _detrend is None and n:
        first = detect_photon_events(*args, **kw, _detrend=False)
        second = second_pass(first, windows, ids, origin_m, direction, n_air, s)
        return detect_photon_events(*args, **kw, _detrend=second)
    shot, z = event_heights_m(offsets, times_s, origin_m, direction, n_air)
    keys = windows.of(ids, origin_m, direction)
    keys_w, window = np.unique(keys, return_inverse=True)
    n_win = int(window.max()) + 1 if n else 0
    ev_win = window[shot]
    carry = np.zeros(n)  # each shot's bottom height over its window's (the second pass)
    if isinstance(_detrend, tuple):
        carry, split_w = _detrend
        # the events below the surface band with the seabed's slope taken out
        z = np.where(z < split_w[ev_win], z - carry[shot], z)
    empty = WaveformDetections(
        *(
            np.zeros(n, dtype=b)
            for b in (bool, float, float, float, bool, float, float, float, float, np.uint16)
        )
    )
    if z.size == 0:
        return empty
    cb = s.centroid_bins
    # bins on the absolute grid z = bin_m * k, so an event's bin never depends on the other
    # events of the chunk; the histogram starts ``pad`` bins below the chunk's lowest event and
    # ends ``pad`` above its highest, so every box holding a window's event exists whatever
    # the chunk's extent (its results then do not depend on the chunk either)
    pad = 2 * cb + 2
    k_abs = np.floor(z / s.bin_m).astype(np.int64)
    k0 = int(k_abs.min()) - pad
    nb = int(k_abs.max()) + pad - k0 + 1
    b = k_abs - k0
    # live-time (Coates) correction: recorded counts over the live share of the shot-channels
    shots_w = np.bincount(window, minlength=n_win)
    tau_h = dead_height_m(dead_time_s, n_air, direction[shot, 2])
    w_ev = 1.0 / event_live_fraction(ev_win, z, tau_h, shots_w, n_channels)
    live = bin_live_fraction(ev_win, z, tau_h, k0 * s.bin_m, s.bin_m, nb, shots_w, n_channels)
    raw = np.bincount(ev_win * nb + b, minlength=n_win * nb).reshape(n_win, nb).astype(float)
    hist = np.bincount(ev_win * nb + b, weights=w_ev, minlength=n_win * nb).reshape(n_win, nb)
    bg = background(hist)
    # the look-elsewhere count of each window: the bins of its own range gate (its events'
    # span, as the background's), not the chunk's histogram
    span = gate_span(hist)
    n_searched = np.maximum(span.sum(axis=1), 1)[:, None]
    bg_safe = np.maximum(bg, 1e-3)  # an empty background still has a finite p-value scale
    rows = np.arange(n_win)
    col = np.arange(nb)[None, :]
    # counts of a return spread over neighbouring bins: test the sum over the centroid window
    # (corrected counts, recorded counts, live share): the recorded counts of a box are Poisson
    # of the rate times its live share, so significances use those two
    csum = [
        np.concatenate([np.zeros((n_win, 1)), np.cumsum(a, axis=1)], axis=1)
        for a in (hist, raw, live)
    ]

    def box_sum(lo, hi, which=0):
        """Sums over bins ``[lo, hi]`` per window and bin (clipped to the histogram)."""
        lo, hi = np.clip(lo, 0, nb), np.clip(hi + 1, 0, nb)
        cs = csum[which]
        return np.take_along_axis(cs, hi, axis=1) - np.take_along_axis(
            cs, np.minimum(lo, hi), axis=1
        )

    full = np.broadcast_to(col, (n_win, nb))
    box = box_sum(full - cb, full + cb)
    box_live = box_sum(full - cb, full + cb, 2)
    sig_box = significance(
        box_sum(full - cb, full + cb, 1), bg_safe[:, None] * box_live, n_searched
    )
    # Surface: the FIRST significant return from above (the highest bin), not the strongest:
    # at 532 nm a shallow seabed can return more photons than the water surface.
    top = np.where(sig_box >= s.threshold_sigma, col, -1).max(axis=1)
    has_s = top >= 0
    # its peak: from the highest bin of that box holding at least the box's mean count (a
    # lone background photon above the echo does not), climb down while the counts do not
    # fall, no further than one box length below the box (whose leading edge may alone
    # have made it significant). The climb stops at the first dip, so a brighter seabed
    # past it is not reached.
    top0 = np.maximum(top, 0)
    in_box = np.abs(col - top0[:, None]) <= cb
    strong = in_box & (hist * (2 * cb + 1) >= box[rows, top0][:, None])
    i_s = np.where(strong, col, 0).max(axis=1)
    for _ in range(3 * cb):
        step = (i_s > 0) & (i_s > top - 2 * cb)
        step &= hist[rows, np.maximum(i_s - 1, 0)] >= hist[rows, i_s]
        i_s = np.where(step, i_s - 1, i_s)
    # Bottom: a return below the surface's box and at least min_separation_m below its peak.
    # Closer (very shallow water), surface and bottom merge within the system response and
    # dead time: no bottom is reported rather than a split of the surface echo.
    # (a scan's cell: and below the band its waves spread the surface echo over)
    sep_m = max(s.min_separation_m, windows.sea_band_m)
    sep_bins = max(int(math.ceil(sep_m / s.bin_m)), cb + 1)
    s_lo = i_s - cb  # lowest bin of the surface box
    below = col <= (i_s - sep_bins)[:, None]
    # the water-column return decays smoothly below the surface: a bottom must stand out of
    # its local level (the larger mean of the flanking bins, the surface box left out), not
    # only of the background
    # bins the dead time left (nearly) blind hold no measurement: not a level, not a dip
    measured = live >= MEASURED_LIVE_FRACTION
    local = np.maximum(
        flank_trend(
            hist, gap=cb + 1, length=s.trend_bins, valid=span & measured & (col < s_lo[:, None])
        ),
        bg_safe[:, None],
    )
    # the candidate's box stops short of the surface box, so the surface tail is not counted
    hi_b = np.minimum(full + cb, s_lo[:, None] - 1)
    box_b = box_sum(full - cb, hi_b, 1)
    n_b = np.maximum(box_sum(full - cb, hi_b, 2), 1e-9)  # live bins of the box
    # ... and it must stand out of the emptiest bin between its box and the surface: the
    # falling tail of the surface echo has no such dip and so never passes as a bottom. Only
    # measured bins count: after a saturated surface the dead time empties the next bins, and
    # the water column resuming below them is no second echo. With no measured bin between,
    # the candidate cannot be told from the surface: it is no bottom.
    # The dip's level is a 3-bin mean (of the measured bins): one bin's Poisson low in the
    # column is no dip.
    cm = np.concatenate([np.zeros((n_win, 1)), np.cumsum(hist * measured, axis=1)], axis=1)
    cn = np.concatenate([np.zeros((n_win, 1)), np.cumsum(measured, axis=1)], axis=1)
    lo3, hi3 = np.clip(col - 1, 0, nb), np.clip(col + 2, 0, nb)
    n3 = cn[:, hi3[0]] - cn[:, lo3[0]]
    mean3 = (cm[:, hi3[0]] - cm[:, lo3[0]]) / np.maximum(n3, 1)
    upper = np.where((col < i_s[:, None]) & measured, mean3, np.inf)
    suffix_min = np.minimum.accumulate(upper[:, ::-1], axis=1)[:, ::-1]
    suffix_min = np.concatenate([suffix_min, np.full((n_win, 1), np.inf)], axis=1)
    valley_min = np.take_along_axis(suffix_min, np.clip(hi_b + 1, 0, nb), axis=1)
    local = np.maximum(local, valley_min)
    told = np.isfinite(local)
    sig_all = np.where(told, significance(box_b, np.where(told, local, 1.0) * n_b, n_searched), 0.0)
    i_b = np.argmax(np.where(below, sig_all, -np.inf), axis=1)
    sig_s = np.where(has_s, sig_box[rows, i_s], 0.0)
    sig_b = np.where(has_s & below[rows, i_b], sig_all[rows, i_b], 0.0)
    has_b = has_s & (sig_b >= s.threshold_sigma)
    # the centroids of surface and bottom stop at the emptiest bin between them
    between = (col > i_b[:, None]) & (col < i_s[:, None])
    valley = np.where(has_b, np.argmin(np.where(between & measured, hist, np.inf), axis=1), -1)
    s_box = (np.maximum(i_s - cb, valley + 1), i_s + cb)
    b_box = (i_b - cb, np.minimum(i_b + cb, np.where(has_b, valley - 1, nb)))

    def centroid(i_peak, box):
        lo, hi = box[0][ev_win], box[1][ev_win]
        near = (b >= lo) & (b <= hi)
        # live-time corrected weights (the recorded echo is cut short by the dead time);
        # subtract the background's share, spread uniformly over the centroid bins
        w = np.bincount(ev_win[near], weights=w_ev[near], minlength=n_win)
        zsum = np.bincount(ev_win[near], weights=(w_ev * z)[near], minlength=n_win)
        nbins = np.maximum(box[1] - box[0] + 1, 1)
        # heights from absolute bin numbers (integers: exact, whatever the chunk's k0)
        centre = (2 * k0 + box[0] + box[1] + 1) * (0.5 * s.bin_m)
        excess = np.maximum(w - bg * nbins, 1e-9)
        zc = (zsum - bg * nbins * centre) / excess
        peak_z = (k0 + i_peak + 0.5) * s.bin_m
        return np.where(w > bg * nbins, zc, peak_z), np.maximum(excess, 0.0)

    # No bottom: light is seen to come back down to the lowest bin of the run of significant
    # boxes that starts at the surface peak (the water column); a bottom there, brighter than
    # the column, would have been found. Past it nothing is established: the limit, and none
    # where the run ends before a box clear of the surface's own (opaque water, land: the
    # surface echo's tail alone makes the boxes overlapping it significant).
    weak_below = (sig_box < s.threshold_sigma) & (col < i_s[:, None])
    i_lim = np.where(weak_below, col, -1).max(axis=1) + 1
    # ... but the run's lowest box may owe its counts to its upper bins alone, and an echo's
    # significant boxes reach past the reflector that made it: a bottom too near the surface
    # to be told apart (merged into its echo) ends the run that far below itself. Light is
    # established, and with it the absence of any bottom, only that far above the run's end
    i_lim = i_lim + echo_reach_bins(top - i_s, cb, pulse_sigma_s, n_air, s.bin_m)
    # the detection limit (a bottom of the assumed reflectance seen down to it), where the
    # window's column is measurable. Class 45 takes the shallower of it and the column's
    # extent: the limit rests on assumed ρ and β_π and on a column decay that forward scatter
    # makes slower than a bottom's, so alone it can claim "no bottom" over a bottom too dim
    # to see
    i_det = np.full(n_win, -1, dtype=np.int64)
    if no_bottom is not None and group_index is not None:
        i_det = photon_detection_limit(
            hist,
            box,
            bg,
            span & measured & (col < (s_lo - cb)[:, None]),
            n_searched,
            # the column fit leaves a bottom's box (and its flanks) out
            ~has_b[:, None] | (np.abs(col - i_b[:, None]) > 2 * cb),
            half_box=cb,
            bin_m=s.bin_m,
            n_air=n_air,
            group_index=group_index,
            bottom_reflectance=no_bottom.bottom_reflectance,
            backscatter_180_per_m_sr=no_bottom.backscatter_180_per_m_sr,
            threshold_sigma=s.threshold_sigma,
            min_column_snr=no_bottom.min_column_snr,
            # a window without a bottom claims its absence at the settings' probability; a
            # found bottom is judged against the threshold's own limit (a weak bottom past
            # where the assumed one is found half the time is suspect: BEYOND_DETECTION_LIMIT)
            detection_probability=np.where(has_b, 0.5, no_bottom.detection_probability),
        )
    has_det = has_s & (i_det >= 0)
    beyond = has_b & has_det & (i_b < i_det) & (sig_b < 2 * s.threshold_sigma)
    i_lim = np.where(has_det, np.maximum(i_det, i_lim), i_lim)
    has_lim = has_s & ~has_b & (i_lim < s_lo - cb)
    z_lim = (k0 + i_lim + 0.5) * s.bin_m
    z_s, amp_s = centroid(i_s, s_box)
    lam_s = surface_pileup_pe(shot, window, b, ev_win, s_box, n, n_win, n_channels)
    z_b, amp_b = centroid(i_b, b_box)
    if s.echo_ml and pulse_sigma_s > 0:
        # the centroid of a piled-up echo lies early: fit the known pulse to what was live
        per_m = 1.0 / (np.maximum(shots_w, 1) * max(int(n_channels), 1) * s.bin_m)
        z_s, z_b = surface_and_bottom_ml(
            (ev_win, z, tau_h), window, direction, pulse_sigma_s, n_air, n_channels,
            {"z_s": z_s, "z_b": z_b, "has_s": has_s, "has_b": has_b, "bg_s": bg * per_m,
             "bg_b": local[rows, i_b] * per_m, "edge_s": (k0 + s_box[0]) * s.bin_m,
             "edge_b": (k0 + b_box[1] + 1) * s.bin_m},
        )  # fmt: skip
    # per shot: time at which its own measured beam reaches the window's detected heights
    dz = direction[:, 2]
    with np.errstate(divide="ignore"):
        scale = np.where(dz < 0, 2.0 * n_air / (c * -dz), 0.0)
    t_s = (origin_m[:, 2] - z_s[window]) * scale
    t_b = (origin_m[:, 2] - (z_b[window] + carry)) * scale
    hs = has_s[window] & (t_s > 0)
    hb = has_b[window] & hs & (t_b > t_s)
    t_lim = (origin_m[:, 2] - z_lim[window]) * scale
    t_lim = np.where(has_lim[window] & hs & ~hb & (t_lim > t_s), t_lim, 0.0)
    t_det = (origin_m[:, 2] - (k0 + i_det[window] + 0.5) * s.bin_m) * scale
    t_det = np.where(has_det[window] & hs & (t_det > t_s), t_det, 0.0)
    conf_s = 1.0 - np.exp(-0.5 * (np.maximum(sig_s, 0) / s.threshold_sigma) ** 4)
    conf_b = 1.0 - np.exp(-0.5 * (np.maximum(sig_b, 0) / s.threshold_sigma) ** 4)
    flags = np.zeros(n, dtype=np.uint16)
    flags[hs & (sig_s[window] < 2 * s.threshold_sigma)] |= np.uint16(DetectorFlag.LOW_SNR)
    flags[hs & (lam_s >= s.saturation_pe)[window]] |= np.uint16(DetectorFlag.SATURATED)
    flags[hb & beyond[window]] |= np.uint16(DetectorFlag.BEYOND_DETECTION_LIMIT)
    zero = np.zeros(n)
    return WaveformDetections(
        has_surface=hs,
        t_surface_s=np.where(hs, t_s, zero),
        surface_amplitude=np.where(hs, amp_s[window], zero),
        surface_confidence=np.where(hs, conf_s[window], zero),
        has_bottom=hb,
        t_bottom_s=np.where(hb, t_b, zero),
        bottom_amplitude=np.where(hb, amp_b[window], zero),
        bottom_confidence=np.where(hb, conf_b[window], zero),
        noise_sigma=np.sqrt(bg_safe)[window],
        flags=flags,
        t_no_bottom_s=t_lim,
        t_detection_limit_s=t_det,
    )
