"""Section 3 of ``report.html``: example waveforms, with the depth posterior's fit overlaid.

The fit (the waveform model at the per-parameter posterior median,
:func:`pipeline.uncertainty.waveform_model.expected_waveform`) is drawn only for pulses the depth
posteriors sampled: a run without posteriors shows the waveforms and the detector's times only.
"""

from __future__ import annotations

import numpy as np

from pipeline.outputs import report_figures as F
from pipeline.outputs.report_html import img, para
from pipeline.process.classify import BATHYMETRIC_POINT, NO_BOTTOM_FOUND_AT

__all__ = ["waveform_section", "posterior_system", "N_WAVEFORMS"]

#: Waveforms shown at most.
N_WAVEFORMS = 3


def _posterior_fits(post, system, n_samples: int) -> dict[int, np.ndarray]:
    """Pulse id -> the posterior's fitted waveform ``(n_samples,)``, for pulses it sampled.

    Empty when the depth posteriors did not run (``post`` None or without posteriors): the
    report then overlays no fit. Pulses without a start (NO_START) have no fit.
    """
    p = None if post is None else post.posteriors
    if p is None or p.theta_median is None or system is None:
        return {}
    from pipeline.uncertainty.posterior_settings import PosteriorFlag
    from pipeline.uncertainty.waveform_model import expected_waveform

    started = np.flatnonzero((p.flags & np.uint16(PosteriorFlag.NO_START)) == 0)
    return {
        int(p.pulse_id[j]): expected_waveform(
            p.theta_median[j], n_samples, system, float(p.cos_water[j])
        )
        for j in started
    }


def posterior_system(scene, ctx, post):
    """The posteriors' waveform system, or None when they did not run (emcee not imported)."""
    if post is None or post.posteriors is None:
        return None
    from pipeline.uncertainty.survey_posterior import waveform_system

    return waveform_system(scene, ctx)


def waveform_section(sim, ctx, pts, post=None, system=None) -> str:
    """Example waveforms; with the posterior's fit overlaid when the depth posteriors ran.

    ``post`` is the posterior stage's result (None when it did not run) and ``system`` the
    :class:`~pipeline.uncertainty.waveform_model.WaveformSystem` the posteriors used.
    """
    kept, r = sim.kept, sim.returns
    if kept is not None and not hasattr(kept, "samples"):
        return para(
            "Photon counting: no waveform per pulse. The depth posteriors sampled the height "
            "histograms of the accumulation windows kept by the chunk loop (their events in "
            "time along one shot's beam, with each bin's live share under the dead time)."
        )
    if kept is None or not kept.pulse_id.size:
        return para(
            "No waveform was kept in this run: the chunk loop keeps waveforms only for the "
            "depth posteriors (process.posterior_*), which did not run."
        )
    n_samples = kept.samples.shape[1]
    fits = _posterior_fits(post, system, n_samples)
    order = np.argsort(r.pulse_id)
    idx = order[np.searchsorted(r.pulse_id, kept.pulse_id, sorter=order)]
    # what the pulses became: a class-40 bottom (its depth) or a class-45 no-bottom limit
    depth40 = np.full(kept.pulse_id.size, np.nan)
    is40 = pts.classification == BATHYMETRIC_POINT
    hit = np.isin(kept.pulse_id, pts.pulse_id[is40])
    o40 = np.argsort(pts.pulse_id[is40])
    at = o40[np.searchsorted(pts.pulse_id[is40], kept.pulse_id[hit], sorter=o40)]
    depth40[hit] = pts.depth_m[is40][at]
    # with posteriors, the examples are bottoms that have one, so their fit can be shown
    with_fit = hit & np.isin(kept.pulse_id, np.fromiter(fits, dtype=np.int64, count=len(fits)))
    cand = with_fit if with_fit.any() else hit
    pick = []
    if cand.any():  # the shallowest, median and deepest class-40 bottom kept
        ranked = np.flatnonzero(cand)[np.argsort(depth40[cand])]
        pick = sorted({int(ranked[0]), int(ranked[len(ranked) // 2]), int(ranked[-1])})
    limit = np.flatnonzero(
        np.isin(kept.pulse_id, pts.pulse_id[pts.classification == NO_BOTTOM_FOUND_AT])
    )
    if limit.size:  # one no-bottom pulse in place of the median bottom
        pick = (pick[:1] + pick[-1:] if len(pick) == 3 else pick) + [int(limit[0])]
    # shallow to deep, the no-bottom pulse last
    pick = sorted(pick[:N_WAVEFORMS] or [0], key=lambda i: np.nan_to_num(depth40[i], nan=np.inf))
    t_ns = np.arange(n_samples) * ctx.instrument.sample_interval_s * 1e9
    marks = []
    for i in pick:
        j = idx[i]
        m = {"title": f"pulse {int(kept.pulse_id[i])}"}
        if r.has_surface[j]:
            m["surface"] = (r.t_surface_s[j] - kept.t0_s[i]) * 1e9
        if np.isfinite(depth40[i]):
            m["bottom"] = (r.t_bottom_s[j] - kept.t0_s[i]) * 1e9
            m["title"] += f": class-40 bottom at {depth40[i]:.2f} m depth"
        elif r.t_no_bottom_s is not None and r.t_no_bottom_s[j] > 0:
            m["no-bottom limit"] = (r.t_no_bottom_s[j] - kept.t0_s[i]) * 1e9
            m["title"] += ": no bottom found down to its limit (class 45)"
        marks.append(m)
    curves = [fits.get(int(kept.pulse_id[i])) for i in pick]
    fig = F.waveforms(t_ns, kept.samples[pick].astype(float), marks, curves)
    n_fit = sum(c is not None for c in curves)
    fit_text = (
        f" {n_fit} of them show the depth posterior's fit (the waveform model at the per-"
        "parameter posterior median) in green."
        if n_fit
        else " No posterior fit is drawn: the depth posteriors did not run or sampled none of "
        "these pulses."
    )
    return img(fig, "example waveforms") + para(
        f"{len(pick)} of the {kept.pulse_id.size} waveforms kept for the posteriors (the "
        "shallowest and deepest class-40 bottoms, a class-45 pulse), with the detector's times."
        + fit_text
    )
