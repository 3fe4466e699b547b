"""Depth posteriors of a bounded sample of a survey's bathymetric points (``bathy run``).

The chunk loop keeps the waveforms of a fixed share of the pulses
(:func:`pipeline.run_survey.kept_for_posterior`, a few times :func:`posterior_budget`);
here, once the points, their TPU and the cells exist, :func:`posterior_budget` of the kept
bathymetric points are chosen, first in the cells that matter
(:func:`pipeline.process.cell_uncertainty.select_posterior_pulses`: the IHO order could flip,
or a flagged point), then evenly among the rest, and their emcee posteriors are sampled and
carried through refraction onto the seabed point
(:func:`pipeline.process.seabed_posterior.seabed_posteriors`). Cost: the budget times about
0.3-0.5 s (about 15 min per km² at the default 2000/km²), linear in the area, bounded per km².
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from pipeline.process.cell_uncertainty import select_posterior_pulses
from pipeline.process.seabed_posterior import SeabedPosteriors, seabed_posteriors, take_surface
from pipeline.process.waveform_model import WaveformSystem

__all__ = ["posterior_budget", "waveform_system", "choose_points", "survey_posteriors"]


def posterior_budget(scene, area_km2: float) -> int:
    """Points to sample: ``posterior_pulses_per_km2`` over ``area_km2``, at least the minimum.

    ``posterior_min_pulses`` is the minimum; 0 for photon counting (its windows have no
    waveform). The chunk loop passes the survey's extent (an upper bound, to keep enough
    waveforms), the sampling the area of the grid cells with soundings.
    """
    ps = scene.process
    if scene.detector.mode != "full_waveform":
        return 0
    area = max(float(area_km2), 0.0)
    return int(max(ps.posterior_min_pulses, round(ps.posterior_pulses_per_km2 * area)))


def waveform_system(scene, group_index: float) -> WaveformSystem:
    """The instrument as the processing knows it: the scene's system and detector values.

    Nothing of the water or the seabed: those are the posterior's parameters, but for
    ``group_index``, the one processing assumes (:class:`~pipeline.process.context.
    ProcessingContext`).
    """
    from pipeline.run_survey import _system_fwhm_s

    det = scene.detector
    return WaveformSystem(
        sample_interval_s=1.0 / det.sample_rate_hz,
        pulse_fwhm_s=_system_fwhm_s(scene),
        group_index=group_index,
        offset_counts=det.baseline_counts,
        counts_per_photoelectron=det.counts_per_photoelectron,
        excess_noise_factor=det.excess_noise_factor,
        electronic_noise_counts=det.electronic_noise_counts,
    )


def _sounded_area_km2(grid) -> float:
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


def survey_posteriors(scene, sim: dict, processed, ctx, unc: dict, grid) -> dict[str, Any] | None:
    """Sample the depth posteriors of up to :func:`posterior_budget` bathymetric points.

    Parameters
    ----------
    scene : Scene
    sim : dict
        :func:`pipeline.run_survey.simulate_detections` output (``returns``,
        ``kept_waveforms``); the truth in it is not read.
    processed : Processed
        Georeferenced points and the fitted surface (one row per pulse of ``returns``).
    ctx : ProcessingContext
        What processing assumes (:func:`pipeline.process.context.processing_context`).
    unc : dict
        ``points40``, ``tpu40`` and ``cells`` of the uncertainty stage.
    grid : Grid

    Returns
    -------
    dict or None
        ``posteriors`` (:class:`SeabedPosteriors`, or None when every candidate has an
        in-column return), ``point_index`` (rows of ``points40``), ``cost_s`` and
        ``skipped_column`` (kept points left out for an in-column return, which the
        posterior's model lacks); None when nothing is sampled (photon counting, a zero budget
        or no kept waveform of a bathymetric point).
    """
    from pipeline.run_survey import detect_noise

    n = posterior_budget(scene, _sounded_area_km2(grid))
    kept = sim.get("kept_waveforms")
    if kept is None or n == 0:
        return None
    pid_k, t0_k, samples_k = kept
    pts = unc["points40"]
    ret = sim["returns"]
    # the posterior's waveform model has no in-column echo (a scattering layer): pulses with
    # one would be sampled under a wrong model, so they are left out and counted
    if ret.has_column is not None and ret.has_column.any():
        pid_kept = np.setdiff1d(pid_k, ret.pulse_id[ret.has_column])
    else:
        pid_kept = pid_k
    cand = np.flatnonzero(np.isin(pts.pulse_id, pid_kept))
    n_column = int(np.count_nonzero(np.isin(pts.pulse_id, pid_k))) - cand.size
    if cand.size == 0:
        return {"posteriors": None, "point_index": cand, "cost_s": 0.0, "skipped_column": n_column}
    preferred = select_posterior_pulses(
        grid, unc["cells"], unc["tpu40"], max_pulses=max(n, 1), seed=scene.scene.seed
    )
    sel = choose_points(cand, preferred, n, scene.scene.seed)
    pid = pts.pulse_id[sel]
    order = np.argsort(ret.pulse_id)
    rows = order[np.searchsorted(ret.pulse_id[order], pid)]
    korder = np.argsort(pid_k)
    krows = korder[np.searchsorted(pid_k[korder], pid)]
    t0 = time.perf_counter()
    post: SeabedPosteriors = seabed_posteriors(
        samples_k[krows].astype(np.float64),
        t0_k[krows],
        ret.select(rows),
        take_surface(processed.surface, rows),
        waveform_system(scene, ctx.refraction.group_index),
        scene.process.posterior,
        ctx.refraction,
        seed=scene.scene.seed,
        detect_settings=scene.process.detect,
        detect_noise=detect_noise(scene),
    )
    return {
        "posteriors": post,
        "point_index": sel,
        "cost_s": time.perf_counter() - t0,
        "skipped_column": n_column,
    }
