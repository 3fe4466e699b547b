"""The local random error of the soundings from their pairs (:func:`pair_scatter`).

Part of the TPU's inputs measured from neighbouring soundings
(:mod:`pipeline.uncertainty.tpu_neighbours`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from pipeline.uncertainty.seabed_gradient import group_means, seabed_gradient

__all__ = ["pair_scatter"]

#: query points per neighbour search block (memory: ~1.5 kB each with 64 neighbours)
_QUERY_BLOCK = 65536


def pair_scatter(
    xy_m: Any,
    depth_m: Any,
    gradient: Any = None,
    *,
    order: Any = None,
    group: Any = None,
    query_xy_m: Any = None,
    max_separation_m: float = 2.0,
    neighbours: int = 64,
    rise_per_m2: float | None = None,
    relief_slope_sigma: float | None = None,
    return_figures: bool = False,
):
    """Local one-sigma random error of the soundings' depths (or heights), from their pairs.

    Each sounding (or each ``group`` of soundings sharing one detection, e.g. the shots of a
    photon-counting window, taken at their mean) is paired with the next one in ``order``
    (the acquisition order: the pulse number), or without ``order`` with its nearest one, if it
    lies within ``max_separation_m``. Their depth difference less the local slope times their
    separation, ``D = d_i - d_j - g . (p_i - p_j)``, holds the two soundings' own random errors
    (timing, jitter, relief at the footprint scale) and not what they share (navigation, water
    indices; successive pulses share nearly all else): ``E[D²] = s_i² + s_j²``. At each query
    point (default: each sounding) the estimate is ``sqrt(mean(D² / 2))`` over the nearest
    ``neighbours`` pairs. ``gradient`` (``(n, 2)``, :func:`seabed_gradient`) defaults to the one of
    the (grouped) soundings themselves: a group's shots share one depth, so only the groups
    show the slope.

    The true depth also differs between two soundings beyond the plane: seabed relief, and the
    sea above them (a depth is read below the sea over its sounding), both real and no error.
    Their part of ``E[D²] / 2`` is the semivariogram of the true depth about the plane, which a
    smooth field raises as ``a h²`` from the origin; the random error is its nugget. ``a`` is
    measured once over the survey (with ``order``) from each sounding's pairs with its next and
    its next but one (lags ``h_1``, ``h_2``; where both pairs exist the soundings' error
    variance cancels in ``D_2² / 2 - D_1² / 2 = a (h_2² - h_1²)``, so a depth-varying noise
    does not bias ``a``), as ``a = sum(D_2² / 2 - D_1² / 2) / sum(h_2² - h_1²)`` (at least 0;
    the next but one within ``2 max_separation_m``; 0 unless ``sum h_2² > 2 sum h_1²``), and the
    estimate is ``sqrt(max(mean(D² / 2 - a h²), 0))`` over the nearest pairs. A rise that is not
    quadratic (relief or waves near the pairs' lag scale) is removed only in part. Without it,
    pairs 1-2 m apart on a scanner over waves or a rough seabed put the sea's and the relief's
    height differences into the timing (``benchmarks/RESULTS_tpu_calibration.md``, per-stratum
    calibration).

    ``rise_per_m2`` and ``relief_slope_sigma`` (the ``local_sigma`` of the soundings' own
    gradient, :func:`seabed_gradient`, where ``gradient`` is not given): as given, measured
    over a whole survey whose part these soundings are (a tile's soundings then get the
    survey's figures), not measured here.

    Returns
    -------
    (m,) float64
        NaN where no pair exists at all.
    figures : dict
        ``rise_per_m2`` (``a``, given or measured; 0 where it cannot be told) and
        ``relief_slope_sigma`` (used by the soundings' own gradient; None: none made or no
        regional step). Only with ``return_figures``.
    """
    figures = {"rise_per_m2": rise_per_m2, "relief_slope_sigma": relief_slope_sigma}
    out = _pair_scatter(
        xy_m, depth_m, gradient, order, group, query_xy_m, max_separation_m, neighbours, figures
    )
    return (out, figures) if return_figures else out


def _pair_scatter(xy_m, depth_m, gradient, order, group, query_xy_m, max_sep, neighbours, fig):
    """:func:`pair_scatter`; ``fig`` is filled with the figures it used."""
    max_separation_m = max_sep
    given, relief = fig["rise_per_m2"], fig["relief_slope_sigma"]
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    dep = np.asarray(depth_m, dtype=np.float64).ravel()
    g = None if gradient is None else np.asarray(gradient, dtype=np.float64).reshape(-1, 2)
    key = None if order is None else np.asarray(order, dtype=np.float64).ravel()
    q = xy if query_xy_m is None else np.asarray(query_xy_m, dtype=np.float64).reshape(-1, 2)
    if group is not None:
        _, inv = np.unique(np.asarray(group).ravel(), return_inverse=True)
        cnt = np.bincount(inv).astype(np.float64)
        if g is not None:
            g = np.column_stack([np.bincount(inv, weights=g[:, k]) / cnt for k in range(2)])
        xy, dep = group_means(group, xy, dep)
        if key is not None:
            first = np.full(len(cnt), np.inf)
            np.minimum.at(first, inv, key)
            key = first
    out = np.full(len(q), np.nan)
    rise = fig["rise_per_m2"] = 0.0 if given is None else float(given)
    if len(xy) < 2 or (len(q) == 0 and given is not None):
        return out
    # the survey's rise given, no pair beyond the queries' nearest is read: only their
    # soundings need a gradient (a block of a survey: most of its halo's are not queried)
    at_queries = g is None and given is not None
    if g is None and not at_queries:
        g, fig["relief_slope_sigma"] = seabed_gradient(
            xy, dep, local_sigma=relief, return_local_sigma=True
        )
    if key is None:
        _, idx = cKDTree(xy).query(xy, k=2, workers=-1)
        i, j, j2 = np.arange(len(xy)), idx[:, 1], None  # no second lag along a scan
    else:
        seq = np.argsort(key, kind="stable")
        i, j, j2 = seq[:-1], seq[1:], np.append(seq[2:], seq[-1])
    if at_queries:
        return _scatter_at_queries(xy, dep, i, j, q, max_separation_m, neighbours, fig, out)
    half_sq, sep_sq, ok = _pair_half_squares(xy, dep, g, i, j, max_separation_m)
    if not np.any(ok):
        return out
    # the true depth's own rise between the pairs (relief, the sea above the soundings): its
    # curvature a from the same soundings' pairs at two lags (their noise cancels)
    if j2 is not None and given is None:
        half_sq2, sep_sq2, ok2 = _pair_half_squares(xy, dep, g, i, j2, 2.0 * max_separation_m)
        both = ok & ok2 & (j2 != j)
        den = float(np.sum(sep_sq2[both] - sep_sq[both]))
        if den > float(np.sum(sep_sq[both])):  # lags apart enough to tell a rise
            rise = fig["rise_per_m2"] = max(
                float(np.sum(half_sq2[both] - half_sq[both])) / den, 0.0
            )
    if len(q) == 0:
        return out
    i, j = i[ok], j[ok]
    half_sq = half_sq[ok] - rise * sep_sq[ok]
    k = min(neighbours, half_sq.size)
    tree = cKDTree(0.5 * (xy[i] + xy[j]))
    for lo in range(0, len(q), _QUERY_BLOCK):  # (queries, k) temporaries bounded
        qq = q[lo : lo + _QUERY_BLOCK]
        _, near = tree.query(qq, k=k, workers=-1)
        near = np.asarray(near).reshape(len(qq), k)
        out[lo : lo + len(qq)] = np.sqrt(np.maximum(np.mean(half_sq[near], axis=1), 0.0))
    return out


def _pair_half_squares(xy, dep, g, i, j, max_separation_m):
    """``D² / 2`` of the pairs ``(i, j)`` (plane removed), their squared lags, and which count."""
    sep = xy[i] - xy[j]
    sep_sq = np.sum(sep**2, axis=1)
    diff = dep[i] - dep[j] - np.sum(0.5 * (g[i] + g[j]) * sep, axis=1)
    return 0.5 * diff**2, sep_sq, np.sqrt(sep_sq) <= max_separation_m  # no overflow of a huge limit


def _scatter_at_queries(xy, dep, i, j, q, max_separation_m, neighbours, fig, out):
    """:func:`_pair_scatter`'s estimate at ``q`` with the survey's rise given (``fig``).

    The same figures to the bit: the same pairs and nearest pairs, each pair's ``D² / 2``
    from the same gradient rows (:func:`seabed_gradient`'s queries are independent), made
    only for the pairs some query reads. Fills ``out`` ``(len(q),)`` and returns it.
    """
    sep_sq = np.sum((xy[i] - xy[j]) ** 2, axis=1)
    ok = np.sqrt(sep_sq) <= max_separation_m
    if not np.any(ok):
        return out
    i, j, sep_sq = i[ok], j[ok], sep_sq[ok]
    k = min(neighbours, i.size)
    tree = cKDTree(0.5 * (xy[i] + xy[j]))
    starts = range(0, len(q), _QUERY_BLOCK)  # (queries, k) temporaries bounded
    near = [
        np.asarray(tree.query(q[lo : lo + _QUERY_BLOCK], k=k, workers=-1)[1]).reshape(-1, k)
        for lo in starts
    ]
    read = np.unique(np.concatenate([nb.ravel() for nb in near]))
    ends = np.unique(np.concatenate([i[read], j[read]]))
    g = np.zeros((len(xy), 2))  # rows no pair read stay 0: never used
    g[ends], fig["relief_slope_sigma"] = seabed_gradient(
        xy, dep, xy[ends], local_sigma=fig["relief_slope_sigma"], return_local_sigma=True
    )
    half_sq = np.zeros(i.size)
    h, _, _ = _pair_half_squares(xy, dep, g, i[read], j[read], max_separation_m)
    half_sq[read] = h - fig["rise_per_m2"] * sep_sq[read]
    for lo, nb in zip(starts, near, strict=True):
        out[lo : lo + len(nb)] = np.sqrt(np.maximum(np.mean(half_sq[nb], axis=1), 0.0))
    return out
