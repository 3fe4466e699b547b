"""Comparison with the truth: the only module that meets it.

The truth comes in as a callable, never by import: ``truth_depth_m(x_m, y_m)`` (depth below the
water level, positive down) or ``truth_z_m(x_m, y_m)`` (seabed elevation in the local frame),
both vectorised over local coordinates. The orchestrator builds it from the simulated world.

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
from pipeline.process.classify import BATHYMETRIC_POINT
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
    "iho_fractions",
    "point_errors_m",
    "grid_errors_m",
    "evaluate",
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
        true_d = np.asarray(truth_depth_m(x, y), dtype=np.float64)
        return points.depth_m - true_d, true_d
    true_z = np.asarray(truth_z_m(x, y), dtype=np.float64)
    return true_z - z, np.maximum(points.depth_m, 0.0)


def grid_errors_m(
    grid: Grid,
    *,
    truth_depth_m: TruthFn | None = None,
    truth_z_m: TruthFn | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Cell errors (truth at the cell centres; NaN where empty) and depths for the allowance."""
    _truth(truth_depth_m, truth_z_m)
    xx, yy = np.meshgrid(grid.x_m, grid.y_m)
    empty = grid.count == 0
    if truth_depth_m is not None:
        true_d = np.asarray(truth_depth_m(xx, yy), dtype=np.float64)
        err = np.where(empty, np.nan, grid.depth_m - np.where(empty, 0.0, true_d))
        return err, true_d
    true_z = np.asarray(truth_z_m(xx, yy), dtype=np.float64)
    err = np.where(empty, np.nan, true_z - np.where(empty, 0.0, grid.z_m))
    return err, np.where(empty, np.nan, grid.depth_m)


def evaluate(
    points: Points,
    *,
    uncorrected: Points | None = None,
    grid: Grid | None = None,
    truth_depth_m: TruthFn | None = None,
    truth_z_m: TruthFn | None = None,
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
        gerr, gdepth = grid_errors_m(grid, **kw)
        gstats, giho = error_stats(gerr), iho_fractions(gerr, gdepth)
    return ErrorReport(error_stats(err), raw, gstats, iho_fractions(err, depth), giho)


def tpu_coverage(
    points: Points, sigma_v_m: Any, *, truth_depth_m: TruthFn, k: float = 1.96
) -> dict[str, Any]:
    """How often the true depth lies within ``± k σ_v`` of the measured depth.

    Parameters
    ----------
    points : Points
        The points whose vertical uncertainty is ``sigma_v_m`` (same order).
    sigma_v_m : (n,) array_like
        Propagated 1σ vertical uncertainty, metres.
    truth_depth_m : callable
        True depth at local ``(x, y)``.
    k : float
        Coverage factor (1.96: the 95 % interval of a normal error).

    Returns
    -------
    dict
        ``n``, ``k``, ``fraction_within`` and the median ``|error| / sigma``.
    """
    sig = np.asarray(sigma_v_m, dtype=np.float64)
    err, _ = point_errors_m(points, truth_depth_m=truth_depth_m)
    ok = np.isfinite(err) & (sig > 0)
    z = np.abs(err[ok]) / sig[ok]
    return {
        "n": int(ok.sum()),
        "k": k,
        "fraction_within": _json_number(float(np.mean(z <= k))) if z.size else None,
        "median_abs_error_over_sigma": _json_number(float(np.median(z))) if z.size else None,
    }
