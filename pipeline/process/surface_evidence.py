"""Evidence of water for the surface fit: which returns set the level, and an all-land survey.

Water shows light from under its surface return: a bottom, an in-column return, a column
decay the detector measured, or a clipped plateau that runs on from the surface into the
column (``DetectorFlag.CLIPPED_MERGED``, :mod:`pipeline.process.detect_clipped`). Land is
opaque: its echo is the only one of its pulse.

Level points (:func:`level_points`). The water-level search (:func:`~pipeline.process.
surface_land.global_plane`) takes the histogram mode of the surface returns with water under
them. A clipped surface merged with the column is only an early bound of the surface (within a
sample or two of it, never late) and stays out of the level when unclipped returns show water;
when none does (every water pulse clipped: a pulse energy far above the digitiser's range),
the bounds are the only water the survey measured and set the level, rather than the land
echoes that are still timed (which would put the water level on the land: +6.4 m in
``bathy stress``'s ``saturation`` case).

All land (:func:`no_water_seen`). With no water level given and a detector that looked for
the column (no-bottom limits given), a survey where fewer than ``min_wet_pulses`` pulses show
light from under their surface return has no evidence of water. That alone is not enough: a
calm sea with no glint returns no surface echo, and the only echo of each pulse is the seabed
seen through it (a small survey of clear water at 20 degrees off nadir: echoes 5.2 m below
the water level, nothing else). Those echoes lie *below* the level processing expects
(``fallback_water_level_m``: the local vertical frame's zero is the mean water level; in a real
survey a geoid and tide model's level). A land surface lies above it. So the survey is all
land when, also, the median height of its surface returns is more than ``dry_level_margin_m``
above the expected level; else the returns stay water, as without the rule.
"""

from __future__ import annotations

import numpy as np

from pipeline.process.returns import DetectedReturns, DetectorFlag

__all__ = ["clipped_into_column", "level_points", "no_water_seen"]


def clipped_into_column(returns: DetectedReturns) -> np.ndarray:
    """(n,) bool: the pulse's surface echo is clipped into a plateau running into the column."""
    merged = (returns.flags & np.uint16(DetectorFlag.CLIPPED_MERGED)) != 0
    return returns.has_surface & merged


def level_points(
    has_s: np.ndarray, bound: np.ndarray, wet: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The surface returns that set the water level, and which of them have water under them.

    Parameters
    ----------
    has_s : (n,) bool
        Surface returns that time the surface (not clipped into the column).
    bound : (n,) bool
        Surface returns clipped into the column (:func:`clipped_into_column`): early bounds.
    wet : (n,) bool
        A bottom return well below the surface return.

    Returns
    -------
    use : (n,) bool
        ``has_s``, and ``bound`` too when no unclipped return is wet (fewer than 3).
    wet_use : (n,) bool
        ``wet``, and ``bound`` when it is used (a plateau into the column is water under it).
    """
    if np.count_nonzero(wet & has_s) >= 3 or not bound.any():
        return has_s, wet
    return has_s | bound, wet | bound


def no_water_seen(
    returns: DetectedReturns, wet: np.ndarray, column_below_m: np.ndarray, level_m: float, st
) -> bool:
    """The survey is all land: no light from under its surface returns, which stand high.

    Parameters
    ----------
    returns : DetectedReturns
    wet : (n,) bool
        A bottom return ``level_min_depth_m`` below the pulse's surface return.
    column_below_m : (n,) float
        Height of the surface return above the pulse's in-column return (air range).
    level_m : float
        Median height of the surface returns (local z).
    st : SurfaceFitSettings
        ``min_wet_pulses``, ``level_min_depth_m``, ``water_level_hint_m``,
        ``fallback_water_level_m``, ``dry_level_margin_m``.

    Returns
    -------
    bool
        Fewer than ``min_wet_pulses`` pulses show light from under their surface return and
        ``level_m`` is more than ``dry_level_margin_m`` above ``fallback_water_level_m``;
        False when a water level is given, when the detector did not look for the column
        (``returns.t_no_bottom_s`` is None) or when ``min_wet_pulses`` is 0.
    """
    if st.water_level_hint_m is not None or returns.t_no_bottom_s is None:
        return False
    if st.min_wet_pulses == 0 or not np.isfinite(level_m):
        return False
    lit = wet | (returns.has_column & (column_below_m > st.level_min_depth_m))
    lit |= (returns.t_no_bottom_s > 0.0) | clipped_into_column(returns)
    if int(np.count_nonzero(lit & returns.has_surface)) >= st.min_wet_pulses:
        return False
    return bool(level_m > st.fallback_water_level_m + st.dry_level_margin_m)
