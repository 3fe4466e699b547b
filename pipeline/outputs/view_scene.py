"""The 3D scene of a survey run as plain arrays: points, true seabed, water surface, beams.

Built by the ``views`` stage of :mod:`pipeline.run_survey`, on the evaluation side (it reads
``sim.truth`` for the seabed and water meshes and the per-point depth error, as
:mod:`pipeline.outputs.report` does); :mod:`pipeline.outputs.view3d` turns it into ``.vtp``
files and pictures. Numpy only: building it cannot fail for want of a renderer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.evaluate import truth_at
from pipeline.process.classify import BATHYMETRIC_POINT
from pipeline.process.returns import ReturnKind

__all__ = ["ViewScene", "Surface", "view_scene", "surface_grid", "pick_beams"]

#: Beams (aircraft -> surface point -> bottom point) drawn at most.
N_BEAMS = 8
#: Vertices of a truth surface mesh per axis at most (a 200 x 200 mesh: 40 000 vertices).
MAX_SURFACE_VERTICES = 200
#: Margin around the points where the truth surfaces are drawn, metres.
SURFACE_MARGIN_M = 2.0


@dataclass(frozen=True)
class Surface:
    """A height field on a regular grid: ``z_m[j, i]`` at ``(x_m[i], y_m[j])``, local frame.

    Attributes
    ----------
    x_m : (nx,) float64
    y_m : (ny,) float64
    z_m : (ny, nx) float64
        Height (up) in the local frame, metres.
    """

    x_m: np.ndarray
    y_m: np.ndarray
    z_m: np.ndarray


@dataclass(frozen=True)
class ViewScene:
    """Everything the 3D views show, in the local frame (x east, y north, z up; metres).

    Attributes
    ----------
    xyz_m : (n, 3) float64
        Every point of ``points.laz``, in its order.
    classification : (n,) uint8
    depth_m : (n,) float64
        Depth below the local fitted water surface, as in the LAS file.
    error_m : (n,) float64
        Measured minus true depth for class-40 points; NaN for every other point (their
        depth is not a seabed depth, so it has no error against the seabed).
    uncertainty_v_m : (n,) float64
        The LAS ``uncertainty_v_m``: the propagated TPU (one sigma of z) of the class-40 points
        with a TPU, the a-priori value of the others.
    seabed : Surface
        The true seabed.
    water : Surface
        The true water surface.
    beams_m : (k, 3, 3) float64
        Per beam the measured aircraft position, the pulse's surface point and its class-40
        bottom point.
    beam_pulse_id : (k,) int64
    origin_m : (3,) float64
        The local frame's origin in the CRS (easting, northing, 0).
    crs : str
    """

    xyz_m: np.ndarray
    classification: np.ndarray
    depth_m: np.ndarray
    error_m: np.ndarray
    uncertainty_v_m: np.ndarray
    seabed: Surface
    water: Surface
    beams_m: np.ndarray
    beam_pulse_id: np.ndarray
    origin_m: np.ndarray
    crs: str


def surface_grid(height_m, bounds_m, max_vertices: int = MAX_SURFACE_VERTICES) -> Surface:
    """Sample ``height_m(x, y)`` on a regular grid over ``bounds_m`` = (xmin, xmax, ymin, ymax).

    The step is the same along both axes, the longer side gets ``max_vertices`` vertices.
    """
    xmin, xmax, ymin, ymax = bounds_m
    step = max(xmax - xmin, ymax - ymin, 1e-6) / (max_vertices - 1)
    x = np.linspace(xmin, xmax, max(2, int(np.ceil((xmax - xmin) / step)) + 1))
    y = np.linspace(ymin, ymax, max(2, int(np.ceil((ymax - ymin) / step)) + 1))
    xx, yy = np.meshgrid(x, y)
    z = np.asarray(height_m(xx, yy), dtype=np.float64).reshape(xx.shape)
    if not np.all(np.isfinite(z)):
        raise ValueError("the truth surface is not finite over the view's bounds")
    return Surface(x, y, z)


def pick_beams(points, returns, n: int = N_BEAMS) -> tuple[np.ndarray, np.ndarray]:
    """Up to ``n`` beams spread over the survey: aircraft, surface point, bottom point.

    A pulse qualifies when it has a class-40 point and a surface (measured or derived) point;
    the beams are the qualifying pulses at evenly spaced ranks of pulse id.

    Returns
    -------
    beams_m : (k, 3, 3) float64
    pulse_id : (k,) int64
    """
    is40 = points.classification == BATHYMETRIC_POINT
    surf = np.isin(points.kind, (ReturnKind.SURFACE, ReturnKind.DERIVED_SURFACE))
    both = np.intersect1d(points.pulse_id[is40], points.pulse_id[surf])
    if not both.size:
        return np.zeros((0, 3, 3)), np.zeros(0, dtype=np.int64)
    pid = both[np.unique(np.linspace(0, both.size - 1, min(n, both.size)).round().astype(int))]

    def first_row(mask):
        # the first point of each chosen pulse among the rows in `mask`
        rows = np.flatnonzero(mask)
        order = np.argsort(points.pulse_id[rows], kind="stable")
        at = np.searchsorted(points.pulse_id[rows], pid, sorter=order)
        return rows[order[at]]

    order = np.argsort(returns.pulse_id)
    aircraft = returns.origin_meas_m[order[np.searchsorted(returns.pulse_id, pid, sorter=order)]]
    beams = np.stack(
        [aircraft, points.xyz_m[first_row(surf)], points.xyz_m[first_row(is40)]], axis=1
    )
    return beams, pid


def view_scene(points, returns, truth, origin_m, crs: str) -> ViewScene:
    """The run's 3D scene; ``truth`` (seabed, water, ``depth_m``) is read for evaluation only.

    Parameters
    ----------
    points : Points
        The processed points, as written to ``points.laz`` (with their TPU).
    returns : DetectedReturns
        The detections (measured aircraft positions of the beams).
    truth : Truth
    origin_m : sequence of 3 float
    crs : str
    """
    xyz = points.xyz_m
    is40 = points.classification == BATHYMETRIC_POINT
    error = np.full(xyz.shape[0], np.nan)
    if is40.any():
        x, y = xyz[is40, 0], xyz[is40, 1]
        error[is40] = points.depth_m[is40] - truth_at(truth.depth_m, x, y)
    # the surfaces over the points (the bathymetric ones when there are any), plus a margin
    where = xyz[is40] if is40.any() else xyz
    if not where.shape[0]:
        raise ValueError("no point to draw")
    lo, hi = where[:, :2].min(axis=0) - SURFACE_MARGIN_M, where[:, :2].max(axis=0)
    bounds = (lo[0], hi[0] + SURFACE_MARGIN_M, lo[1], hi[1] + SURFACE_MARGIN_M)
    beams, pid = pick_beams(points, returns)
    return ViewScene(
        xyz_m=xyz,
        classification=points.classification,
        depth_m=points.depth_m,
        error_m=error,
        uncertainty_v_m=points.uncertainty_v_m,
        seabed=surface_grid(truth.seabed.height_m, bounds),
        water=surface_grid(truth.water.height_m, bounds),
        beams_m=beams,
        beam_pulse_id=pid,
        origin_m=np.asarray(origin_m, dtype=np.float64),
        crs=str(crs),
    )
