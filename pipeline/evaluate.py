"""Comparison with the truth: the only module that meets it.

The truth comes in as a callable, never by import: ``truth_depth_m(x_m, y_m)`` (depth below the
water level, positive down) or ``truth_z_m(x_m, y_m)`` (seabed elevation in the local frame),
both vectorised over local coordinates. The orchestrator builds it from the simulated world.
Over a moving sea the depth below the surface depends on when the pulse saw it: a truth callable
with a true ``per_pulse`` attribute is called ``truth_depth_m(x_m, y_m, pulse_id)`` for points
(each point's own pulse), and as ``truth_depth_m(x_m, y_m)`` where there is no pulse (cells).

Errors are *depth* errors, positive when the measurement is too deep:
``error = depth_measured - depth_true`` with ``truth_depth_m``, or
``error = z_true - z_measured`` with ``truth_z_m``.

IHO S-44 (6th edition, 2020), Table 1 (from :mod:`pipeline.iho`, re-exported here): the maximum
allowable total vertical uncertainty at the 95 % confidence level is
``TVU(d) = sqrt(a^2 + (b d)^2)``:

=========  ======  =======
order      a (m)   b
=========  ======  =======
Exclusive  0.15    0.0075
Special    0.25    0.0075
1a, 1b     0.50    0.013
2          1.00    0.023
=========  ======  =======

``fraction_within`` is the fraction of compared points (or grid cells) whose absolute error is
within the allowance at their depth; ``meets`` is ``fraction_within >= 0.95``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.iho import IHO_CONFIDENCE, IHO_ORDERS, tvu_allowance_m
from pipeline.process.classify import BATHYMETRIC_POINT, WATER_COLUMN
from pipeline.process.grid import Grid
from pipeline.process.returns import Points

__all__ = [
    "IHO_ORDERS",
    "IHO_CONFIDENCE",
    "ErrorStats",
    "IhoResult",
    "ErrorReport",
    "tvu_allowance_m",
    "error_stats",
    "truth_at",
    "iho_fractions",
    "point_errors_m",
    "grid_errors_m",
    "cell_truth",
    "evaluate",
    "water_column_report",
]

TruthFn = Callable[[np.ndarray, np.ndarray], Any]


@dataclass(frozen=True)
class ErrorStats:
    """Summary of depth errors (m).

    Count, bias (mean), standard deviation, RMSE, 95th percentile and maximum of the absolute
    error; NaN statistics when ``n == 0``.
    """

    n: int
    bias_m: float
    std_m: float
    rmse_m: float
    p95_abs_m: float
    max_abs_m: float

    def to_dict(self) -> dict[str, Any]:
        """Plain data; NaN becomes None (JSON has no NaN)."""
        return {k: _json_number(v) for k, v in dataclasses.asdict(self).items()}


@dataclass(frozen=True)
class IhoResult:
    """Share of errors within one IHO order's TVU allowance."""

    order: str
    a_m: float
    b: float
    n: int
    fraction_within: float
    meets: bool

    def to_dict(self) -> dict[str, Any]:
        """Plain data; NaN becomes None."""
        return {k: _json_number(v) for k, v in dataclasses.asdict(self).items()}


@dataclass(frozen=True)
class ErrorReport:
    """Point and grid errors against the truth, before and after refraction correction."""

    points: ErrorStats
    points_uncorrected: ErrorStats | None
    grid: ErrorStats | None
    iho_points: tuple[IhoResult, ...]
    iho_grid: tuple[IhoResult, ...]

    def to_dict(self) -> dict[str, Any]:
        """Plain, JSON-ready data."""
        return {
            "points": self.points.to_dict(),
            "points_uncorrected": None
            if self.points_uncorrected is None
            else self.points_uncorrected.to_dict(),
            "grid": None if self.grid is None else self.grid.to_dict(),
            "iho_points": {r.order: r.to_dict() for r in self.iho_points},
            "iho_grid": {r.order: r.to_dict() for r in self.iho_grid},
            "sign": "error = measured depth - true depth (positive: too deep)",
        }


def _json_number(v: Any) -> Any:
    if isinstance(v, float) and not np.isfinite(v):
        return None
    return v


def error_stats(errors_m: Any) -> ErrorStats:
    """Bias, standard deviation (ddof 0), RMSE, 95th-percentile and max absolute error."""
    e = np.asarray(errors_m, dtype=np.float64).ravel()
    e = e[np.isfinite(e)]
    if e.size == 0:
        nan = float("nan")
        return ErrorStats(0, nan, nan, nan, nan, nan)
    a = np.abs(e)
    return ErrorStats(
        n=int(e.size),
        bias_m=float(e.mean()),
        std_m=float(e.std()),
        rmse_m=float(np.sqrt(np.mean(e * e))),
        p95_abs_m=float(np.percentile(a, 95.0)),
        max_abs_m=float(a.max()),
    )


def iho_fractions(errors_m: Any, depth_m: Any) -> tuple[IhoResult, ...]:
    """Per IHO order, the fraction of finite errors within ``TVU(depth)``."""
    e = np.asarray(errors_m, dtype=np.float64).ravel()
    d = np.asarray(depth_m, dtype=np.float64).ravel()
    ok = np.isfinite(e) & np.isfinite(d)
    e, d = e[ok], np.maximum(d[ok], 0.0)
    out = []
    for order, (a, b) in IHO_ORDERS.items():
        frac = float(np.mean(np.abs(e) <= tvu_allowance_m(d, order))) if e.size else float("nan")
        out.append(IhoResult(order, a, b, int(e.size), frac, bool(frac >= IHO_CONFIDENCE)))
    return tuple(out)


#: Points per call of a truth function: a seabed's or a sea's evaluation holds temporaries of
#: a few hundred bytes per point (the Palmer benchmark's evaluation held 206 MB for 300 k
#: pulses' points at once); in blocks they stay bounded whatever the survey's size.
TRUTH_BLOCK = 65_536


def truth_at(fn: TruthFn, x: np.ndarray, y: np.ndarray, pulse_id: Any = None) -> np.ndarray:
    """The truth at points ``(n,)``, each at its own pulse's time when the truth is per pulse.

    Shared by every evaluation (points, per-point file, features) so a moving sea is met the
    same way everywhere. Evaluated :data:`TRUTH_BLOCK` points at a time (a truth is a function
    of each point alone: the same values as one call); a per-pulse truth's blocks go in pulse
    order, so a moving sea meets each of its time slabs once, as one call would.
    """
    per_pulse = pulse_id is not None and getattr(fn, "per_pulse", False)
    x = np.asarray(x, dtype=np.float64).ravel()
    y = np.asarray(y, dtype=np.float64).ravel()
    pid = np.asarray(pulse_id).ravel() if per_pulse else None
    order = np.arange(x.size) if pid is None else np.argsort(pid, kind="stable")
    out = np.empty(x.size)
    for a in range(0, x.size, TRUTH_BLOCK):
        b = order[a : a + TRUTH_BLOCK]
        v = fn(x[b], y[b]) if pid is None else fn(x[b], y[b], pid[b])
        out[b] = np.asarray(v, dtype=np.float64).ravel()
    return out


def _truth(truth_depth_m, truth_z_m):
    if (truth_depth_m is None) == (truth_z_m is None):
        raise ValueError("give exactly one of `truth_depth_m` and `truth_z_m`")


def point_errors_m(
    points: Points,
    *,
    truth_depth_m: TruthFn | None = None,
    truth_z_m: TruthFn | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Depth errors of ``points`` and the true depths used for the IHO allowance.

    With ``truth_z_m`` the depth for the allowance is the measured ``depth_m`` (clipped at 0).
    """
    _truth(truth_depth_m, truth_z_m)
    x, y, z = points.xyz_m[:, 0], points.xyz_m[:, 1], points.xyz_m[:, 2]
    if truth_depth_m is not None:
        true_d = truth_at(truth_depth_m, x, y, points.pulse_id)
        return points.depth_m - true_d, true_d
    true_z = truth_at(truth_z_m, x, y, points.pulse_id)
    return true_z - z, np.maximum(points.depth_m, 0.0)


def grid_errors_m(
    grid: Grid,
    *,
    truth_depth_m: TruthFn | None = None,
    truth_z_m: TruthFn | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Cell errors (truth at the cell centres; NaN where empty) and depths for the allowance.

    A designated cell (``grid.designated``: the least depth of a submerged object in it) is
    scored against the least true depth in the cell (:func:`cell_truth`), what it states.
    """
    _truth(truth_depth_m, truth_z_m)
    empty = grid.count == 0
    if truth_depth_m is not None:
        true_d = cell_truth(grid, truth_depth_m, shoal=np.minimum)
        err = np.where(empty, np.nan, grid.depth_m - np.where(empty, 0.0, true_d))
        return err, true_d
    true_z = cell_truth(grid, truth_z_m, shoal=np.maximum)
    err = np.where(empty, np.nan, true_z - np.where(empty, 0.0, grid.z_m))
    return err, np.where(empty, np.nan, grid.depth_m)


#: samples per cell side for the least true depth of a designated cell
_CELL_SAMPLES = 21


def cell_truth(grid: Grid, fn: TruthFn, shoal=np.minimum) -> np.ndarray:
    """The truth ``fn(x, y)`` at the non-empty cells' centres, ``(ny, nx)``, NaN elsewhere.

    At designated cells, its extreme: ``shoal`` (``np.minimum`` for depths, ``np.maximum``
    for elevations) over ``_CELL_SAMPLES`` x ``_CELL_SAMPLES`` points spanning the cell (edges
    included), so a designated sounding (a feature's least depth) is compared with the cell's
    shoalest truth.

    Only cells holding soundings (``grid.count > 0``, or designated) are evaluated, by
    :func:`truth_at`'s bounded blocks: a truth holds a few hundred bytes a point while it is
    evaluated (:data:`TRUTH_BLOCK`), and a survey's grid can have millions of cells, most of
    them empty where its soundings are sparse.
    """
    des = getattr(grid, "designated", None)
    has_des = des is not None and bool(np.any(des))
    want = grid.count > 0
    if has_des:
        want = want | des
    rows, cols = np.nonzero(want)
    out = np.full(grid.count.shape, np.nan)
    out[rows, cols] = truth_at(fn, grid.x_m[cols], grid.y_m[rows])
    if not has_des:
        return out
    r = grid.resolution_m
    off = np.linspace(-0.5, 0.5, _CELL_SAMPLES) * r * (1.0 - 1e-9)
    ox, oy = (a.ravel() for a in np.meshgrid(off, off))
    rows, cols = np.nonzero(des)
    cx, cy = grid.x_m[cols], grid.y_m[rows]
    vals = np.asarray(fn(cx[:, None] + ox, cy[:, None] + oy), dtype=np.float64)
    out[rows, cols] = shoal.reduce(vals, axis=1)
    return out


def evaluate(
    points: Points,
    *,
    uncorrected: Points | None = None,
    grid: Grid | None = None,
    truth_depth_m: TruthFn | None = None,
    truth_z_m: TruthFn | None = None,
    grid_truth_depth_m: TruthFn | None = None,
    classes: tuple[int, ...] = (BATHYMETRIC_POINT,),
) -> ErrorReport:
    """Compare processed points (and optionally the uncorrected points and the grid) with truth.

    Parameters
    ----------
    points : Points
        Refraction-corrected, classified points; only ``classes`` are compared.
    uncorrected : Points, optional
        The same bottom returns without refraction correction (same classes compared).
    grid : Grid, optional
        Gridded seabed; compared at the cell centres.
    truth_depth_m, truth_z_m : callable
        Exactly one: the truth as a function of local ``(x, y)``.
    grid_truth_depth_m : callable, optional
        The true depth below the grid's datum (the mean water level) as a function of local
        ``(x, y)``, for a grid whose depths are below a datum rather than below the local
        surface the points' ``depth_m`` use; default: ``truth_depth_m`` / ``truth_z_m``.
    classes : tuple of int
        Class codes compared (default 40, bathymetric point).

    Returns
    -------
    ErrorReport
    """
    _truth(truth_depth_m, truth_z_m)
    kw = {"truth_depth_m": truth_depth_m, "truth_z_m": truth_z_m}

    def pick(p: Points) -> Points:
        return p.select(np.isin(p.classification, np.asarray(classes, dtype=np.uint8)))

    err, depth = point_errors_m(pick(points), **kw)
    raw = None
    if uncorrected is not None:
        raw = error_stats(point_errors_m(pick(uncorrected), **kw)[0])
    gstats, giho = None, ()
    if grid is not None:
        gkw = kw if grid_truth_depth_m is None else {"truth_depth_m": grid_truth_depth_m}
        gerr, gdepth = grid_errors_m(grid, **gkw)
        gstats, giho = error_stats(gerr), iho_fractions(gerr, gdepth)
    return ErrorReport(error_stats(err), raw, gstats, iho_fractions(err, depth), giho)


def water_column_report(
    points: Points, layer_depth_m: float | None, layer_thickness_m: float | None = None
) -> dict[str, Any]:
    """Class-64 (water column) points against the scene's scattering layer.

    Parameters
    ----------
    points : Points
        Classified points; only class 64 is looked at.
    layer_depth_m : float or None
        True depth of the layer's centre below the water level (the scene's
        ``water.layer_depth_m``); None or 0 when the scene has no layer: every class-64
        point is then a false alarm and only the count is reported.
    layer_thickness_m : float, optional
        The layer's thickness: adds the fraction of points within its half-thickness.

    Returns
    -------
    dict
        ``n`` (class-64 points), ``layer_depth_m``, ``median_error_m`` and ``error``
        (:class:`ErrorStats` of ``depth_m - layer_depth_m``, positive: too deep),
        ``fraction_within_layer`` (with a thickness); None where not applicable.
    """
    depth = points.depth_m[points.classification == WATER_COLUMN]
    out: dict[str, Any] = {"n": int(depth.size), "layer_depth_m": None}
    out.update(median_error_m=None, error=None, fraction_within_layer=None)
    if not layer_depth_m:
        return out
    err = depth - layer_depth_m
    out["layer_depth_m"] = float(layer_depth_m)
    out["error"] = error_stats(err).to_dict()
    if err.size:
        out["median_error_m"] = float(np.median(err))
        if layer_thickness_m is not None:
            out["fraction_within_layer"] = float(np.mean(np.abs(err) <= 0.5 * layer_thickness_m))
    return out
