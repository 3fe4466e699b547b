"""Maximum-likelihood height of a piled-up echo under dead time (measured data only).

Why
---
A one-channel photon counter with a dead time longer than the echo records at most the first
photon of a bright surface echo per shot. The live-time (Coates) correction
(:mod:`pipeline.process.photon_livetime`) divides the recorded counts by the share of
shot-channels still live; it is unbiased only while that share stays measurable. At a calm or
nadir water surface a shot sees 10-40 photoelectrons: every channel has fired by about one
sigma before the echo's centre, the live share there is ``exp(-10)`` or less, the later half of
the echo is never seen and the corrected centroid lies early (high) by ~1 pulse sigma (3-5 cm
of range on the suite's photon scenes, i.e. seabed depths 2-4 cm too deep). A bright shallow
seabed (a few photoelectrons per shot) piles up the same way and comes out shallow.

What is still measured is the echo's leading edge, and the system's pulse shape is known
(processing's assumption: the instrument's system response, a Gaussian of
``system_fwhm_s``). The recorded events of a non-paralyzable counter are a Poisson process of
intensity ``L(z) r(z)``: ``r`` the photon rate per shot-channel, ``L`` the number of
shot-channels live at ``z`` (known from the recorded events themselves: each blinds its
channel for the dead time below it). Its log-likelihood (Snyder & Miller 1991, "Random Point
Processes in Time and Space", ch. 7; the same likelihood as the photon posteriors) is

    ln Λ = Σ_i ln r(z_i) - ∫ L(z) r(z) dz,     r(z) = A φ_σ(z - z0) + β,

with ``β`` the window's background (for a bottom: the water column's local level). For each
candidate ``z0`` the amplitude ``A`` is solved by the EM fixed point
``A ← Σ_i A φ_i / (A φ_i + β) / ∫ L φ``; the ``z0`` of largest likelihood (a grid of σ/10,
refined by a parabola) is the echo's height. Without pile-up ``L`` is
constant and this is an ordinary Gaussian fit, so weak echoes keep their centroid's answer.

Model limits: one Gaussian of the system width (an echo widened by waves, a seabed sloping
along the window or forward scattering is fitted narrower: a piled-up one then still lies a
little early); the water-column return that starts under the surface is left out of the model
and of most of the fitted span (which ends 4 σ below the first guess); a bottom's span stops
at the surface's echo, a surface's at the bottom's.
"""

from __future__ import annotations

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S

__all__ = ["echo_height_ml", "surface_and_bottom_ml"]

#: candidate echo heights: the first guess ± this many sigmas (the Coates centroid of a
#: saturated echo lies up to ~1.5 σ high)
SEARCH_SIGMAS = 3.0
#: fitted span: from this many sigmas above the highest candidate...
SPAN_ABOVE_SIGMAS = 3.0
#: ... to this many below the lowest (past the pulse: the water column starts there)
SPAN_BELOW_SIGMAS = 1.0
#: candidate step and exposure grid step, in sigmas (the parabola refines between candidates)
STEP_SIGMAS = 0.1
#: windows fitted at once (memory: windows x candidates x events)
BATCH_WINDOWS = 32
#: EM iterations of the amplitude per candidate
EM_ITERATIONS = 25
#: fewest events in the span for a fit (fewer: the first guess stands)
MIN_EVENTS = 10


def _live_count(ev_win, z_m, tau_h_m, grid_win, grid_z_m):
    """Recorded events of each grid point's window in ``(z, z + tau_h]`` (channels blind there).

    Keys are ``window + i z`` as complex numbers, which sort by window, then height, exactly:
    no rounding that depends on which windows share the batch (so any chunking agrees).
    """
    order = np.sort(ev_win.astype(np.float64) + 1j * z_m)
    win = grid_win.astype(np.float64)
    return np.searchsorted(order, win + 1j * (grid_z_m + tau_h_m), side="right") - np.searchsorted(
        order, win + 1j * grid_z_m, side="right"
    )


def _event_sum(x: np.ndarray) -> np.ndarray:
    """Sum over the last (padded events) axis, in event order whatever the padding.

    ``np.sum`` sums pairwise in blocks set by the axis length, so the padded width (the busiest
    window of the batch) would change the last bits; a running sum does not.
    """
    return np.cumsum(x, axis=-1)[..., -1]


def echo_height_ml(
    ev_win: np.ndarray,
    z_m: np.ndarray,
    z_guess_m: np.ndarray,
    fit: np.ndarray,
    sigma_h_m: np.ndarray,
    tau_h_m: float | np.ndarray,
    n_live: np.ndarray,
    background_per_m: np.ndarray,
    floor_m: np.ndarray | None = None,
    ceiling_m: np.ndarray | None = None,
) -> np.ndarray:
    """Maximum-likelihood height of one echo per window (see module).

    Parameters
    ----------
    ev_win : (n_events,) int
        Window of each recorded event.
    z_m : (n_events,) float
        Height of each event on its shot's measured beam.
    z_guess_m : (n_windows,) float
        First guess of each echo's height (the live-time corrected centroid).
    fit : (n_windows,) bool
        Windows to fit (those with the echo).
    sigma_h_m : (n_windows,) float
        The system response's sigma as a height, per window (> 0).
    tau_h_m : float or (n_windows,) float
        Height span of the dead time below an event (:func:`~pipeline.process.photon_livetime.
        dead_height_m`), one for all or per window.
    n_live : (n_windows,) float
        Shot-channels of each window (shots times channels per beam).
    background_per_m : (n_windows,) float
        Background photon rate per shot-channel and metre of height.
    floor_m, ceiling_m : (n_windows,) float, optional
        Heights the fitted span stays within (another echo of the window lies past them).

    Returns
    -------
    (n_windows,) float
        The fitted heights; the first guess where the window is not fitted or has fewer than
        :data:`MIN_EVENTS` events in its span.
    """
    out = np.asarray(z_guess_m, dtype=np.float64).copy()
    tau_w = np.broadcast_to(np.asarray(tau_h_m, dtype=np.float64), out.shape)
    todo = np.flatnonzero(fit & (sigma_h_m > 0))
    if todo.size == 0 or z_m.size == 0:
        return out
    # events sorted by window, so each batch takes its windows' events as one slice
    order = np.argsort(ev_win, kind="stable")
    ev_win, z_m = ev_win[order], z_m[order]
    top = out + (SEARCH_SIGMAS + SPAN_ABOVE_SIGMAS) * sigma_h_m
    bot = out - (SEARCH_SIGMAS + SPAN_BELOW_SIGMAS) * sigma_h_m
    if ceiling_m is not None:
        top = np.minimum(top, ceiling_m)
    if floor_m is not None:
        bot = np.maximum(bot, floor_m)
    # a span squeezed between two echoes holds too little of this one's pulse for a fit
    todo = todo[top[todo] - bot[todo] >= 2.0 * sigma_h_m[todo]]
    for lo in range(0, todo.size, BATCH_WINDOWS):
        idx = todo[lo : lo + BATCH_WINDOWS]
        first, last = np.searchsorted(ev_win, [idx[0], idx[-1] + 1])
        # the blind spans come from every event of these windows
        ev = (ev_win[first:last], z_m[first:last])
        out[idx] = _fit_batch(*ev, out[idx], idx, sigma_h_m[idx], tau_w[idx], (bot[idx], top[idx]),
                              n_live[idx], background_per_m[idx])  # fmt: skip
    return out


def _fit_batch(ev_win, z_m, guess, idx, sig, tau_h_m, span, n_live, background_per_m):
    """Fitted heights of windows ``idx`` (ascending), within ``span = (bottom, top)``.

    Per-window arrays are those of ``idx``; the events are those of the windows ``idx[0]`` to
    ``idx[-1]`` (see :func:`echo_height_ml`).
    """
    if z_m.size == 0:
        return guess
    bot, top = span
    # the windows' events inside their spans, padded to (n_fit, m)
    row = np.full(int(max(ev_win.max(), idx.max())) + 1, -1, dtype=np.int64)
    row[idx] = np.arange(idx.size)
    r_ev = row[ev_win]
    sel = r_ev >= 0
    sel[sel] &= (z_m[sel] <= top[r_ev[sel]]) & (z_m[sel] >= bot[r_ev[sel]])
    r_sel, z_sel = r_ev[sel], z_m[sel]
    n_ev = np.bincount(r_sel, minlength=idx.size)
    order = np.argsort(r_sel, kind="stable")
    r_sel, z_sel = r_sel[order], z_sel[order]
    pos = np.arange(r_sel.size) - np.repeat(np.cumsum(n_ev) - n_ev, n_ev)
    m = max(int(n_ev.max()), 1)
    ev = np.full((idx.size, m), np.nan)
    ev[r_sel, pos] = z_sel
    valid = np.isfinite(ev)
    # exposure: live shot-channels on a grid over each span (every event of the window blinds,
    # whether in the span or not)
    n_grid = int(np.ceil((2 * SEARCH_SIGMAS + SPAN_ABOVE_SIGMAS + SPAN_BELOW_SIGMAS) / STEP_SIGMAS))
    dz = (top - bot) / n_grid
    g = bot[:, None] + (np.arange(n_grid) + 0.5)[None, :] * dz[:, None]
    dead = _live_count(ev_win, z_m, np.repeat(tau_h_m, n_grid), np.repeat(idx, n_grid), g.ravel())
    live = np.maximum(n_live[:, None] - dead.reshape(idx.size, n_grid), 0.0)
    # candidates (n_fit, n_cand)
    n_cand = int(round(2 * SEARCH_SIGMAS / STEP_SIGMAS)) + 1
    offs = np.linspace(-SEARCH_SIGMAS, SEARCH_SIGMAS, n_cand)
    z0 = guess[:, None] + offs[None, :] * sig[:, None]
    inv = 1.0 / (sig * np.sqrt(2.0 * np.pi))
    # Gaussian density of each event / grid point under each candidate: (n_fit, n_cand, m)
    phi = inv[:, None, None] * np.exp(
        -0.5 * ((np.nan_to_num(ev)[:, None, :] - z0[:, :, None]) / sig[:, None, None]) ** 2
    )
    phi = np.where(valid[:, None, :], phi, 0.0)
    phi_g = inv[:, None, None] * np.exp(
        -0.5 * ((g[:, None, :] - z0[:, :, None]) / sig[:, None, None]) ** 2
    )
    expo = np.maximum(np.sum(live[:, None, :] * phi_g, axis=2) * dz[:, None], 1e-300)
    beta = np.maximum(background_per_m, 0.0)[:, None, None]
    amp = np.maximum(n_ev[:, None] - beta[:, :, 0] * (live.sum(axis=1) * dz)[:, None], 1.0)
    amp = amp / expo
    for _ in range(EM_ITERATIONS):
        share = amp[:, :, None] * phi / np.maximum(amp[:, :, None] * phi + beta, 1e-300)
        amp = np.maximum(_event_sum(np.where(valid[:, None, :], share, 0.0)), 1e-12) / expo
    rate = np.where(valid[:, None, :], amp[:, :, None] * phi + beta, 1.0)
    loglik = _event_sum(np.log(np.maximum(rate, 1e-300))) - amp * expo
    best = np.argmax(loglik, axis=1)
    # parabola through the best candidate and its neighbours (not at the grid's edge)
    inner = (best > 0) & (best < n_cand - 1)
    b = np.clip(best, 1, n_cand - 2)
    rows = np.arange(idx.size)
    y0, y1, y2 = loglik[rows, b - 1], loglik[rows, b], loglik[rows, b + 1]
    curv = y0 - 2.0 * y1 + y2
    frac = np.where(inner & (curv < 0), 0.5 * (y0 - y2) / np.where(curv < 0, curv, -1.0), 0.0)
    z_best = guess + (offs[best] + np.clip(frac, -0.5, 0.5) * (offs[1] - offs[0])) * sig
    return np.where(n_ev >= MIN_EVENTS, z_best, guess)


def surface_and_bottom_ml(events, window, direction, pulse_sigma_s, n_air, n_channels, found):
    """Maximum-likelihood heights of each window's surface and bottom (:func:`echo_height_ml`).

    Parameters
    ----------
    events : tuple
        ``(ev_win, z_m, tau_h_m)``: window, height and dead-time height span of each event,
        ``(n_events,)`` each.
    window : (n_shots,) int
        Window of each shot.
    direction : (n_shots, 3) float
        Measured unit beam direction of each shot.
    pulse_sigma_s : float
        Sigma of the system response (processing's assumption of the instrument).
    n_air : float
        Phase index of air.
    n_channels : int
        Channels per beam.
    found : dict of str to (n_windows,) arrays
        ``z_s``, ``z_b`` (first guesses), ``has_s``, ``has_b``, ``bg_s``, ``bg_b`` (background
        and the column's local level, counts per shot-channel and metre), ``edge_s`` (lowest
        height of the surface's box) and ``edge_b`` (highest of the bottom's).

    Returns
    -------
    z_s, z_b : (n_windows,) float
        Each echo's span stops at the other's box; the background above the surface and the
        column's local level at the bottom are the ``β`` of their fits.
    """
    ev_win, z_m, tau_h = events
    n_win = found["z_s"].size
    shots = np.maximum(np.bincount(window, minlength=n_win), 1)
    n_live = shots * max(int(n_channels), 1)
    u_z = np.bincount(window, weights=np.abs(direction[:, 2]), minlength=n_win) / shots
    sig_h = pulse_sigma_s * SPEED_OF_LIGHT_M_S * u_z / (2.0 * n_air)
    # each window's own dead-time span (the mean over its events, summed in event order): a
    # statistic over the chunk's events would tie a window's fit to its chunk-mates
    n_ev = np.bincount(ev_win, minlength=n_win)
    tau_sum = np.bincount(ev_win, weights=np.broadcast_to(tau_h, np.shape(ev_win)), minlength=n_win)
    tau = tau_sum / np.maximum(n_ev, 1)
    fit = (ev_win, z_m)
    floor = np.where(found["has_b"], found["edge_b"], -np.inf)
    z_s = echo_height_ml(*fit, found["z_s"], found["has_s"], sig_h, tau, n_live, found["bg_s"],
                         floor_m=floor)  # fmt: skip
    z_b = echo_height_ml(*fit, found["z_b"], found["has_b"], sig_h, tau, n_live, found["bg_b"],
                         ceiling_m=found["edge_s"])  # fmt: skip
    return z_s, z_b
