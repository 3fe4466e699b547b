"""The TPU's timing terms split into the waveform's own precision and the excess measured.

Each return's timing sigma starts as the detector's own (a Cramér–Rao bound from its waveform)
and is raised where the survey measures more: by the scatter of successive soundings
(:func:`~pipeline.uncertainty.tpu.timing_from_scatter`) and, for the surface, by the surface
heights' variogram nugget (:func:`~pipeline.uncertainty.tpu_measured.with_surface_ranging`).
A depth posterior from the same waveform (:mod:`pipeline.uncertainty.survey_posterior`)
replaces the first part, not the second: what the detector's model of the echo cannot see
(a bottom echo spread over a sloping footprint, a surface onset under waves) is not in the
waveform likelihood either. :func:`split_timing_excess` keeps the timing terms as the
detector's share and puts the rest in two terms of their own, so the posterior's nuisances and
the cells sampled by a posterior keep it (every term but
:data:`~pipeline.uncertainty.tpu_settings.TIMING_TERMS`).

A term is ``J sigma`` (x, y, z, depth per unit of time, times the sigma), so the split is
exact: ``J sigma_own`` and ``J sqrt(sigma^2 - sigma_own^2)``; their squares add up to the
term's, and the totals of the TPU are left as they were.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline.process.returns import DetectedReturns
from pipeline.uncertainty.tpu import PointTpu

__all__ = ["EXCESS_TERMS", "split_timing_excess"]

#: The timing terms' excess over the detector's own sigmas, by return.
EXCESS_TERMS = {
    "timing_surface": "timing_surface_excess",
    "timing_bottom": "timing_bottom_excess",
}


def _own_share(own, raised, rows: np.ndarray) -> np.ndarray | None:
    """``own / raised`` at ``rows`` in [0, 1] (1 where no return); None without own sigmas."""
    if own is None or raised is None:
        return None
    o = np.asarray(own, dtype=np.float64)[rows]
    r = np.asarray(raised, dtype=np.float64)[rows]
    share = np.where(r > 0.0, o / np.where(r > 0.0, r, 1.0), 1.0)
    return np.clip(np.nan_to_num(share, nan=1.0), 0.0, 1.0)


def split_timing_excess(
    tpu: PointTpu, detector: DetectedReturns, raised: DetectedReturns
) -> PointTpu:
    """``tpu`` with each timing term split into the detector's share and the excess.

    Parameters
    ----------
    tpu : PointTpu
        Its ``row`` indexes the pulses of ``detector`` and ``raised``.
    detector : DetectedReturns
        The detections with the detector's own timing sigmas (``t_*_sigma_s``).
    raised : DetectedReturns
        The same detections with the sigmas the TPU propagated (raised by the measured
        scatter and variogram).

    Returns
    -------
    PointTpu
        The same totals; ``terms`` with ``timing_surface`` / ``timing_bottom`` at the
        detector's share and :data:`EXCESS_TERMS` holding the rest. Unchanged where the
        detector gave no sigmas (photon counting: the scatter set them all).
    """
    rows = np.asarray(tpu.row)
    pairs = {
        "timing_surface": (detector.t_surface_sigma_s, raised.t_surface_sigma_s),
        "timing_bottom": (detector.t_bottom_sigma_s, raised.t_bottom_sigma_s),
    }
    terms = dict(tpu.terms)
    for name, (own, up) in pairs.items():
        share = _own_share(own, up, rows)
        if share is None or name not in terms:
            continue
        term = terms[name]
        terms[name] = term * share[:, None]
        terms[EXCESS_TERMS[name]] = term * np.sqrt(1.0 - share * share)[:, None]
    return dataclasses.replace(tpu, terms=terms)
