"""Per-point residuals and sigmas of a survey run: ``evaluation_points.npz``.

``evaluation.json`` gives run-level figures; a scene suite (:mod:`pipeline.suite`) pools points
of many runs into strata (wind, attenuation, slope, depth band, receiver), which needs the
points themselves. The evaluate stage (:mod:`pipeline.survey_report`) writes, next to
``evaluation.json``, one ``.npz`` of plain float/bool arrays. Like that stage it meets the
truth; processing never reads the file.

Arrays (``n`` rows per group; a group is empty when the run has none):

* ``pt_*`` - every seabed point (class 40 and 43): ``pt_x_m``, ``pt_y_m``, measured
  ``pt_depth_m`` (below the fitted local surface), ``pt_true_depth_m`` and
  ``pt_error_m = measured - true`` (positive: too deep), as ``evaluation.json``'s ``error.points``;
  ``pt_error_thu_m``: where ``|pt_error_m| > 1 m``, the error against the true depth nearest the
  measured one within the point's THU95 (:mod:`pipeline.evaluate_thu`: a sounding beside a wall
  whose depth is the wall top's); elsewhere ``pt_error_m``.
* ``tpu_*`` - the class-40 points the TPU propagated: ``tpu_true_depth_m``, ``tpu_error_m``,
  ``tpu_sigma_depth_m`` (1 σ of the depth), ``tpu_group`` (photon window, else the row),
  ``tpu_x_m``, ``tpu_y_m``, and ``tpu_term_<name>``: each term's one-sigma change of the depth
  (:data:`pipeline.uncertainty.tpu.RANDOM_TERMS`, ``CORRELATED_TERMS`` and the survey's own,
  ``PointTpu.terms``; they add in quadrature to ``tpu_sigma_depth_m``), to see which term is
  short where the coverage fails.
* ``post_*`` - sampled depth posteriors with a start: ``post_true_depth_m``, ``post_median_m``,
  ``post_lo68_m``, ``post_hi68_m``, ``post_lo95_m``, ``post_hi95_m``, ``post_converged``; and
  ``post_wave_*_m`` (same keys) the waveform posterior alone, before the TPU nuisances
  (:mod:`pipeline.uncertainty.seabed_posterior`).
* ``cell_*`` - non-empty grid cells: ``cell_x_m``, ``cell_y_m``, ``cell_depth_m`` (below the
  datum), ``cell_true_depth_m`` (below the true mean level), ``cell_error_m``, ``cell_count``.
* ``rej_*`` - the bathymetric points processing rejected as gross errors (class 7, withheld:
  :mod:`pipeline.process.seabed_outliers`): ``rej_true_depth_m``, ``rej_error_m``,
  ``rej_tvu`` (rejected for its TPU), ``rej_surface`` (for an implausible water surface;
  neither: a seabed outlier).
* ``nb_depth_m`` - measured depths of the class-45 (no-bottom-found-at) points: each is a
  pulse's own detection limit (:mod:`pipeline.process.detection_limit`), the run's measured
  extinction depth; ``nb_true_depth_m`` the true depth at each (its claim, "no bottom down to
  here", holds where the true depth is at least the point's).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.evaluate import grid_errors_m, point_errors_m, truth_at
from pipeline.evaluate_thu import error_within_thu_m
from pipeline.outputs.atomic import atomic_path
from pipeline.process.classify import NO_BOTTOM_FOUND_AT, SEABED_CLASSES
from pipeline.process.returns import PointFlag
from pipeline.process.seabed_outliers import REJECTED
from pipeline.uncertainty.tpu_settings import DEPTH

__all__ = [
    "point_arrays",
    "write_evaluation_points",
    "gross_report",
    "rejected_arrays",
    "rejected_report",
    "class45_arrays",
    "class45_report",
]


def point_arrays(
    processed,
    grid,
    unc,
    post,
    truth_depth_m,
    grid_truth_depth_m,
    group=None,
    seabed_height_m=None,
):
    """The arrays of ``evaluation_points.npz`` (see the module docstring).

    Parameters
    ----------
    processed : ProcessedPoints
    grid : Grid
    unc : SurveyUncertainty
    post : SurveyPosteriors or None
    truth_depth_m, grid_truth_depth_m : callable
        True depth below the local surface (points) and below the mean level (grid) at local
        ``(x, y)``.
    group : (n_tpu,) array_like, optional
        Shared-measurement label of the TPU points (photon windows).
    seabed_height_m : callable, optional
        True seabed height at local ``(x, y)``: ``pt_error_thu_m`` searches each gross point's
        THU95 disc on it (:func:`~pipeline.evaluate_thu.error_within_thu_m`); None: no search
        (``pt_error_thu_m`` is ``pt_error_m``).

    Returns
    -------
    dict of str to ndarray
    """
    pts = processed.points
    p40 = pts.select(np.isin(pts.classification, SEABED_CLASSES))  # 40 and 43
    err, true_d = point_errors_m(p40, truth_depth_m=truth_depth_m)
    out = {
        "pt_x_m": p40.xyz_m[:, 0],
        "pt_y_m": p40.xyz_m[:, 1],
        "pt_depth_m": p40.depth_m,
        "pt_true_depth_m": true_d,
        "pt_error_m": err,
        "pt_error_thu_m": err
        if seabed_height_m is None
        else error_within_thu_m(
            p40.xyz_m[:, 0], p40.xyz_m[:, 1], err, p40.uncertainty_h_m, seabed_height_m
        ),
    }
    terr, ttrue = point_errors_m(unc.points40, truth_depth_m=truth_depth_m)
    n_tpu = terr.size
    out.update(
        tpu_true_depth_m=ttrue,
        tpu_error_m=terr,
        tpu_sigma_depth_m=np.asarray(unc.tpu40.sigma_depth_m, dtype=np.float64),
        tpu_group=np.arange(n_tpu) if group is None else np.asarray(group).ravel(),
        tpu_x_m=np.asarray(unc.points40.xyz_m[:, 0], dtype=np.float64),
        tpu_y_m=np.asarray(unc.points40.xyz_m[:, 1], dtype=np.float64),
    )
    for name, term in unc.tpu40.terms.items():
        out[f"tpu_term_{name}"] = np.asarray(term[:, DEPTH], dtype=np.float64)
    out.update(_posterior_arrays(post, truth_depth_m))
    gerr, gtrue = grid_errors_m(grid, truth_depth_m=grid_truth_depth_m)
    xx, yy = np.meshgrid(grid.x_m, grid.y_m)
    full = grid.count > 0
    out.update(
        cell_x_m=xx[full],
        cell_y_m=yy[full],
        cell_depth_m=grid.depth_m[full],
        cell_true_depth_m=np.asarray(gtrue, dtype=np.float64)[full],
        cell_error_m=gerr[full],
        cell_count=grid.count[full],
    )
    out.update(class45_arrays(pts, truth_depth_m))
    out.update(rejected_arrays(pts, truth_depth_m))
    return out


def gross_report(error_m: np.ndarray, error_thu_m: np.ndarray) -> dict[str, int]:
    """``evaluation.json``'s ``gross_errors``: seabed points more than 1 m off.

    ``over_1m`` at their own position (``pt_error_m``); ``over_1m_beyond_thu95`` against every
    seabed within their THU95 (``pt_error_thu_m``, :mod:`pipeline.evaluate_thu`).
    """
    return {
        "over_1m": int(np.sum(np.abs(error_m) > 1.0)),
        "over_1m_beyond_thu95": int(np.sum(np.abs(error_thu_m) > 1.0)),
    }


def rejected_arrays(points, truth_depth_m) -> dict[str, np.ndarray]:
    """``rej_true_depth_m``, ``rej_error_m``, ``rej_tvu`` of the rejected soundings."""
    rej = points.select((points.flags & np.uint16(REJECTED)) != 0)
    err, true_d = point_errors_m(rej, truth_depth_m=truth_depth_m)
    tvu = (rej.flags & np.uint16(PointFlag.TVU_EXCEEDED)) != 0
    surf = (rej.flags & np.uint16(PointFlag.SURFACE_IMPLAUSIBLE)) != 0
    return {"rej_true_depth_m": true_d, "rej_error_m": err, "rej_tvu": tvu, "rej_surface": surf}


def class45_arrays(points, truth_depth_m) -> dict[str, np.ndarray]:
    """``nb_depth_m`` and ``nb_true_depth_m`` of the class-45 points (module notes)."""
    sel = np.asarray(points.classification) == NO_BOTTOM_FOUND_AT
    xyz = np.asarray(points.xyz_m, dtype=np.float64)[sel]
    pid = None if getattr(points, "pulse_id", None) is None else np.asarray(points.pulse_id)[sel]
    true = truth_at(truth_depth_m, xyz[:, 0], xyz[:, 1], pid) if sel.any() else np.zeros(0)
    return {
        "nb_depth_m": np.asarray(points.depth_m, dtype=np.float64)[sel],
        "nb_true_depth_m": np.asarray(true, dtype=np.float64),
    }


def class45_report(points, truth_depth_m) -> dict[str, int | float | None]:
    """``evaluation.json``'s ``no_bottom`` claims against the truth.

    A class-45 point claims no bottom down to its depth: it holds where the true seabed at its
    position is at least that deep. ``class45_past_seabed`` counts those that do not,
    ``class45_past_seabed_over_0.5m`` those more than 0.5 m past it (beyond a footprint's
    relief), ``class45_past_seabed_m_max`` the largest overshoot (None: none past).
    """
    a = class45_arrays(points, truth_depth_m)
    past = a["nb_depth_m"] - a["nb_true_depth_m"]
    over = past[past > 0.0]
    return {
        "class45_past_seabed": int(over.size),
        "class45_past_seabed_over_0.5m": int(np.count_nonzero(over > 0.5)),
        "class45_past_seabed_m_max": float(over.max()) if over.size else None,
    }


def rejected_report(points, truth_depth_m) -> dict[str, int | float | None]:
    """``evaluation.json``'s ``seabed_rejected``: the rejected soundings against the truth.

    Per rule, and how many were gross errors (``|error| > 1 m``) and how many were good
    (``|error| <= 0.5 m``: the test's cost).
    """
    a = rejected_arrays(points, truth_depth_m)
    e = np.abs(a["rej_error_m"])
    return {
        "n": int(e.size),
        "tvu_exceeded": int(a["rej_tvu"].sum()),
        "surface_implausible": int(a["rej_surface"].sum()),
        "seabed_outlier": int((~a["rej_tvu"] & ~a["rej_surface"]).sum()),
        "over_1m": int(np.sum(e > 1.0)),
        "within_0.5m": int(np.sum(e <= 0.5)),
        "max_abs_error_m": float(e.max()) if e.size else None,
    }


def _posterior_arrays(post, truth_depth_m) -> dict[str, np.ndarray]:
    """The ``post_*`` arrays: the started posteriors and the truth at their median position."""
    keys = ("median", "lo68", "hi68", "lo95", "hi95")
    empty = {f"post_{k}_m": np.zeros(0) for k in ("true_depth", *keys)}
    empty.update({f"post_wave_{k}_m": np.zeros(0) for k in keys})
    empty["post_converged"] = np.zeros(0, dtype=bool)
    if post is None or post.posteriors is None:
        return empty
    from pipeline.uncertainty.posterior import PosteriorFlag

    p = post.posteriors
    started = (p.flags & np.uint16(PosteriorFlag.NO_START)) == 0
    xy = p.xyz_median_m[started]
    # over a moving sea, the depth below the surface each pulse saw (as the points and
    # evaluation.json's posterior coverage): the time-0 sea is another surface
    true_d = truth_at(truth_depth_m, xy[:, 0], xy[:, 1], np.asarray(p.pulse_id)[started])
    out = {"post_true_depth_m": true_d}
    out.update({f"post_{k}_m": np.asarray(p.depth_m[k])[started] for k in keys})
    wave = getattr(p, "waveform_depth_m", None) or p.depth_m
    out.update({f"post_wave_{k}_m": np.asarray(wave[k])[started] for k in keys})
    out["post_converged"] = np.asarray(p.converged)[started]
    return out


def write_evaluation_points(path: Path, arrays: dict[str, np.ndarray]) -> Path:
    """Write ``arrays`` to ``path`` (a compressed ``.npz``) and return the path."""
    path = Path(path)
    # through an open file: numpy would append ".npz" to a temporary path without it
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)
    return path
