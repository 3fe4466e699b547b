"""What a sweep's table says: the Pareto front of error against cost, the cheapest run per order.

Pure functions of the sweep's columns (:mod:`pipeline.sweep` fills them from each run's
``evaluation.json`` and manifest), so they can be checked on hand-made tables.

Meeting an IHO S-44 order (our rule, stated in ``sweep.json``): at least
:data:`pipeline.iho.IHO_CONFIDENCE` (95 %) of the run's class-40 soundings have
``|measured - true depth| <= TVU(order, true depth)`` (``evaluation.json``,
``error.iho_points``). S-44 states its allowances at 95 % confidence; this reads them as a
share of the soundings' actual errors, which only a simulation with a truth can give.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.iho import CLASSIFIED_ORDERS, IHO_CONFIDENCE

__all__ = ["pareto_front", "strictest_met", "cheapest_meeting"]


def pareto_front(cost: Any, error: Any) -> np.ndarray:
    """Runs no other run beats: none is at most as costly and as wrong, and better in one.

    Parameters
    ----------
    cost, error : (n,) array_like
        Cost (e.g. CPU seconds per km²) and error (e.g. depth RMSE, m) of each run; both
        smaller is better. Runs with a non-finite value are never on the front.

    Returns
    -------
    (n,) bool ndarray
        True for the runs on the front (ties: equal runs are both on it).
    """
    c = np.asarray(cost, dtype=np.float64).ravel()
    e = np.asarray(error, dtype=np.float64).ravel()
    if c.shape != e.shape:
        raise ValueError(f"`cost` {c.shape} and `error` {e.shape} must have the same length")
    ok = np.isfinite(c) & np.isfinite(e)
    # dominated[i, j]: run j is at most run i in both and strictly better in one (O(n²): a
    # sweep has tens of runs)
    no_worse = (c[None, :] <= c[:, None]) & (e[None, :] <= e[:, None])
    better = (c[None, :] < c[:, None]) | (e[None, :] < e[:, None])
    dominated = (no_worse & better & ok[None, :]).any(axis=1)
    return ok & ~dominated


def strictest_met(fractions: dict[str, Any], threshold: float = IHO_CONFIDENCE) -> np.ndarray:
    """The strictest order each run meets, ``"none"`` when it meets none.

    Parameters
    ----------
    fractions : dict of str to (n,) array_like
        Per order of :data:`pipeline.iho.CLASSIFIED_ORDERS`, each run's fraction of soundings
        within the order's TVU (NaN: no sounding, never met).
    threshold : float
        Fraction at least (95 %).

    Returns
    -------
    (n,) ndarray of str
    """
    n = len(np.atleast_1d(fractions[CLASSIFIED_ORDERS[0]]))
    out = np.full(n, "none", dtype=object)
    for order in reversed(CLASSIFIED_ORDERS):  # loosest first: the strictest met is written last
        f = np.asarray(fractions[order], dtype=np.float64).ravel()
        out[np.nan_to_num(f, nan=-1.0) >= threshold] = order
    return out.astype(str)


def cheapest_meeting(
    cost: Any, fractions: dict[str, Any], threshold: float = IHO_CONFIDENCE
) -> dict[str, int | None]:
    """Per order, the index of the cheapest run meeting it (None when no run does).

    Parameters
    ----------
    cost : (n,) array_like
        Cost of each run; a run with a non-finite cost is never chosen.
    fractions : dict of str to (n,) array_like
        As :func:`strictest_met`.
    threshold : float

    Returns
    -------
    dict of str to int or None
        Keyed by :data:`pipeline.iho.CLASSIFIED_ORDERS`; ties go to the first run.
    """
    c = np.asarray(cost, dtype=np.float64).ravel()
    out: dict[str, int | None] = {}
    for order in CLASSIFIED_ORDERS:
        f = np.asarray(fractions[order], dtype=np.float64).ravel()
        meets = (np.nan_to_num(f, nan=-1.0) >= threshold) & np.isfinite(c)
        out[order] = int(np.flatnonzero(meets)[np.argmin(c[meets])]) if meets.any() else None
    return out
