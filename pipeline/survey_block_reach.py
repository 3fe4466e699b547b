"""Which of a block's loaded pulses processing must make as the whole survey would (issue 15).

A block (:mod:`pipeline.survey_blocks`) loads its own pulses and a halo, keeps only its own
pulses' points and its own cells, and propagates the TPU and makes the class-43 and rejection
tests only at the points it keeps and within their tests' reach
(:func:`~pipeline.survey_blocks.tpu_points`). Processing's per-pulse work (the local water
planes, :func:`~pipeline.process.surface_fit.fit_water_surface`; the kriged sea above the
soundings and the class-45 points, :func:`~pipeline.process.refraction.seabed_points`) is
needed only at the pulses whose results those read, measured from the box holding the
block's cells and its own pulses' positions (``b`` the survey's beam reach,
:func:`~pipeline.process_tiles.beam_reach_m`):

* **kept** points lie within ``b + tests_reach_m + one grid cell`` of it (its own pulses'
  points a beam reach from their positions, then :func:`~pipeline.survey_blocks.tpu_points`'
  margin);
* **their readers** reach, from a kept point, the soundings within the TPU's reach
  (:func:`~pipeline.uncertainty.tpu_survey_wide.tpu_halo_m`: the gradient's and the pair
  scatter's searches) and another beam to their pulses; the rejection planes' references
  within ``tests_reach_m`` and a beam; the class-45 contradiction's soundings and ground
  within ``no_bottom_radius_m`` / ``no_bottom_land_radius_m`` and a beam. These read the
  soundings' depths or their classes, which read the depths (a sounding above the sea or
  shallower than ``min_depth_m`` is not class 40): within the largest of them the sea is
  kriged (``krige``).
* **the kriging** of those reads the nearest surface echoes that are water and not outliers
  of their own planes, on the pulse's beam (another beam) and within the kriging's allowance
  (the surface fit's ``radius_m``, as :func:`~pipeline.process_tiles.processing_halo_m`
  allows it); and the wave pool's cell of a kept point's entry
  (:mod:`pipeline.uncertainty.wave_pool`: a beam to its pulse, one to its entry, the cell's
  diagonal, a beam from each contributor's entry to its pulse) reads their planes' scatter
  alone. There the local planes are fitted (``planes``); they read every loaded
  water-surface point (the land decision is still made for every pulse).

Outside ``planes`` a pulse keeps the global plane, outside ``krige`` its depth reads the
plane: their points are not the survey's and nothing the block keeps reads them. The margins
are square (a superset of the round ones) and come from the settings and the beam reach
alone, never from results.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["processing_reach_m", "processing_rows"]


def processing_reach_m(ctx, ps, beam_reach_m: float) -> tuple[float, float]:
    """How far past a block's box the sea is kriged and the planes are fitted (m; module notes).

    Parameters
    ----------
    ctx : ProcessingContext
        The surface fit's and the TPU's settings.
    ps : ProcessSettings
        The scene's ``process`` (the tests', the grid's and the class-45 test's figures).
    beam_reach_m : float
        The survey's beam reach.

    Returns
    -------
    krige_m, planes_m : float
        ``planes_m >= krige_m``.
    """
    from pipeline.survey_blocks import tests_reach_m
    from pipeline.uncertainty.tpu_survey_wide import tpu_halo_m

    b = float(beam_reach_m)
    tests = tests_reach_m(ps)
    kept = b + tests + ps.grid_resolution_m
    cl = ps.classify
    radius = max(cl.no_bottom_radius_m, cl.no_bottom_land_radius_m)
    krige = kept + b + max(tpu_halo_m(ctx.tpu), tests, radius)
    pool = kept + 3.0 * b + math.sqrt(2.0) * ctx.tpu.wave_pool_cell_m
    return float(krige), float(max(krige + b + ctx.surface_fit.radius_m, pool))


def processing_rows(pos_m: np.ndarray, own: np.ndarray, box_m, reach_m: float) -> np.ndarray:
    """``(n,)`` bool: the pulses within ``reach_m`` of the box holding a block (square margin).

    Parameters
    ----------
    pos_m : (n, 2) float
        The loaded pulses' positions (:func:`~pipeline.detection_store.pulse_position_m`).
    own : (n,) bool
        The block's own pulses (an edge block's lie beyond its box: the box grows to hold
        them).
    box_m : (4,) float
        The block's own cells, ``(w, e, s, n)`` (m, local frame).
    reach_m : float
    """
    x, y = pos_m[:, 0], pos_m[:, 1]
    w, e, s, n = (float(v) for v in box_m)
    if np.any(own):
        w, e = min(w, float(x[own].min())), max(e, float(x[own].max()))
        s, n = min(s, float(y[own].min())), max(n, float(y[own].max()))
    return (x >= w - reach_m) & (x <= e + reach_m) & (y >= s - reach_m) & (y <= n + reach_m)
