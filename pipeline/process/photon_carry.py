"""A scan's cell window's one bottom height carried to each shot along the seabed's slope.

A cell window (:mod:`pipeline.process.photon_windows`) detects one bottom height for shots
spread over its cell, ``cell_m`` across: over a seabed sloping by ``g`` each shot's own
seabed differs from the window's by ``g . (p_i - p_w)`` (``p`` where the beams meet the
datum ``z = 0``, ``p_w`` the window's mean), ``g L / sqrt(12)`` rms over a cell of side ``L``
(0.14 m over 10 m cells at a slope of 0.05; 0.5 m at 10°). The neighbouring windows of the
same slab measure that slope: each window's slope is the least-squares slope of its
neighbours' bottom heights about its own (a plane through the window's own height, so the
mean over its shots stays what the histogram measured), and each shot's bottom height moves
along it. The heights are the detector's (on the measured beam in air, before refraction), so
the slope is the apparent seabed's; across a cell and its neighbours the beams' angles change
little (an oscillating mirror's by ~1-2°), and the refraction correction then runs on each
shot's own beam as before.

Only windows of the same slab are neighbours, so the carry, like the windows, does not
depend on the chunking (chunks hold whole slabs). Where fewer than 3 neighbours with a bottom
lie within :data:`NEIGHBOUR_CELLS` cell sides, or they lie on a line, no slope is taken (the
shots keep the window's height).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.photon_windows import crossing_xy, slab_of

__all__ = [
    "NEIGHBOUR_CELLS",
    "MAX_SLOPE",
    "SLAB_APART_M",
    "detrended_heights",
    "neighbour_slopes",
    "second_pass",
]

#: Neighbouring windows within this many cell sides of a window's centre fit its slope.
NEIGHBOUR_CELLS = 2.5
#: Largest slope taken (tan 45°): a steeper fit is a false bottom among the neighbours.
MAX_SLOPE = 1.0
#: Neighbours searched per window, at most (a 2.5-cell radius holds ~20 cells).
_K = 24
#: Distance put between slabs in a neighbour search (beyond any radius): a window's
#: neighbours are its slab's whatever other slabs lie near.
SLAB_APART_M = 1.0e6


def neighbour_slopes(z_w, has_w, centre_xy, slab, cell_m):
    """Each window's seabed slope, from the bottom heights of its slab's neighbours.

    Parameters
    ----------
    z_w : (n_windows,) float
        Each window's detected bottom height (m; meaningless where ``has_w`` is False).
    has_w : (n_windows,) bool
        Windows with a bottom.
    centre_xy : (n_windows, 2) float
        Each window's mean of its shots' crossings of ``z = 0``.
    slab : (n_windows,) int
        Each window's slab (only windows of one slab are neighbours).
    cell_m : float
        The cells' side.

    Returns
    -------
    (n_windows, 2) float
        The slope of a plane through each window's own height fitted to its neighbours' (0
        where none is taken, module notes); a shot's bottom moves by ``slope . (xy - centre)``.
    """
    n_w = z_w.shape[0]
    slope = np.zeros((n_w, 2))
    rows = np.flatnonzero(has_w)
    if rows.size >= 4:
        # the slab as a third coordinate, farther than any radius: a window's neighbours are
        # its slab's whatever other slabs share the chunk (chunk-invariant)
        pts = np.column_stack([centre_xy[rows], slab[rows] * SLAB_APART_M])
        k = min(_K, rows.size)
        dist, nb = cKDTree(pts).query(pts, k=k, distance_upper_bound=NEIGHBOUR_CELLS * cell_m)
        ok = np.isfinite(dist) & (dist > 0.0)  # the window itself is not its own neighbour
        nb = np.where(ok, nb, 0)
        nbr = rows[nb]
        ok &= slab[nbr] == slab[rows][:, None]
        d = np.where(ok[:, :, None], centre_xy[nbr] - centre_xy[rows][:, None, :], 0.0)
        dz = np.where(ok, z_w[nbr] - z_w[rows][:, None], 0.0)
        # the slope of a plane through the window's own height: 2 x 2 normal equations
        a = np.einsum("wki,wkj->wij", d, d)
        b = np.einsum("wki,wk->wi", d, dz)
        det = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] ** 2
        # at least 3 neighbours, spread in both directions (not on a line): the smaller
        # eigenvalue of the offsets' scatter at least a quarter cell squared per neighbour
        tr = a[:, 0, 0] + a[:, 1, 1]
        small = 0.5 * (tr - np.sqrt(np.maximum(tr**2 - 4.0 * det, 0.0)))
        good = (ok.sum(axis=1) >= 3) & (small >= ok.sum(axis=1) * (0.25 * cell_m) ** 2)
        safe = np.where(good, det, 1.0)
        sx = (a[:, 1, 1] * b[:, 0] - a[:, 0, 1] * b[:, 1]) / safe
        sy = (a[:, 0, 0] * b[:, 1] - a[:, 0, 1] * b[:, 0]) / safe
        s = np.where(good[:, None], np.column_stack([sx, sy]), 0.0)
        s = np.where((np.hypot(s[:, 0], s[:, 1]) <= MAX_SLOPE)[:, None], s, 0.0)
        slope[rows] = s
    return slope


def second_pass(first, windows, ids, origin_m, direction, n_air, settings):
    """The second detection pass's ``(carry, split)``, from the first pass's detections.

    ``first`` holds the first pass's detections (``WaveformDetections``, one height per
    window); ``windows``, ``ids``, ``origin_m``, ``direction`` and ``n_air`` are the
    detector's (:func:`~pipeline.process.detect_photons.detect_photon_events`), ``settings``
    its settings.

    ``carry`` (n_shots,): each shot's bottom height over its window's, along the window's
    :func:`neighbour_slopes`; ``split`` (n_windows,): the height below which its events are
    de-trended (:func:`_split_m`).
    """
    keys_w, window = np.unique(windows.of(ids, origin_m, direction), return_inverse=True)
    n_win = keys_w.size
    _, z_b, has_b = _window_heights(first.t_bottom_s, first.has_bottom, window, n_win,
                                    origin_m, direction, n_air)  # fmt: skip
    _, z_s, has_s = _window_heights(first.t_surface_s, first.has_surface, window, n_win,
                                    origin_m, direction, n_air)  # fmt: skip
    xy = crossing_xy(origin_m, direction)
    cnt = np.maximum(np.bincount(window, minlength=n_win), 1)
    centre = np.column_stack(
        [np.bincount(window, weights=xy[:, k], minlength=n_win) / cnt for k in range(2)]
    )
    slope = neighbour_slopes(z_b, has_b, centre, slab_of(keys_w), windows.cell_m)
    carry = np.sum(slope[window] * (xy - centre[window]), axis=1)
    return carry, _split_m(z_s, has_s, windows, settings)


def _window_heights(t, has, window, n_win, origin_m, direction, n_air):
    """Shots' heights at times ``t`` on their beams, their windows' means over ``has``.

    ``(z (n_shots,), mean (n_windows,), any (n_windows,))``: the height of each shot, the mean
    over each window's shots with ``has`` (0 without), whether any has.
    """
    z = origin_m[:, 2] + SPEED_OF_LIGHT_M_S / (2.0 * n_air) * t * direction[:, 2]
    k = np.bincount(window, weights=has, minlength=n_win)
    mean = np.bincount(window, weights=np.where(has, z, 0.0), minlength=n_win)
    return z, mean / np.maximum(k, 1), k > 0


def _split_m(z_s, has_s, windows, settings):
    """Height below which a window's events are de-trended (:func:`second_pass`, notes).

    Halfway from the surface to the bottom search's top, and below the surface's centroid
    box (its echo's lower tail is not moved); ``-inf`` without a surface.
    """
    sep = max(settings.min_separation_m, windows.sea_band_m)
    box_m = (settings.centroid_bins + 1) * settings.bin_m
    return np.where(has_s, z_s - max(0.5 * sep, box_m), -np.inf)


def detrended_heights(z_ev, shot, detections, windows, ids, origin_m, direction, n_air, settings):
    """Event heights as the detector's second pass histogrammed them, ``(n_events,)``.

    For the kept windows' events of a posterior (:func:`~pipeline.uncertainty.
    photon_posterior.keep_windows`): below each cell window's surface (the split of
    :func:`second_pass`), an event moves by its shot's carry, which the detections hold as
    each shot's bottom height less its window's mean. Windows of consecutive shots: as given.
    """
    if windows.cell_m <= 0.0:
        return z_ev
    _, window = np.unique(windows.of(ids, origin_m, direction), return_inverse=True)
    n_win = int(window.max()) + 1
    z_b, mean_b, _ = _window_heights(detections.t_bottom_s, detections.has_bottom, window,
                                     n_win, origin_m, direction, n_air)  # fmt: skip
    _, z_s, has_s = _window_heights(detections.t_surface_s, detections.has_surface, window,
                                    n_win, origin_m, direction, n_air)  # fmt: skip
    carry = np.where(detections.has_bottom, z_b - mean_b[window], 0.0)
    split = _split_m(z_s, has_s, windows, settings)
    return np.where(z_ev < split[window[shot]], z_ev - carry[shot], z_ev)
