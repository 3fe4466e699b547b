"""ASPRS LAS 1.4 point classes (topo-bathy domain profile) and the rules that assign them.

Class codes
-----------
LAS 1.4 R15 standard classes used here: 1 unclassified, 2 ground, 7 low noise, 18 high noise.
The ASPRS Topo-Bathy Lidar Domain Profile adds 40 bathymetric point (seabed), 41 water surface,
42 derived water surface (synthetic, where refraction was computed), 43 submerged object,
44 IHO S-57 object and 45 no-bottom-found-at. The rules below do not produce 43, 44 or 45: 43
is given to seabed points that stand above the local seabed by :mod:`pipeline.process.objects`
(after the TPU, which its test uses), 45 by the survey run (:mod:`pipeline.run_survey`); 44 is
defined for completeness. :data:`SEABED_CLASSES` (40 and 43) are the seabed soundings.

Water column: LAS 1.4 R15 has no class for a return from inside the water column (a
scattering layer, fish, turbidity). Code 45 is sometimes used for it in USGS/NOAA deliveries,
but R15 defines 45 as no-bottom-found-at, which this pipeline also emits, so the two would be
confused. Water-column returns therefore get :data:`WATER_COLUMN` = 64, the first
user-definable code (64-255), and ``points.laz`` names it (and the bathymetric classes) in its
LAS 1.4 Classification Lookup VLR (:mod:`pipeline.outputs.las`), so readers see the meaning.

Rules (:func:`classify_points`), first match wins
-------------------------------------------------
Bottom returns (``ReturnKind.BOTTOM``):

1. ``GRAZING`` (no valid water entry) -> 1 unclassified.
2. Any detector flag of ``unreliable_detector_flags`` (default MERGED, CLIPPED_MERGED,
   BEYOND_DETECTION_LIMIT:
   the bottom time is not trustworthy; a SATURATED pulse's clipped echoes are timed from their
   plateau's edges, or given no bottom, by :mod:`pipeline.process.detect_clipped`), or the
   pulse's own surface return is an outlier of the local fit (``surface_outlier_unreliable``:
   its timing reference is suspect) -> 1.
3. ``confidence < min_confidence`` -> 7 low noise.
4. ``LAND`` (the pulse is above the water level + margin) -> 2 ground.
5. ``ABOVE_SURFACE`` or ``depth_m < 0`` (a "bottom" above the fitted water surface over water)
   -> 18 high noise.
6. ``depth_m > max_depth_m`` (when set: deeper than the system can see) or
   ``depth_m < min_depth_m`` (closer to the surface than the system resolves) -> 7 low noise.
7. Otherwise -> 40 bathymetric point.

Surface returns (``ReturnKind.SURFACE``); detector flags are ignored (a saturated specular
surface return still times the surface: :mod:`pipeline.process.detect_clipped`), but one:

1. ``GRAZING``, or the detector flag ``CLIPPED_MERGED`` (a clipped plateau running on into
   the column: the surface time is only an early bound) -> 1 unclassified.
2. ``LAND``: the only return of its pulse -> 2 ground; the first of several -> 1 (vegetation,
   structure or unknown).
3. ``confidence < min_confidence`` -> 7 low noise.
4. ``SURFACE_OUTLIER``: above its local surface (``depth_m < 0``) -> 18 high noise (spray,
   birds), below -> 7 low noise.
5. Otherwise -> 41 water surface.

Water-column returns (``ReturnKind.WATER_COLUMN``): the bottom rules 1-6 (their timing and
geometry are those of a bottom return, earlier), with ``LAND`` -> 1 (no water column over
land), otherwise -> 64 water column.

Derived water-surface points (``ReturnKind.DERIVED_SURFACE``) -> 42.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.config import setting
from pipeline.process.returns import DetectorFlag, PointFlag, Points, ReturnKind

__all__ = [
    "NEVER_CLASSIFIED",
    "UNCLASSIFIED",
    "GROUND",
    "LOW_NOISE",
    "HIGH_NOISE",
    "BATHYMETRIC_POINT",
    "WATER_SURFACE",
    "DERIVED_WATER_SURFACE",
    "SUBMERGED_OBJECT",
    "IHO_S57_OBJECT",
    "NO_BOTTOM_FOUND_AT",
    "WATER_COLUMN",
    "SEABED_CLASSES",
    "CLASS_NAMES",
    "ClassifySettings",
    "classify_points",
]

NEVER_CLASSIFIED = 0
UNCLASSIFIED = 1
GROUND = 2
LOW_NOISE = 7
HIGH_NOISE = 18
BATHYMETRIC_POINT = 40
WATER_SURFACE = 41
DERIVED_WATER_SURFACE = 42
SUBMERGED_OBJECT = 43
IHO_S57_OBJECT = 44
NO_BOTTOM_FOUND_AT = 45
#: Water-column return (scattering layer, fish, turbidity): user-definable code 64, because
#: LAS 1.4 R15 has no water-column class and its 45 means no-bottom-found-at (some USGS/NOAA
#: deliveries used 45 for the water column, which would clash); named in the file's
#: Classification Lookup VLR.
WATER_COLUMN = 64
#: Seabed soundings: bathymetric points and the submerged objects standing on the seabed
SEABED_CLASSES = (BATHYMETRIC_POINT, SUBMERGED_OBJECT)

CLASS_NAMES: dict[int, str] = {
    NEVER_CLASSIFIED: "never classified",
    UNCLASSIFIED: "unclassified",
    GROUND: "ground",
    LOW_NOISE: "low noise",
    HIGH_NOISE: "high noise",
    BATHYMETRIC_POINT: "bathymetric point",
    WATER_SURFACE: "water surface",
    DERIVED_WATER_SURFACE: "derived water surface",
    SUBMERGED_OBJECT: "submerged object",
    IHO_S57_OBJECT: "IHO S-57 object",
    NO_BOTTOM_FOUND_AT: "no-bottom-found-at",
    WATER_COLUMN: "water column",
}

_FLAG_NAMES = tuple(f.name for f in DetectorFlag)


@dataclass(frozen=True, kw_only=True)
class ClassifySettings:
    """Thresholds of the classification rules."""

    min_confidence: float = setting(0.5, ge=0.0, le=1.0, doc="below: noise")
    max_depth_m: float | None = setting(None, gt=0.0, doc="deeper bottom points: low noise")
    min_depth_m: float = setting(
        0.0, ge=0.0, le=10.0, doc="shallower bottom points (unresolvable from the surface): noise"
    )
    surface_outlier_unreliable: bool = setting(
        False, doc="a bottom whose pulse's own surface return is an outlier stays unclassified"
    )
    # a class-45 point claims no bottom down to its depth; a class-40 sounding a few metres
    # away, shallower by more than the evaluation's relief allowance (0.5 m), says there is
    # one: over a shoal whose echo merged with the surface's, or past a bottom too dark for
    # the assumed one. 3 m, set on the suite's tuning half (benchmarks/RESULTS_suite.md):
    # of its 836 claims more than 0.5 m under the seabed it withholds 630 (2 m: 522, 4 m:
    # 724), and 350 of its 94 737 that hold (0.37 %; 4 m: 0.70 %)
    no_bottom_radius_m: float = setting(
        3.0,
        ge=0.0,
        le=100.0,
        doc="a class-45 claim is not made where a class-40 sounding within this distance is "
        "shallower than it by more than no_bottom_margin_m (0: no test)",
    )
    no_bottom_margin_m: float = setting(0.5, ge=0.0, le=100.0, doc="see no_bottom_radius_m")
    # land (class 2, its depth negative: above the water) says the same of a claim near the
    # shore: the seabed rises to it. Claims drawn from a column's level at the survey's decay
    # (pipeline.process.column_level) reached over land edges, where an echo's slow tail reads
    # as column. 8 m, set on the suite's tuning half (0, 6, 24; benchmarks/RESULTS_suite.md):
    # the smallest of 3, 5, 8, 10 and 15 m that withholds 90 % of the claims more than 0.5 m
    # under the seabed within 15 m of land (79 of 82; 5 m: 54), at a cost of 23 of their
    # 69 000 claims that hold
    no_bottom_land_radius_m: float = setting(
        8.0,
        ge=0.0,
        le=100.0,
        doc="a class-45 claim is not made where a class-2 ground point within this distance is "
        "shallower than it by more than no_bottom_margin_m (0: no test)",
    )
    unreliable_detector_flags: tuple[str, ...] = setting(
        ("MERGED", "CLIPPED_MERGED", "BEYOND_DETECTION_LIMIT"),
        doc="detector flags that leave a bottom point unclassified (SATURATED alone does not: "
        "the detectors time clipped echoes from their edges or report no bottom)",
    )

    def __post_init__(self) -> None:
        for name in self.unreliable_detector_flags:
            if name not in _FLAG_NAMES:
                raise ValueError(
                    f"`unreliable_detector_flags` items must be one of {', '.join(_FLAG_NAMES)}; "
                    f"got {name!r}"
                )

    @property
    def unreliable_mask(self) -> int:
        """The unreliable detector flags as one bit mask."""
        mask = 0
        for name in self.unreliable_detector_flags:
            mask |= int(DetectorFlag[name])
        return mask


def _has(flags: np.ndarray, bits: int) -> np.ndarray:
    return (flags & np.uint16(bits)) != 0


def classify_points(points: Points, settings: ClassifySettings | None = None) -> Points:
    """Assign ASPRS class codes by the rules of this module's docstring.

    Parameters
    ----------
    points : Points
        Points from :mod:`pipeline.process.refraction` (any classification).
    settings : ClassifySettings, optional
        Defaults if omitted.

    Returns
    -------
    Points
        A copy with ``classification`` filled in.
    """
    st = settings or ClassifySettings()
    f, df = points.flags, points.detector_flags
    conf, depth = points.confidence, points.depth_m
    low_conf = conf < st.min_confidence
    grazing = _has(f, PointFlag.GRAZING)
    land = _has(f, PointFlag.LAND)

    outlier = _has(f, PointFlag.SURFACE_OUTLIER)
    bottom = np.select(
        [
            grazing,
            _has(df, st.unreliable_mask) | (outlier & st.surface_outlier_unreliable),
            low_conf,
            land,
            _has(f, PointFlag.ABOVE_SURFACE) | (depth < 0.0),
            (depth > st.max_depth_m) if st.max_depth_m is not None else np.zeros_like(land),
            depth < st.min_depth_m,
        ],
        [UNCLASSIFIED, UNCLASSIFIED, LOW_NOISE, GROUND, HIGH_NOISE, LOW_NOISE, LOW_NOISE],
        default=BATHYMETRIC_POINT,
    )
    surface = np.select(
        [
            grazing,
            _has(df, DetectorFlag.CLIPPED_MERGED),
            land & (points.number_of_returns <= 1),
            land,
            low_conf,
            outlier & (depth < 0.0),
            outlier,
        ],
        [UNCLASSIFIED, UNCLASSIFIED, GROUND, UNCLASSIFIED, LOW_NOISE, HIGH_NOISE, LOW_NOISE],
        default=WATER_SURFACE,
    )
    # a column return is timed and refracted like a bottom: the same rules, another class
    # (over land there is no water column: the bottom rules' ground becomes unclassified)
    column = np.select(
        [bottom == BATHYMETRIC_POINT, bottom == GROUND], [WATER_COLUMN, UNCLASSIFIED], bottom
    )
    cls = np.select(
        [
            points.kind == ReturnKind.BOTTOM,
            points.kind == ReturnKind.SURFACE,
            points.kind == ReturnKind.WATER_COLUMN,
        ],
        [bottom, surface, column],
        default=np.where(
            points.kind == ReturnKind.DERIVED_SURFACE, DERIVED_WATER_SURFACE, UNCLASSIFIED
        ),
    )
    return points.replace(classification=cls.astype(np.uint8))
