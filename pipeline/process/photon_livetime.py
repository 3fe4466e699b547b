"""Dead-time (live-time) correction of accumulated photon events (measured data only).

A photon-counting channel is blind for its dead time ``tau`` after each recorded event
(non-paralyzable), so a strong echo hides the photons that follow it within ``tau``: the
recorded echo is cut short and its centroid lies early (high), the "first-photon bias" of
ICESat-2 (ATL03 ATBD, Neumann et al. 2019, sec. "first photon bias"), and the few
nanoseconds after a bright water surface look empty, so the water-column return that resumes
below them looks like a second echo.

The correction is the live-time (Coates) correction of time-correlated photon counting:
Coates (1968), "The correction for photon 'pile-up' in the measurement of radiative
lifetimes", J. Phys. E 1:878, generalised to a finite dead time by Isbaner et al. (2016),
"Dead-time correction of fluorescence lifetime measurements and fluorescence lifetime
imaging", Opt. Express 24:9429. Over the shots of a window, the channels that can record a
photon at time ``t`` are those with no recorded event in ``[t - tau, t)``; the recorded count
at ``t`` divided by that live share is an unbiased estimate of the photon rate there. Both
come from the recorded events alone: every event blinds one channel of its shot for ``tau``.

Heights, not times, are what the detector histograms: a height drop ``dz`` along a beam of
vertical direction component ``u_z`` is a time ``2 n_air dz / (c |u_z|)``, so the dead time
spans ``tau c |u_z| / (2 n_air)`` metres of height below each event.
"""

from __future__ import annotations

import numpy as np

from pipeline import optics

__all__ = [
    "event_heights_m",
    "dead_height_m",
    "event_live_fraction",
    "bin_live_fraction",
    "surface_pileup_pe",
    "MIN_LIVE_FRACTION",
]

#: live share below which a rate is not estimated (its correction would be 1 / 0): the
#: corrected counts are capped at this many times the recorded ones
MIN_LIVE_FRACTION = 0.02


def event_heights_m(offsets, times_s, origin_m, direction, n_air):
    """Each event's shot and its height on the shot's measured beam (no refraction).

    Parameters
    ----------
    offsets : (n_shots + 1,) int
        Events of shot ``i`` are ``times_s[offsets[i]:offsets[i + 1]]``.
    times_s : (n_events,) float
        Event times after emission, seconds.
    origin_m, direction : (n_shots, 3) float
        Measured laser position and unit beam direction of each shot.
    n_air : float
        Phase index of air (range ``r = c t / (2 n_air)``).

    Returns
    -------
    shot : (n_events,) int64
    z_m : (n_events,) float64
    """
    shot = np.repeat(np.arange(origin_m.shape[0]), np.diff(offsets))
    r = optics.SPEED_OF_LIGHT_M_S * np.asarray(times_s) / (2.0 * n_air)
    return shot, origin_m[shot, 2] + r * direction[shot, 2]


def dead_height_m(dead_time_s: float, n_air: float, direction_z: np.ndarray) -> np.ndarray:
    """Height below an event over which its channel is blind.

    Parameters
    ----------
    dead_time_s : float
        Dead time per channel (the detector's datasheet), seconds.
    n_air : float
        Phase index of air.
    direction_z : (n,) float
        Vertical component of each event's measured unit beam direction.

    Returns
    -------
    (n,) float
        ``dead_time_s c |u_z| / (2 n_air)``, metres.
    """
    return dead_time_s * optics.SPEED_OF_LIGHT_M_S * np.abs(direction_z) / (2.0 * n_air)


def event_live_fraction(window, z_m, tau_h_m, shots_per_window, n_channels=1):
    """Share of a window's shot-channels live at each event's own height.

    Parameters
    ----------
    window : (n_events,) int
        Window of each event.
    z_m : (n_events,) float
        Height of each event.
    tau_h_m : (n_events,) float
        Height span of the dead time below each event (:func:`dead_height_m`).
    shots_per_window : (n_windows,) int
        Shots of each window.
    n_channels : int
        Channels per beam, each blinded by its own events.

    Returns
    -------
    (n_events,) float
        ``1 - m / (n_shots n_channels)``, ``m`` the window's events in ``(z, z + tau_h]``
        (each blinded one channel at ``z``), floored at :data:`MIN_LIVE_FRACTION`.
    """
    if z_m.size == 0:
        return np.ones(0)
    # events sorted by window, then height: a window's events above z are a contiguous run
    span = float(z_m.max() - z_m.min()) + float(np.max(tau_h_m)) + 1.0
    key = window.astype(np.float64) * span + (z_m - z_m.min())
    order = np.sort(key)
    above = np.searchsorted(order, key + tau_h_m, side="right") - np.searchsorted(
        order, key, side="right"
    )
    n_live = np.maximum(shots_per_window[window], 1) * max(int(n_channels), 1)
    return np.maximum(1.0 - above / n_live, MIN_LIVE_FRACTION)


def bin_live_fraction(ev_win, z_m, tau_h_m, z0_m, bin_m, n_bins, shots_per_window, n_channels=1):
    """Mean live share of each window's height bins.

    Parameters
    ----------
    ev_win : (n_events,) int
        Window of each event.
    z_m, tau_h_m : (n_events,) float
        Height of each event and the height span of its dead time.
    z0_m : float
        Lower edge of bin 0; bins are ``[z0 + k bin_m, z0 + (k + 1) bin_m)``.
    bin_m : float
        Bin height.
    n_bins : int
        Bins per window.
    shots_per_window : (n_windows,) int
        Shots of each window.
    n_channels : int
        Channels per beam.

    Returns
    -------
    (n_windows, n_bins) float
        ``1 - D / (n_shots n_channels)``, ``D`` the dead shot-channel share of the bin: each
        event adds the overlap of its blind interval ``[z - tau_h, z)`` with the bin, in bins.
        Floored at :data:`MIN_LIVE_FRACTION`.
    """
    n_win = shots_per_window.size
    dead = np.zeros(n_win * n_bins)
    if z_m.size:
        lo, hi = (z_m - tau_h_m - z0_m) / bin_m, (z_m - z0_m) / bin_m  # in bin units
        k_hi = np.floor(hi).astype(np.int64)
        # a blind interval covers at most ceil(tau_h / bin) + 1 bins: loop over that handful
        for j in range(int(np.ceil(float(np.max(hi - lo)))) + 2):
            k = k_hi - j
            overlap = np.clip(np.minimum(hi, k + 1.0) - np.maximum(lo, k), 0.0, 1.0)
            ok = (overlap > 0) & (k >= 0) & (k < n_bins)
            dead += np.bincount(
                ev_win[ok] * n_bins + k[ok], weights=overlap[ok], minlength=n_win * n_bins
            )
    n_live = np.maximum(shots_per_window, 1)[:, None] * max(int(n_channels), 1)
    return np.maximum(1.0 - dead.reshape(n_win, n_bins) / n_live, MIN_LIVE_FRACTION)


def surface_pileup_pe(shot, window, b, ev_win, s_box, n, n_win, n_channels):
    """Surface photoelectrons per shot and channel of each window, from its pile-up.

    A channel records at most one event per dead time, so of an echo shorter than it each
    shot-channel keeps only whether it fired: with ``λ`` photoelectrons per channel, a shot
    (``N`` channels) has an event in the surface box with probability ``1 − exp(−N λ)``.
    Inverted on the window's share ``p`` of such shots (capped at ``1 − 1/(2 S)`` of ``S``
    shots, where ``λ`` stops being measurable): ``λ = −ln(1 − p) / N``. Background events in
    the box count too (a few per cent at most: the box spans a few ns).
    """
    in_box = (b >= s_box[0][ev_win]) & (b <= s_box[1][ev_win])
    hit = np.bincount(shot[in_box], minlength=n) > 0
    shots = np.maximum(np.bincount(window, minlength=n_win), 1)
    p = np.bincount(window[hit], minlength=n_win) / shots
    p = np.minimum(p, 1.0 - 0.5 / shots)
    return -np.log1p(-p) / max(int(n_channels), 1)
