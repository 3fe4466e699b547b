"""Depth posteriors of a bounded sample of a survey's bathymetric points (``bathy run``).

The chunk loop keeps the waveforms of a fixed share of the pulses
(:func:`~pipeline.uncertainty.posterior_selection.kept_for_posterior`);
here, once the points, their TPU and the cells exist, :func:`posterior_budget` of the kept
bathymetric points are chosen, first in the cells that matter
(:func:`pipeline.uncertainty.cell_uncertainty.select_posterior_pulses`: the IHO order could flip,
or a flagged point), then evenly among the rest, and their emcee posteriors are sampled and
carried through refraction onto the seabed point
(:func:`pipeline.uncertainty.seabed_posterior.seabed_posteriors`), marginalised over the TPU
terms the waveform does not hold (:func:`nuisance_depth_sigma_m`). Cost: the budget times
about 0.06 CPU s (``benchmarks/RESULTS_posterior.md``; about 2 CPU min per km² at the default
2000/km²), linear in the area, bounded per km².

Photon counting (no waveform per pulse): the chunk loop keeps the events of a share of the
accumulation windows, the budget counts windows, and one shot per kept window is sampled on
the window's histogram along its beam, with each bin's live share under the dead time
(:mod:`pipeline.uncertainty.photon_posterior`); the rest is the same.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from pipeline.process.context import ProcessingContext
from pipeline.process.grid import Grid
from pipeline.process.refraction import ProcessedPoints
from pipeline.process.returns import DetectedReturns
from pipeline.uncertainty.cell_uncertainty import select_posterior_pulses
from pipeline.uncertainty.photon_posterior import (
    KeptPhotons,
    at_detected_surface,
    photon_starts,
    photon_system,
    window_candidates,
    window_histograms,
)
from pipeline.uncertainty.posterior_selection import (
    KeptWaveforms,
    choose_points,
    posterior_budget,
    sounded_area_km2,
)
from pipeline.uncertainty.seabed_posterior import (
    SeabedPosteriors,
    seabed_posteriors,
    take_surface,
    water_cosine,
)
from pipeline.uncertainty.survey_uncertainty import SurveyUncertainty
from pipeline.uncertainty.tpu_settings import DEPTH, TIMING_TERMS
from pipeline.uncertainty.waveform_model import WaveformSystem

__all__ = ["SurveyPosteriors", "waveform_system", "survey_posteriors", "nuisance_depth_sigma_m"]


@dataclass(frozen=True)
class SurveyPosteriors:
    """The posterior stage's result.

    ``posteriors`` (None when every candidate had an in-column return), ``point_index`` rows of
    ``points40`` sampled, ``cost_s`` and ``skipped_column``.
    """

    posteriors: SeabedPosteriors | None
    point_index: np.ndarray
    cost_s: float
    skipped_column: int


def waveform_system(scene, ctx: ProcessingContext) -> WaveformSystem:
    """The instrument as the processing knows it: the scene's system and detector values.

    Nothing of the water or the seabed: those are the posterior's parameters, but for the
    group index, the one processing assumes (:class:`~pipeline.process.context.
    ProcessingContext`). Photon counting: Poisson counts per detector height bin
    (:func:`~pipeline.uncertainty.photon_posterior.photon_system`).
    """
    if ctx.instrument.photon_counting:
        return photon_system(
            scene.process.photon_detect.bin_m,
            ctx.instrument.air_index,
            ctx.instrument.system_fwhm_s,
            ctx.refraction.group_index,
        )
    det = scene.detector
    return WaveformSystem(
        sample_interval_s=ctx.instrument.sample_interval_s,
        pulse_fwhm_s=ctx.instrument.system_fwhm_s,
        group_index=ctx.refraction.group_index,
        offset_counts=det.baseline_counts,
        counts_per_photoelectron=det.counts_per_photoelectron,
        excess_noise_factor=det.excess_noise_factor,
        electronic_noise_counts=det.electronic_noise_counts,
        surface_misfit=scene.process.posterior.surface_misfit,
    )


def survey_posteriors(
    scene,
    returns: DetectedReturns,
    kept: KeptWaveforms | KeptPhotons | None,
    processed: ProcessedPoints,
    ctx: ProcessingContext,
    unc: SurveyUncertainty,
    grid: Grid,
    progress: bool = False,
) -> SurveyPosteriors | None:
    """Sample the depth posteriors of up to :func:`posterior_budget` bathymetric points.

    Parameters
    ----------
    scene : Scene
        Only ``process`` settings, ``detector`` records and the seed are read.
    returns : DetectedReturns
        The survey's detections, ``(n_pulses,)`` per field.
    kept : KeptWaveforms or KeptPhotons or None
        The waveforms the chunk loop kept (photon counting: the kept windows' events; one
        posterior per window, :mod:`pipeline.uncertainty.photon_posterior`).
    processed : ProcessedPoints
        Georeferenced points and the fitted surface (one row per pulse of ``returns``).
    ctx : ProcessingContext
        What processing assumes (:func:`pipeline.process.context.processing_context`).
    unc : SurveyUncertainty
        ``points40``, ``tpu40`` and ``cells`` of the uncertainty stage.
    grid : Grid
    progress : bool
        A progress bar over the posterior batches (stderr).

    Returns
    -------
    SurveyPosteriors or None
        None when nothing is sampled (a zero budget or no kept waveform of a bathymetric
        point); ``skipped_column`` counts kept points left out for an in-column return, which
        the posterior's model lacks.
    """
    ps = scene.process
    n = posterior_budget(ps, sounded_area_km2(grid))
    if kept is None or n == 0:
        return None
    if isinstance(kept, KeptPhotons):
        return _photon_posteriors(scene, returns, kept, processed, ctx, unc, grid, n, progress)
    pts = unc.points40
    ret = returns
    # the posterior's waveform model has no in-column echo (a scattering layer): pulses with
    # one would be sampled under a wrong model, so they are left out and counted
    if ret.has_column is not None and ret.has_column.any():
        pid_kept = np.setdiff1d(kept.pulse_id, ret.pulse_id[ret.has_column])
    else:
        pid_kept = kept.pulse_id
    cand = np.flatnonzero(np.isin(pts.pulse_id, pid_kept))
    n_column = int(np.count_nonzero(np.isin(pts.pulse_id, kept.pulse_id))) - cand.size
    if cand.size == 0:
        return SurveyPosteriors(None, cand, 0.0, n_column)
    preferred = select_posterior_pulses(
        grid, unc.cells, unc.tpu40, max_pulses=max(n, 1), seed=scene.scene.seed
    )
    sel = choose_points(cand, preferred, n, scene.scene.seed)
    pid = pts.pulse_id[sel]
    order = np.argsort(ret.pulse_id)
    rows = order[np.searchsorted(ret.pulse_id[order], pid)]
    korder = np.argsort(kept.pulse_id)
    krows = korder[np.searchsorted(kept.pulse_id[korder], pid)]
    nuisance = np.zeros(len(rows))
    if ps.posterior.marginalise_tpu:
        nuisance = nuisance_depth_sigma_m(unc.tpu40.terms, sel)
    t0 = time.perf_counter()
    post: SeabedPosteriors = seabed_posteriors(
        kept.samples[krows].astype(np.float64),
        kept.t0_s[krows],
        ret.select(rows),
        take_surface(processed.surface, rows),
        waveform_system(scene, ctx),
        ps.posterior,
        ctx.refraction,
        seed=scene.scene.seed,
        detect_settings=ps.detect,
        detect_noise=(ctx.instrument.noise_samples, ctx.instrument.shot_noise_counts),
        progress=progress,
        nuisance_depth_sigma_m=nuisance,
    )
    return SurveyPosteriors(post, sel, time.perf_counter() - t0, n_column)


def _photon_posteriors(scene, returns, kept, processed, ctx, unc, grid, n, progress):
    """:func:`survey_posteriors` of a photon-counting survey: one shot per kept window.

    The window's events histogrammed along the shot's beam with each sample's live share
    (:mod:`pipeline.uncertainty.photon_posterior`); otherwise as for full waveforms.
    """
    ps, ins = scene.process, ctx.instrument
    pts = unc.points40
    windows = ins.windows
    pts_win = windows.of_points(pts.pulse_id, returns)
    cand = window_candidates(pts.pulse_id, kept, windows, pts_win, pts.xyz_m[:, :2])
    if cand.size == 0:
        return SurveyPosteriors(None, cand, 0.0, 0)
    preferred = select_posterior_pulses(
        grid, unc.cells, unc.tpu40, max_pulses=max(n, 1), seed=scene.scene.seed
    )
    sel = choose_points(cand, preferred, n, scene.scene.seed)
    order = np.argsort(returns.pulse_id)
    rows = order[np.searchsorted(returns.pulse_id[order], pts.pulse_id[sel])]
    system = waveform_system(scene, ctx)
    samples, exposure, t0 = window_histograms(
        kept,
        pts_win[sel],
        returns.origin_meas_m[rows, 2],
        returns.direction_meas[rows, 2],
        returns.t_surface_s[rows],
        returns.t_bottom_s[rows],
        system,
        ins.air_index,
        scene.detector.n_channels,
    )
    surface = at_detected_surface(take_surface(processed.surface, rows), returns.select(rows))
    cosw = water_cosine(
        returns.direction_meas[rows], surface.normal, surface.air_index, ctx.refraction.phase_index
    )
    theta0 = photon_starts(
        samples, exposure, t0, returns.t_surface_s[rows], returns.t_bottom_s[rows], cosw, system
    )
    nuisance = np.zeros(len(rows))
    if ps.posterior.marginalise_tpu:
        nuisance = nuisance_depth_sigma_m(unc.tpu40.terms, sel)
    t_start = time.perf_counter()
    post = seabed_posteriors(
        samples,
        t0,
        returns.select(rows),
        surface,
        system,
        ps.posterior,
        ctx.refraction,
        seed=scene.scene.seed,
        progress=progress,
        nuisance_depth_sigma_m=nuisance,
        exposure=exposure,
        theta0=theta0,
    )
    return SurveyPosteriors(post, sel, time.perf_counter() - t_start, 0)


def nuisance_depth_sigma_m(terms: dict[str, np.ndarray], index: np.ndarray) -> np.ndarray:
    """One-sigma depth change of the TPU terms a waveform posterior does not hold.

    Every term of :attr:`PointTpu.terms <pipeline.uncertainty.tpu.PointTpu>` but the two
    timing terms (:data:`~pipeline.uncertainty.tpu_settings.TIMING_TERMS`: the detector's own
    share of the waveform's ranging, which the posterior replaces), in quadrature, in the
    depth column (the depth compared at the measured position: slope coupling included). The
    timing the survey measured beyond the detector's (the scatter of successive soundings,
    the surface variogram's nugget: :mod:`pipeline.uncertainty.tpu_timing`) is among them: the
    waveform's likelihood does not see it either.

    Parameters
    ----------
    terms : dict of (n, 4) ndarray
        The TPU's one-sigma term rows (x, y, z, depth).
    index : (k,) int
        Rows wanted.

    Returns
    -------
    (k,) ndarray
    """
    var = np.zeros(len(index))
    for name, rows in terms.items():
        if name not in TIMING_TERMS:
            var += rows[index, DEPTH] ** 2
    return np.sqrt(var)
