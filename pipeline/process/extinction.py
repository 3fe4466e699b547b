"""The survey's extinction depth, from its own points: where it lost a seabed it found elsewhere.

Each class-45 (no-bottom-found-at) point stands at its pulse's detection limit
(:mod:`pipeline.process.detection_limit`, :mod:`pipeline.process.photon_limit`): no bottom
down to there. Where the light gave out, those limits gather at the extinction depth. Not
every class-45 point says that: over a shore a bottom merged with the surface, on a dark or
steep patch one pulse's echo was too weak, and their limits lie shallower than bottoms the
same water gave elsewhere (suite seeds 54 and 7006: a 4.2 m and a 2.0 m median in c = 0.064
and 0.076 /m water, whose seabed was found to 4.9 m and deeper). In one water, a bottom found
deeper than a limit shows the light reached deeper; so only the limits at least as deep as the
95th percentile of the class-40 depths count (the survey established the seabed that deep; the
deepest 5 % of its soundings may be the lucky bright ones past a mean limit), and the
extinction depth is their median. With fewer than :data:`MIN_CLASS45` of them the survey did
not reach it (``None``): it found a bottom wherever it sounded.
"""

from __future__ import annotations

import numpy as np

__all__ = ["MIN_CLASS45", "extinction_depth"]

#: class-45 limits needed to read an extinction depth from them
MIN_CLASS45 = 20


def extinction_depth(
    class45_depth_m: np.ndarray, class40_depth_m: np.ndarray
) -> tuple[float | None, str, float | None]:
    """``(extinction depth or None, source, seabed found to)`` of a survey's points.

    Parameters
    ----------
    class45_depth_m : (n45,) ndarray
        Depths of the class-45 points (their detection limits below the local surface).
    class40_depth_m : (n40,) ndarray
        Depths of the class-40 (bathymetric) points.

    Returns
    -------
    depth_m : float or None
        The extinction depth (m); None: not reached.
    source : str
        ``"class45_beyond_found"`` or ``"not_reached"``.
    found_to_m : float or None
        95th percentile of the class-40 depths (None without any).
    """
    d45 = np.asarray(class45_depth_m, dtype=np.float64)
    d45 = d45[np.isfinite(d45) & (d45 > 0.0)]
    d40 = np.asarray(class40_depth_m, dtype=np.float64)
    d40 = d40[np.isfinite(d40)]
    found = float(np.percentile(d40, 95.0)) if d40.size else None
    if found is not None:
        d45 = d45[d45 >= found]
    if d45.size < MIN_CLASS45:
        return None, "not_reached", found
    return float(np.median(d45)), "class45_beyond_found", found
