"""A survey's cell uncertainty again, after the TPU: posteriors in, rejected soundings out.

Both give back the :class:`~pipeline.uncertainty.survey_uncertainty.SurveyUncertainty` they are
handed with its cells (and order summary) made again; the points' TPU stays as it was.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from pipeline import iho
from pipeline.process.grid import Grid
from pipeline.uncertainty.cell_uncertainty import cell_uncertainty
from pipeline.uncertainty.tpu_settings import take_tpu

__all__ = ["with_posteriors", "without_points"]


def with_posteriors(unc, grid: Grid, point_index: np.ndarray, converged: np.ndarray, std_m):
    """Cell uncertainty again, the converged posteriors' depth sigma in place of the timing.

    The posterior covers the waveform timing of both returns (and its nuisances), which the
    TPU's timing terms approximate; in the cells where points were sampled their variance
    replaces those terms (:func:`pipeline.uncertainty.cell_uncertainty.cell_uncertainty`).

    Parameters
    ----------
    point_index : (k,) int
        Rows of ``unc.points40`` that were sampled.
    converged : (k,) bool
    std_m : (k,) float
        Posterior depth sigma of each.
    """
    n = len(unc.points40)
    sampled = np.zeros(n, dtype=bool)
    sigma = np.zeros(n)
    sampled[point_index[converged]] = True
    sigma[point_index[converged]] = np.asarray(std_m)[converged]
    cells = cell_uncertainty(grid, unc.tpu40, posterior_sigma_v_m=sigma, has_posterior=sampled)
    return dataclasses.replace(unc, cells=cells, summary=iho.order_summary(cells.order).to_dict())


def without_points(unc, keep: np.ndarray, grid: Grid):
    """The uncertainty of the kept bathymetric points only, cells again on ``grid``.

    Processing that rejects soundings after the TPU
    (:mod:`pipeline.process.seabed_outliers`) leaves the other points' TPU as it was; the
    rejected ones leave the TPU check and the cells (``grid``: gridded without them).

    Parameters
    ----------
    unc : SurveyUncertainty
    keep : (len(unc.points40),) bool
        The bathymetric points that stay.
    grid : Grid
    """
    keep = np.asarray(keep, dtype=bool)
    tpu40 = take_tpu(unc.tpu40, np.flatnonzero(keep))
    is40 = unc.is40.copy()
    is40[np.flatnonzero(unc.is40)[~keep]] = False
    cells = cell_uncertainty(grid, tpu40)
    return dataclasses.replace(
        unc,
        tpu40=tpu40,
        points40=unc.points40.select(keep),
        is40=is40,
        cells=cells,
        summary=iho.order_summary(cells.order).to_dict(),
    )
