"""The sea the local surface planes cannot follow, pooled over square cells.

A pulse's local plane (:func:`pipeline.process.surface_fit.fit_water_surface`) leaves a
residual scatter ``fit_sigma`` made of the waves it cannot follow and its surface points'
ranging noise. Read pulse by pulse, ``sqrt(max(fit² - ranging², 0))`` is biased high where
there is no sea: ``fit²`` from ~16 neighbours scatters by ``sqrt(2 / 13)`` ~ 40 % about the
ranging variance, and clipping keeps the half above it. On calm flat water (suite tuning seed
20: ranging 0.05 m) that made a wave term of 0.014 m rms in the depths where the sea has
none, and the TPU 1.45 times the errors. Averaged over a cell of the sea first, ``fit² -
ranging²`` is unbiased; its clip then costs little. A sea changes over hundreds of metres, a
cell of 25 m holds tens of independent fits.

Cells are aligned on the local frame's origin, and each cell's sums run in pulse-id order: a
tile or block that holds a cell's pulses gets the whole survey's figure, to the bit.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.cell_keys import cell_inverse
from pipeline.optics import SPEED_OF_LIGHT_M_S as _C_M_S

__all__ = ["pooled_wave_sigma_m", "surface_wave_sigma_m", "pooled_wave"]


def pooled_wave_sigma_m(
    xy_m: np.ndarray,
    fit_sigma_m: np.ndarray,
    ranging_m: np.ndarray,
    contributes: np.ndarray,
    pulse_id: np.ndarray,
    cell_m: float,
) -> np.ndarray:
    """Each pulse's wave sigma beyond its plane, ``sqrt(max(<fit² - ranging²>, 0))``, (n,).

    Parameters
    ----------
    xy_m : (n, 2) ndarray
        Where each pulse met the sea, local frame (m).
    fit_sigma_m : (n,) ndarray
        Its local plane's residual scatter (m).
    ranging_m : (n,) ndarray
        Its surface point's ranging sigma along the plane's normal (m).
    contributes : (n,) bool ndarray
        Pulses whose ``fit² - ranging²`` enter their cell's mean (water, an own surface
        return and, from :func:`surface_wave_sigma_m`, a bottom); the others take their
        cell's figure.
    pulse_id : (n,) int ndarray
        The sums' order within a cell.
    cell_m : float
        Side of the cells; ``0``: each pulse its own, ``sqrt(max(fit² - ranging², 0))``.

    Returns
    -------
    (n,) ndarray
        Pulses in a cell without a contributor keep their own figure.
    """
    fit = np.asarray(fit_sigma_m, dtype=np.float64)
    rng = np.asarray(ranging_m, dtype=np.float64)
    excess = fit**2 - rng**2
    own = np.sqrt(np.maximum(excess, 0.0))
    n = len(fit)
    if cell_m <= 0.0 or n == 0:
        return own
    xy = np.asarray(xy_m, dtype=np.float64)
    cell = cell_inverse(np.floor(xy / cell_m).astype(np.int64))
    use = np.flatnonzero(np.asarray(contributes, dtype=bool) & np.isfinite(excess))
    if use.size == 0:  # no sounding's plane (no bottom anywhere): each keeps its own
        return own
    # within a cell, in pulse-id order: the same sum whatever the pulses' order or company
    order = use[np.lexsort((np.asarray(pulse_id)[use], cell[use]))]
    c_sorted = cell[order]
    starts = np.flatnonzero(np.r_[True, c_sorted[1:] != c_sorted[:-1]])
    sums = np.add.reduceat(excess[order], starts)
    counts = np.diff(np.r_[starts, order.size])
    mean = np.full(cell.max() + 1, np.nan)
    mean[c_sorted[starts]] = sums / counts
    pooled = mean[cell]
    return np.where(np.isfinite(pooled), np.sqrt(np.maximum(pooled, 0.0)), own)


def surface_wave_sigma_m(returns, surface, timing_sigma_s: float, cell_m: float) -> np.ndarray:
    """:func:`pooled_wave_sigma_m` of every pulse of a survey (or tile), ``(n_pulses,)``.

    The water pulses with a surface return and a bottom enter their cell: the soundings' own
    sea. Pulses without a bottom are left out: on suite tuning seed 0 (turbid, calm, 761 m)
    those of the swath's centre, beyond the light's reach, fit planes scattering up to 0.48 m
    and put a 0.037 m wave term on a flat sea whose soundings' planes showed none. The
    ranging is each surface return's timing sigma (``returns.t_surface_sigma_s``, else
    ``timing_sigma_s``) along the plane's normal.

    Parameters
    ----------
    returns : DetectedReturns
        ``(n_pulses,)`` per field.
    surface : WaterSurface
        Their fitted surface.
    timing_sigma_s : float
        The timing sigma of a return without its own.
    cell_m : float
        Side of the cells (0: pulse by pulse).
    """
    sig = returns.t_surface_sigma_s
    sig = np.full(len(returns), timing_sigma_s) if sig is None else np.asarray(sig, np.float64)
    sig = np.where(returns.has_surface, sig, timing_sigma_s)
    cos_i = np.abs(np.sum(returns.direction_meas * surface.normal, axis=1))
    ranging = _C_M_S * sig / 2.0 * cos_i
    water = np.asarray(surface.is_water, dtype=bool)
    return pooled_wave_sigma_m(
        surface.entry_m[:, :2],
        surface.fit_sigma_m,
        ranging,
        water & returns.has_surface & returns.has_bottom,
        returns.pulse_id,
        cell_m,
    )


def pooled_wave(detector, surface, variogram, st) -> np.ndarray:
    """The TPU's wave sigma per pulse, ``(n_pulses,)``, from the detector's surface sigmas.

    Each sigma raised to the surface variogram's nugget at its incidence (the ranging the
    surface points show, :func:`~pipeline.uncertainty.tpu_measured.with_surface_ranging`), not
    to the pair scatter's share, which is set per sounding: the figure is then the same
    whichever soundings a tile or block propagates (:mod:`pipeline.uncertainty.tpu_subset`).
    A detector without surface sigmas (photon counting) starts from ``st.timing_sigma_s``.
    ``detector``: the survey's (or tile's) returns with every bottom, not only those a block
    propagates.
    """
    from pipeline.uncertainty.tpu_measured import with_surface_ranging

    if detector.t_surface_sigma_s is None:
        own = np.where(detector.has_surface, st.timing_sigma_s, 0.0)
        detector = dataclasses.replace(detector, t_surface_sigma_s=own)
    raised = with_surface_ranging(detector, surface, variogram)
    return surface_wave_sigma_m(raised, surface, st.timing_sigma_s, st.wave_pool_cell_m)
