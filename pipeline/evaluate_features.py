"""Seabed features against the truth: was each IHO S-44 cube detected, and the grid as seabed.

Evaluation side (meets the truth). IHO S-44 (6th ed., 2020) asks a survey of a given order to
*detect* cubic features of a given side (special order 1 m, exclusive order 0.5 m, order 1a
2 m). Per cube of a scene's ``[[seabed.features]]`` (other feature kinds are not scored):

* **points on its top**: seabed soundings (class 40 or 43) inside its (rotated) footprint whose
  depth lies within half its side of the true depth there (the top): nearer the top than the
  seabed around it, so the sounding shows the feature;
* **a grid cell that shows it**: the cell holding the cube's centre is shallower than the
  median of its (up to) eight neighbours by more than half the cube's side;
* **class 43**: submerged-object points (:mod:`pipeline.process.objects`) within 1 m of its
  footprint (the horizontal uncertainty of a sounding);
* **detected**: points on its top or a grid cell that shows it;
* **density**: seabed soundings per m² in its footprint grown by 1 m on each side (the density
  the feature was surveyed at, not a 5 m disc that a profiler's line can cross beside it).

Class-43 points away from every cube are reported as ``object_points_elsewhere`` (false
objects, or real shoal blunders of the soundings).

The grid as **seabed elevation**: each non-empty cell's elevation ``z_m`` against the true
seabed height at its centre (positive: the grid lies above the seabed).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pipeline.evaluate import cell_truth, error_stats, truth_at
from pipeline.process.classify import SEABED_CLASSES, SUBMERGED_OBJECT
from pipeline.process.grid_axes import held_index

__all__ = [
    "OBJECT_MARGIN_M",
    "cube_detection",
    "feature_summary",
    "grid_elevation_errors_m",
    "features_report",
]

#: class-43 points within this of a cube's footprint count as finding it
OBJECT_MARGIN_M = 1.0


def _frame(xy: np.ndarray, f) -> tuple[np.ndarray, np.ndarray]:
    """Along- and across-heading offsets of ``xy`` from the feature's centre."""
    h = math.radians(f.heading_deg)
    dx, dy = xy[:, 0] - f.x_m, xy[:, 1] - f.y_m
    return dx * math.sin(h) + dy * math.cos(h), dx * math.cos(h) - dy * math.sin(h)


def _grid_shows(grid, f) -> tuple[bool, float | None, float | None]:
    """Whether the grid cell at the cube's centre stands above its neighbours' median by s/2."""
    if grid is None:
        return False, None, None
    w, _, _, n = grid.bounds_m
    r = grid.resolution_m
    col, row = math.floor((f.x_m - w) / r), math.floor((n - f.y_m) / r)
    ny, nx = grid.shape
    if getattr(grid, "rows", None) is not None:
        # a grid of some rows and columns: the cube's cell among them (its ring is held too:
        # grid_axes.MARGIN_CELLS around every cell holding a point)
        (row,), r_ok = held_index([row], grid.rows)
        (col,), c_ok = held_index([col], grid.cols)
        if not (r_ok[0] and c_ok[0]):
            return False, None, None
    if not (0 <= row < ny and 0 <= col < nx) or grid.count[row, col] == 0:
        return False, None, None
    ring = grid.depth_m[max(row - 1, 0) : row + 2, max(col - 1, 0) : col + 2].copy()
    ring[min(row, 1), min(col, 1)] = np.nan  # the centre cell itself
    ring = ring[np.isfinite(ring)]
    cell = float(grid.depth_m[row, col])
    if ring.size == 0:
        return False, cell, None
    around = float(np.median(ring))
    return bool(around - cell > 0.5 * f.size_m), cell, around


def cube_detection(features, points, truth_depth_m, grid=None, grid_truth_depth_m=None):
    """Per cube feature: the soundings, grid cell and class-43 points that show it.

    Parameters
    ----------
    features : sequence
        The scene's ``seabed.features`` (``kind``, ``x_m``, ``y_m``, ``size_m``,
        ``heading_deg``); only cubes are scored.
    points : Points
        Classified points (``xyz_m``, ``depth_m``, ``classification``; ``pulse_id`` when the
        truth is per pulse).
    truth_depth_m : callable
        True depth below the points' reference at local ``(x, y)`` (per pulse when it says so).
    grid : Grid, optional
    grid_truth_depth_m : callable, optional
        True depth below the grid's datum; gives ``top_depth_m`` (else ``truth_depth_m``).

    Returns
    -------
    list of dict
        One per cube: ``x_m``, ``y_m``, ``size_m``, ``top_depth_m``, ``base_depth_m``,
        ``density_per_m2``, ``points_in_footprint``, ``points_on_top``, ``object_points``,
        ``grid_cell_depth_m``, ``grid_around_depth_m``, ``grid_shows``, ``detected``.
    """
    cls = np.asarray(points.classification)
    sea = np.isin(cls, SEABED_CLASSES)
    xy = np.asarray(points.xyz_m)[sea, :2]
    depth = np.asarray(points.depth_m)[sea]
    pid = getattr(points, "pulse_id", None)
    pid = None if pid is None else np.asarray(pid)[sea]
    true_d = truth_at(truth_depth_m, xy[:, 0], xy[:, 1], pid) if xy.size else np.zeros(0)
    is43 = cls[sea] == SUBMERGED_OBJECT
    top_fn = grid_truth_depth_m or truth_depth_m
    out = []
    for f in features:
        if f.kind != "cube":
            continue
        s = float(f.size_m)
        along, across = _frame(xy, f)
        inside = (np.abs(along) <= 0.5 * s) & (np.abs(across) <= 0.5 * s)
        grown = 0.5 * s + OBJECT_MARGIN_M
        box = (np.abs(along) <= grown) & (np.abs(across) <= grown)
        on_top = inside & (np.abs(depth - true_d) < 0.5 * s)
        top = float(np.asarray(top_fn(np.array([f.x_m]), np.array([f.y_m])))[0])
        shows, cell, around = _grid_shows(grid, f)
        out.append(
            {
                "x_m": float(f.x_m),
                "y_m": float(f.y_m),
                "size_m": s,
                "top_depth_m": top,
                "base_depth_m": top + s,
                "density_per_m2": float(box.sum() / (2.0 * grown) ** 2),
                "points_in_footprint": int(inside.sum()),
                "points_on_top": int(on_top.sum()),
                "object_points": int((box & is43).sum()),
                "grid_cell_depth_m": cell,
                "grid_around_depth_m": around,
                "grid_shows": shows,
                "detected": bool(on_top.any() or shows),
            }
        )
    return out


def feature_summary(cubes: list[dict], points, features) -> dict[str, Any]:
    """Per cube size: counts detected (any way, by points, by the grid, by class 43).

    Also the class-43 points in all and those away from every cube.
    """
    by_size: dict[str, dict[str, int]] = {}
    for c in cubes:
        d = by_size.setdefault(
            f"{c['size_m']:g}", dict.fromkeys(("n", "detected", "points", "grid", "class43"), 0)
        )
        d["n"] += 1
        d["detected"] += int(c["detected"])
        d["points"] += int(c["points_on_top"] > 0)
        d["grid"] += int(c["grid_shows"])
        d["class43"] += int(c["object_points"] > 0)
    is43 = np.asarray(points.classification) == SUBMERGED_OBJECT
    xy = np.asarray(points.xyz_m)[is43, :2]
    near = np.zeros(len(xy), dtype=bool)
    for f in features:
        if f.kind == "cube":
            along, across = _frame(xy, f)
            g = 0.5 * f.size_m + OBJECT_MARGIN_M
            near |= (np.abs(along) <= g) & (np.abs(across) <= g)
    return {
        "cubes_by_size": by_size,
        "object_points": int(is43.sum()),
        "object_points_elsewhere": int((~near).sum()),
    }


def grid_elevation_errors_m(grid, truth_z_m) -> np.ndarray:
    """Non-empty cells' elevation minus the true seabed height at their centres, (k,) m.

    A designated cell (a feature's least depth) against the highest true seabed in the cell.
    """
    full = grid.count > 0
    return grid.z_m[full] - cell_truth(grid, truth_z_m, shoal=np.maximum)[full]


def features_report(scene, points, truth_depth_m, grid, grid_truth_depth_m, truth_z_m):
    """The ``features`` and ``grid_elevation`` entries of ``evaluation.json``."""
    feats = scene.seabed.features
    cubes = cube_detection(feats, points, truth_depth_m, grid, grid_truth_depth_m)
    return {
        "features": {
            "rule": "detected: a sounding within s/2 of the cube's top inside its footprint, "
            "or the grid cell at its centre shallower than its neighbours' median by > s/2",
            "cubes": cubes,
            **feature_summary(cubes, points, feats),
        },
        "grid_elevation": error_stats(grid_elevation_errors_m(grid, truth_z_m)).to_dict(),
    }
