"""Which pulses get a depth posterior: the waveforms kept, the budget, the points chosen.

The chunk loop keeps the waveforms of a fixed share of the pulses (:func:`kept_for_posterior`,
a few times :func:`posterior_budget`), chosen by a hash of the pulse id so the chunking cannot
change the choice; :func:`choose_points` picks the points sampled among them. No sampler here:
a survey without posteriors never imports emcee.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.process.grid import Grid
from pipeline.process.settings import ProcessSettings

__all__ = [
    "KeptWaveforms",
    "kept_for_posterior",
    "posterior_budget",
    "choose_points",
    "sounded_area_km2",
]


@dataclass(frozen=True)
class KeptWaveforms:
    """Waveforms the chunk loop kept for posteriors.

    ``pulse_id`` (k,), ``t0_s`` (k,) from emission to sample 0, ``samples`` (k, n_samples)
    float32.
    """

    pulse_id: np.ndarray
    t0_s: np.ndarray
    samples: np.ndarray

    @classmethod
    def concatenate(cls, parts: list[KeptWaveforms]) -> KeptWaveforms | None:
        """One set from the chunks' (None when no chunk kept any)."""
        if not parts:
            return None
        return cls(*(np.concatenate([getattr(p, f) for p in parts]) for f in cls._fields()))

    @staticmethod
    def _fields() -> tuple[str, str, str]:
        return ("pulse_id", "t0_s", "samples")


def kept_for_posterior(pulse_id: np.ndarray, fraction: float, seed: int) -> np.ndarray:
    """Pulses whose waveforms are kept for posteriors: a fixed share, by pulse id alone.

    A multiplicative (Weyl) hash of the id spreads the kept pulses evenly over the survey and
    does not depend on the chunking.
    """
    if fraction <= 0.0:
        return np.zeros(pulse_id.shape, dtype=bool)
    golden = np.uint64(0x9E3779B97F4A7C15)
    with np.errstate(over="ignore"):
        h = (pulse_id.astype(np.uint64) + np.uint64(seed)) * golden
    return (h >> np.uint64(11)).astype(np.float64) / 2.0**53 < fraction


def posterior_budget(ps: ProcessSettings, area_km2: float) -> int:
    """Points to sample: ``posterior_pulses_per_km2`` over ``area_km2``, at least the minimum.

    ``posterior_min_pulses`` is the minimum. Photon counting: both count accumulation windows
    (one posterior per window, :mod:`pipeline.uncertainty.photon_posterior`). The chunk loop
    passes the survey's extent (an upper bound, to keep enough waveforms), the sampling the
    area of the grid cells with soundings.
    """
    area = max(float(area_km2), 0.0)
    return int(max(ps.posterior_min_pulses, round(ps.posterior_pulses_per_km2 * area)))


def sounded_area_km2(grid: Grid) -> float:
    """Area of the grid cells holding at least one sounding, km²."""
    return float(np.count_nonzero(grid.count > 0)) * grid.resolution_m**2 / 1e6


def choose_points(candidates: np.ndarray, preferred: np.ndarray, n: int, seed: int) -> np.ndarray:
    """Up to ``n`` of ``candidates``: the ``preferred`` ones first, then evenly spread others.

    Parameters
    ----------
    candidates : (m,) int64
        Point indices that may be chosen (their waveform was kept).
    preferred : (k,) int64
        Point indices chosen first where they are candidates (cells that matter).
    n : int
    seed : int
        Orders the preferred ones when there are more than ``n``.

    Returns
    -------
    (<= n,) int64, sorted
    """
    cand = np.unique(candidates)
    first = np.intersect1d(cand, preferred)
    if first.size > n:
        first = np.sort(np.random.default_rng(seed).choice(first, n, replace=False))
    rest = np.setdiff1d(cand, first)
    need = n - first.size
    if need > 0 and rest.size:
        pick = np.unique(np.linspace(0, rest.size - 1, min(need, rest.size)).round().astype(int))
        first = np.concatenate([first, rest[pick]])
    return np.sort(first)
