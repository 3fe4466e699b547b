"""The TPU of some of a survey's points: only their pulses propagated, every sounding read.

A block of a survey (:mod:`pipeline.survey_blocks`) is loaded with a halo for its neighbour
searches, yet keeps the TPU of only some of its points: its own pulses', its own cells' and
those its class-43 and rejection tests read. The TPU's per-pulse work (the perturbations of
:func:`~pipeline.uncertainty.tpu.point_tpu` and
:func:`~pipeline.uncertainty.tpu.timing_from_scatter`, the gradient's local planes, the pair
scatter's queries) is row by row: one pulse's figures do not depend on which other pulses are
propagated with it, only on the soundings its searches read. So
:func:`~pipeline.uncertainty.survey_uncertainty.survey_uncertainty` propagates the kept
points' pulses alone while its searches still read every sounding: the kept points' TPU is
the same to the bit (``tests/test_survey_blocks.py``, ``benchmarks/blocks_exact.py``).

This needs the survey-wide figures handed in (``wide``): measured here they would be the
kept pulses', not the survey's. Photon-counting windows are propagated whole (a window's
shots share one detection, and its term reads the neighbouring windows), so ``keep`` is not
applied to them.
"""

from __future__ import annotations

import dataclasses

import numpy as np

__all__ = ["propagated_bottoms", "without_bottoms"]


def propagated_bottoms(returns, points, is40: np.ndarray, keep, wide, windows):
    """The pulses :func:`~pipeline.uncertainty.survey_uncertainty.survey_uncertainty` propagates.

    Parameters
    ----------
    returns : DetectedReturns
        ``(n_pulses,)`` per field.
    points : Points
        Their processed points, ``(n_points,)``.
    is40 : (n_points,) bool
        The bathymetric points (class 40 bottoms).
    keep : (n_points,) bool or None
        The points whose TPU is kept; None: all.
    wide : TpuSurveyWide or None
        The survey-wide figures (required with ``keep``).
    windows : PhotonWindows or None
        The detector's windows of shots (photon counting): then every pulse is propagated.

    Returns
    -------
    returns : DetectedReturns
        ``returns`` whose ``has_bottom`` holds only the propagated pulses (the rows
        :func:`~pipeline.uncertainty.tpu.point_tpu` takes); unchanged without ``keep``.
    q : (n_bottom,) bool or slice
        The propagated pulses among the bottom rows of the ``returns`` given (``slice(None)``:
        all of them).
    is40 : (n_points,) bool
        The bathymetric points whose TPU is propagated.
    """
    if keep is None or windows is not None:
        return returns, slice(None), is40
    if wide is None:
        raise ValueError(
            "`keep` needs the survey-wide TPU figures (`wide`): a subset measures its own"
        )
    keep = np.asarray(keep, dtype=bool)
    if keep.shape != is40.shape:
        raise ValueError(f"`keep` must be (n_points,) = {is40.shape}; got {keep.shape}")
    kept40 = is40 & keep
    bottom = returns.has_bottom & np.isin(returns.pulse_id, points.pulse_id[kept40])
    q = bottom[returns.has_bottom]
    return without_bottoms(returns, bottom), q, kept40


#: The fields of a bottom return, 0 where there is none (:class:`DetectedReturns`' rule).
_BOTTOM_FIELDS = ("t_bottom_s", "bottom_confidence", "bottom_amplitude", "t_bottom_sigma_s")


def without_bottoms(returns, bottom: np.ndarray):
    """``returns`` with only the bottoms ``bottom`` ``(n_pulses,)`` bool (of its own) left.

    The other pulses' bottom fields are 0, as for a pulse without a bottom; nothing else
    changes (their surface returns stay).
    """
    drop = returns.has_bottom & ~bottom
    cut = {
        k: np.where(drop, 0.0, v) for k in _BOTTOM_FIELDS if (v := getattr(returns, k)) is not None
    }
    return dataclasses.replace(returns, has_bottom=returns.has_bottom & bottom, **cut)
