"""LAS return numbers of every pulse's points, in time order (LAS 1.4 R15, "Return Number").

A pulse's points are numbered ``1 .. n`` in the order their echoes reach the receiver, ``n``
(``number_of_returns``) being how many points of that pulse there are. Every point counts,
measured or derived: the surface, an in-column return (class 64), the bottom, and the
no-bottom-found-at point (class 45, a ``BOTTOM``-kind point placed at the pulse's detection
limit, later than its surface), so a reader grouping a pulse's points finds ``1 .. n`` once
each. The order is the round-trip time's: surface before column before bottom
(:class:`~pipeline.process.returns.DetectedReturns` enforces it); a derived water-surface point
sits with the surface. Points of the same rank (a surface return and the derived entry point
of its pulse) follow the beam down: the higher one first.
"""

from __future__ import annotations

import numpy as np

from pipeline.process.returns import Points, ReturnKind

__all__ = ["TIME_RANK", "time_order_numbers", "number_all_returns"]

#: Rank of each point kind in a pulse's echo sequence (earlier first).
TIME_RANK = {
    ReturnKind.SURFACE: 1,
    ReturnKind.DERIVED_SURFACE: 1,
    ReturnKind.WATER_COLUMN: 2,
    ReturnKind.BOTTOM: 3,
}


def time_order_numbers(
    pulse_id: np.ndarray, kind: np.ndarray, z_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Return number and number of returns of every point, in time order within its pulse.

    Parameters
    ----------
    pulse_id : (n,) int
        Pulse of each point.
    kind : (n,) int
        :class:`~pipeline.process.returns.ReturnKind` of each point (an unknown kind ranks
        last).
    z_m : (n,) float
        Elevation: orders points of the same rank (higher first: the beam points down).

    Returns
    -------
    return_number, number_of_returns : (n,) uint8
        Clipped to 15 (the LAS 1.4 field's largest value).
    """
    pid = np.asarray(pulse_id, dtype=np.int64)
    kind = np.asarray(kind)
    rank = np.full(pid.shape, max(TIME_RANK.values()) + 1, dtype=np.int64)
    for k, r in TIME_RANK.items():
        rank[kind == k] = r
    order = np.lexsort((-np.asarray(z_m, dtype=np.float64), rank, pid))
    sorted_pid = pid[order]
    first = np.flatnonzero(np.r_[True, sorted_pid[1:] != sorted_pid[:-1]])
    size = np.diff(np.r_[first, sorted_pid.size])
    group = np.repeat(np.arange(first.size), size)
    number = np.empty(pid.shape, dtype=np.int64)
    total = np.empty(pid.shape, dtype=np.int64)
    number[order] = np.arange(order.size) - first[group] + 1
    total[order] = size[group]
    return np.minimum(number, 15).astype(np.uint8), np.minimum(total, 15).astype(np.uint8)


def number_all_returns(points: Points) -> Points:
    """``points`` with every pulse's points numbered ``1 .. n`` in time order."""
    number, total = time_order_numbers(points.pulse_id, points.kind, points.xyz_m[:, 2])
    return points.replace(return_number=number, number_of_returns=total)
