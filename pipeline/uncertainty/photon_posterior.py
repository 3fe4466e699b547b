"""Depth posteriors of photon-counting windows: the events kept and their histograms.

A photon-counting survey records no waveform per pulse: its detector accumulates the events
of ``shots_per_window`` consecutive shots into one height histogram
(:mod:`pipeline.process.detect_photons`) and reports one surface and one bottom per window.
The posterior does the same, with the waveform model's Poisson law
(:mod:`pipeline.uncertainty.waveform_model`, ``receiver="photon_counting"``, validated in
``benchmarks/RESULTS_posterior.md``):

1. The chunk loop keeps the events of a fixed share of the windows (:func:`keep_windows`,
   chosen by a hash of the window number, so the chunking cannot change the choice; chunks
   hold whole windows): their heights on their own measured beams and the height span of each
   event's dead time (:class:`KeptPhotons`).
2. The posterior stage samples one shot per kept window (the shot nearest the window's
   centre): the window's events are histogrammed in round-trip time along that shot's
   measured beam (:func:`window_histograms`), one sample per detector height bin
   (``process.photon_detect.bin_m``, its time at nadir: :func:`photon_system`), from
   ``LEAD_S`` (plus a share of the in-water time) before the detected surface to ``TAIL_S``
   (plus a share) after the detected bottom, so the leading samples are background only, as
   the sampler's start expects.
3. Dead time, as the detector models it (:mod:`pipeline.process.photon_livetime`): each sample
   has its live share ``L`` of the window's shot-channels (every recorded event blinds one
   channel for the dead time). The recorded counts of a non-paralyzable counter are the
   Poisson counts of the rate over its live exposure: the likelihood of a point process
   thinned by its own history is ``prod lambda*(t_i) exp(-int lambda*)`` with ``lambda*`` the
   rate where the channel is live (Snyder & Miller 1991, *Random Point Processes in Time and
   Space*, ch. 7), binned: ``y ~ Poisson(L mu)``. The sampler takes ``L`` as the
   ``exposure`` of each sample (:class:`~pipeline.uncertainty.posterior_target.PulseBatch`).

The posterior's model holds the whole window as one echo: the spread of the seabed under the
window's shots widens its bottom echo (the bottom width is a nuisance parameter) and is the
TPU's ``window_footprint`` term, which the nuisance marginalisation adds
(:func:`~pipeline.uncertainty.survey_posterior.nuisance_depth_sigma_m`).

Budget: ``process.posterior_pulses_per_km2`` and ``posterior_min_pulses`` count windows here
(one posterior each: the window's shots share one measurement).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.photon_carry import detrended_heights
from pipeline.process.photon_livetime import (
    MIN_LIVE_FRACTION,
    dead_height_m,
    event_heights_m,
)
from pipeline.process.photon_windows import PhotonWindows
from pipeline.uncertainty.photon_exposure import (
    ReferenceRate,
    reference_rate,
    weighted_live_fraction,
)
from pipeline.uncertainty.posterior_selection import kept_for_posterior
from pipeline.uncertainty.waveform_model import WaveformSystem, in_water_delay_s

__all__ = [
    "at_detected_surface",
    "KeptPhotons",
    "keep_windows",
    "photon_system",
    "window_candidates",
    "window_histograms",
    "photon_starts",
    "LEAD_S",
    "TAIL_S",
]

#: Histogram time before the detected surface (plus ``SPAN_SHARE`` of the in-water time): the
#: sampler's start reads its noise floor from the leading tenth of the samples, which must be
#: background only; 20 ns is 3 m of height, past the surface echo's tails.
LEAD_S = 20e-9
#: Histogram time after the detected bottom (plus ``SPAN_SHARE``): room for the posterior's
#: bottom below the detector's (its prior keeps the bottom inside the histogram).
TAIL_S = 20e-9
#: Share of the surface-to-bottom time added before and after (keeps the lead above a tenth
#: of the histogram at any depth).
SPAN_SHARE = 0.25


@dataclass(frozen=True)
class KeptPhotons:
    """Events of the windows the chunk loop kept for posteriors.

    Attributes
    ----------
    window : (k,) int64
        Window key (:mod:`pipeline.process.photon_windows`).
    n_shots : (k,) int64
        Shots of each window.
    offsets : (k + 1,) int64
        Events of window ``i`` are rows ``offsets[i]:offsets[i + 1]``.
    z_m : (n,) float64
        Height of each event on its own measured beam (range at the air index).
    tau_h_m : (n,) float64
        Height span of each event's dead time below it.
    """

    window: np.ndarray
    n_shots: np.ndarray
    offsets: np.ndarray
    z_m: np.ndarray
    tau_h_m: np.ndarray

    @classmethod
    def concatenate(cls, parts: list[KeptPhotons]) -> KeptPhotons | None:
        """One set from the chunks' (None when no chunk kept any)."""
        if not parts:
            return None
        starts = np.cumsum([0] + [p.z_m.size for p in parts[:-1]])
        offsets = np.concatenate(
            [[0]] + [p.offsets[1:] + s for p, s in zip(parts, starts, strict=True)]
        )
        return cls(
            window=np.concatenate([p.window for p in parts]),
            n_shots=np.concatenate([p.n_shots for p in parts]),
            offsets=offsets.astype(np.int64),
            z_m=np.concatenate([p.z_m for p in parts]),
            tau_h_m=np.concatenate([p.tau_h_m for p in parts]),
        )


def keep_windows(
    pulse_id: np.ndarray,
    offsets: np.ndarray,
    times_s: np.ndarray,
    origin_m: np.ndarray,
    direction: np.ndarray,
    n_air: float,
    windows: PhotonWindows,
    dead_time_s: float,
    fraction: float,
    seed: int,
    detections=None,
    settings=None,
) -> KeptPhotons | None:
    """The events of a chunk's windows kept for posteriors (None when none is kept).

    Parameters
    ----------
    pulse_id : (n_shots,) int
        Global shot numbers (the chunk holds whole windows).
    offsets : (n_shots + 1,) int
        Events of shot ``i`` are ``times_s[offsets[i]:offsets[i + 1]]``.
    times_s : (n_events,) float
        Event times after emission.
    origin_m, direction : (n_shots, 3) float
        Measured laser position and unit beam of each shot.
    n_air : float
        Phase index of air.
    windows : PhotonWindows
        How the detector grouped the shots.
    dead_time_s : float
        Dead time per channel (the datasheet's).
    fraction : float
        Share of the windows kept (:func:`kept_for_posterior` of the window number).
    seed : int
    detections, settings : optional
        The chunk's detections and the detector's settings: a scan's cell windows keep their
        events as the detector's second pass histogrammed them (the seabed's slope taken
        out below the surface: :func:`~pipeline.process.photon_carry.detrended_heights`).
    """
    if fraction <= 0.0 or pulse_id.size == 0:
        return None
    win = windows.of(pulse_id, origin_m, direction)
    uniq, n_shots = np.unique(win, return_counts=True)
    keep = uniq[kept_for_posterior(uniq, fraction, seed)]
    if keep.size == 0:
        return None
    shot, z = event_heights_m(offsets, times_s, origin_m, direction, n_air)
    if detections is not None:
        z = detrended_heights(
            z, shot, detections, windows, pulse_id, origin_m, direction, n_air, settings
        )
    tau_h = dead_height_m(dead_time_s, n_air, direction[shot, 2])
    ev_win = win[shot]
    sel = np.isin(ev_win, keep)
    order = np.argsort(ev_win[sel], kind="stable")  # events grouped by window
    counts = np.bincount(np.searchsorted(keep, ev_win[sel]), minlength=keep.size)
    return KeptPhotons(
        window=keep,
        n_shots=n_shots[np.isin(uniq, keep)].astype(np.int64),
        offsets=np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
        z_m=z[sel][order],
        tau_h_m=tau_h[sel][order],
    )


def photon_system(bin_m: float, n_air: float, pulse_fwhm_s: float, group_index: float):
    """The posterior's instrument: Poisson counts, one sample per detector bin.

    The sample interval is the round-trip time of one height bin at nadir
    (``2 n_air bin_m / c``); off nadir a bin of time spans less height, which the histogram
    of :func:`window_histograms` follows.
    """
    return WaveformSystem(
        sample_interval_s=2.0 * n_air * bin_m / SPEED_OF_LIGHT_M_S,
        pulse_fwhm_s=pulse_fwhm_s,
        group_index=group_index,
        receiver="photon_counting",
    )


def window_candidates(
    point_pulse_id: np.ndarray,
    kept: KeptPhotons,
    windows: PhotonWindows,
    point_window: np.ndarray | None = None,
    point_xy_m: np.ndarray | None = None,
):
    """Rows of the points that may be sampled: one per kept window, the shot nearest its centre.

    Parameters
    ----------
    point_pulse_id : (n,) int
        Pulse of each bathymetric point.
    kept : KeptPhotons
    windows : PhotonWindows
    point_window : (n,) int64, optional
        Each point's window (:meth:`PhotonWindows.of_points`); needed with cells.
    point_xy_m : (n, 2) float, optional
        Each point's position; needed with cells, whose centre is the mean of its points'
        (consecutive shots' centre is the middle shot).

    Returns
    -------
    (m,) int64
        Point rows, sorted, at most one per kept window.
    """
    pid = np.asarray(point_pulse_id, dtype=np.int64)
    spw = windows.shots_per_window
    win = windows.of(pid) if point_window is None else np.asarray(point_window)
    cand = np.flatnonzero(np.isin(win, kept.window))
    if cand.size == 0:
        return cand
    if windows.cell_m > 0.0:
        _, inv = np.unique(win[cand], return_inverse=True)
        xy = np.asarray(point_xy_m, dtype=np.float64)[cand]
        cnt = np.bincount(inv).astype(np.float64)
        mean = np.column_stack([np.bincount(inv, weights=xy[:, k]) / cnt for k in range(2)])
        off_centre = np.hypot(*(xy - mean[inv]).T)
    else:
        off_centre = np.abs(pid[cand] - (win[cand] * spw + spw // 2))
    order = np.lexsort((pid[cand], off_centre, win[cand]))
    _, first = np.unique(win[cand][order], return_index=True)
    return np.sort(cand[order][first])


def window_histograms(
    kept: KeptPhotons,
    window: np.ndarray,
    origin_z_m: np.ndarray,
    direction_z: np.ndarray,
    t_surface_s: np.ndarray,
    t_bottom_s: np.ndarray,
    system: WaveformSystem,
    n_air: float,
    n_channels: int = 1,
) -> tuple[list[np.ndarray], list[np.ndarray], np.ndarray]:
    """Recorded counts and live shares of kept windows in time along a shot's own beam.

    Parameters
    ----------
    kept : KeptPhotons
    window : (p,) int
        Window of each sampled shot (one of ``kept.window``).
    origin_z_m, direction_z : (p,) float
        Measured laser height and vertical beam component of each sampled shot.
    t_surface_s, t_bottom_s : (p,) float
        The detector's surface and bottom round-trip times of the shot (the crop).
    system : WaveformSystem
        :func:`photon_system` (its sample interval).
    n_air : float
    n_channels : int
        Channels per beam (the datasheet's).

    Returns
    -------
    samples : list of (m_i,) ndarray
        Recorded events per sample: sample ``j`` holds the events whose time along the shot's
        beam, ``2 n_air (z_origin - z) / (c |u_z|)``, lies within half a sample of
        ``t0 + j dt``.
    exposure : list of (m_i,) ndarray
        Live share of each sample over the window's events, weighted by the window's echoes
        within the sample (:mod:`pipeline.uncertainty.photon_exposure`), in (0, 1].
    t0_s : (p,) ndarray
        Round-trip time of sample 0's centre.
    """
    dt = system.sample_interval_s
    c = SPEED_OF_LIGHT_M_S
    span = np.maximum(np.asarray(t_bottom_s) - np.asarray(t_surface_s), 0.0)
    t0 = np.asarray(t_surface_s) - LEAD_S - SPAN_SHARE * span
    t_end = np.asarray(t_bottom_s) + TAIL_S + SPAN_SHARE * span
    samples, exposure = [], []
    for i, w in enumerate(np.asarray(window, dtype=np.int64)):
        k = int(np.flatnonzero(kept.window == w)[0])  # any chunk order
        ev = slice(kept.offsets[k], kept.offsets[k + 1])
        z, tau_h = kept.z_m[ev], kept.tau_h_m[ev]
        scale = 2.0 * n_air / (c * abs(float(direction_z[i])))  # s of round trip per m
        m = int(np.ceil((t_end[i] - t0[i]) / dt)) + 1
        t_ev = (origin_z_m[i] - z) * scale  # along this shot's beam
        j = np.floor((t_ev - t0[i]) / dt + 0.5).astype(np.int64)
        inside = (j >= 0) & (j < m)
        samples.append(np.bincount(j[inside], minlength=m).astype(np.float64))
        dead, n_live = tau_h * scale, int(kept.n_shots[k]) * max(int(n_channels), 1)
        # the plain mean share over each sample gives the rates the reference is read from;
        # the exposure is weighted by where the window's echoes put the light within each
        # sample (pipeline.uncertainty.photon_exposure): the plain mean credits a piled-up
        # echo's sample with the exposure after its events
        plain = weighted_live_fraction(t_ev, dead, t0[i], dt, m, n_live, ReferenceRate.uniform())
        ref = reference_rate(
            samples[-1], np.maximum(plain, MIN_LIVE_FRACTION), t0[i], t_surface_s[i],
            t_bottom_s[i], dt, system.pulse_sigma_s,
        )  # fmt: skip
        exposure.append(weighted_live_fraction(t_ev, dead, t0[i], dt, m, n_live, ref))
    return samples, exposure, t0


def photon_starts(
    samples: list[np.ndarray],
    exposure: list[np.ndarray],
    t0_s: np.ndarray,
    t_surface_s: np.ndarray,
    t_bottom_s: np.ndarray,
    cos_water: np.ndarray,
    system: WaveformSystem,
) -> np.ndarray:
    """Starting parameters from the photon detector's own surface and bottom (P, 9).

    The full-waveform detector the sampler starts from otherwise takes a lone background
    photon for a return (a sparse histogram's noise floor is 0); the photon detector's
    window detections (the same events) are the survey's. Areas are the live-time corrected
    counts within 2 samples of each return less the background (the mean corrected count of
    the leading ``LEAD_S``), the column the corrected counts between them, ``k = 0.1`` 1/m,
    echo widths those of the system response; the sampler's mode search refines them.
    """
    dt = system.sample_interval_s
    out = np.zeros((len(samples), 9))
    for i, (y, e) in enumerate(zip(samples, exposure, strict=True)):
        # the rates as processing caps them (a weighted share can be ~0 just after an echo)
        rate = y / np.maximum(e, MIN_LIVE_FRACTION)
        i_s = int(round((t_surface_s[i] - t0_s[i]) / dt))
        i_b = int(round((t_bottom_s[i] - t0_s[i]) / dt))
        lead = rate[: max(int(LEAD_S / dt), 4)]
        bg = max(float(lead.mean()), 1e-3)

        def area(j, rate=rate, bg=bg):
            return max(float(rate[max(j - 2, 0) : j + 3].sum()) - 5.0 * bg, 1.0)

        col = float(rate[i_s + 3 : max(i_b - 2, i_s + 3)].sum()) - bg * max(i_b - i_s - 5, 0)
        tau = max(t_bottom_s[i] - t_surface_s[i], dt)
        depth = tau / float(in_water_delay_s(1.0, cos_water[i], system.group_index))
        out[i] = [
            depth,
            (t_surface_s[i] - t0_s[i]) * 1e9,
            np.log(area(i_s)),
            np.log(max(col, 1.0)),
            np.log(area(i_b)),
            np.log(0.1),
            bg,
            0.0,
            0.0,
        ]
    return out


def at_detected_surface(surface, returns):
    """The rows' fitted surface with each plane moved to its own detected surface return.

    A photon window's sea is read where its detection put it: the window's height, carried
    along the plane's slope to the shot (``WaterSurface.own_shift_m``), and the depth below
    that plane (``sea_correlation`` None: the plane alone), as the processing reads it where
    the sea correlation holds the own echo's offset whole. The posterior's own sample of the
    surface time then moves the sounding only through the in-water path, as when the planes
    were fitted shot by shot (each through its window's one height). Read below the sampled
    surface instead, the depths of suite tuning 13 and 14 and held-out 9 posteriors moved 2-3
    cm deep (their 68 % coverage 67, 100, 100 % -> 38, 82, 17 %) while the soundings' did not.
    That was measured with each sample's plain mean live share, which put a piled-up surface
    ~0.16 ns early (:mod:`pipeline.uncertainty.photon_exposure`); the weighted
    share removes that difference, and this reading was kept as it is.

    Parameters
    ----------
    surface : WaterSurface
        The rows' fitted surface (:func:`~pipeline.uncertainty.seabed_posterior.take_surface`).
    returns : DetectedReturns
        The same rows' detections.

    Returns
    -------
    WaterSurface
    """
    own = returns.has_surface & surface.is_water
    r_s = SPEED_OF_LIGHT_M_S * returns.t_surface_s / (2.0 * surface.air_index)
    if surface.own_shift_m is not None:
        r_s = r_s + surface.own_shift_m
    r = np.where(own, r_s, surface.range_to_entry_m)
    entry = returns.origin_meas_m + returns.direction_meas * r[:, None]
    return dataclasses.replace(
        surface,
        entry_m=np.where(own[:, None], entry, surface.entry_m),
        range_to_entry_m=r,
        sea_correlation=None,
    )
