"""Gross seabed errors: class-40 points that no survey order accepts, or far below the seabed.

Three rejection rules, all on measured data only (positions, depths and the TPU of the points),
applied after the TPU and the submerged objects (class 43):

1. **Uncertainty beyond every IHO order** (``TVU_EXCEEDED``). A sounding whose own propagated
   95 % vertical uncertainty ``1.96 sigma_v`` exceeds the maximum allowable TVU
   ``sqrt(a² + (b d)²)`` of the survey order ``max_order`` at its depth (IHO S-44 Ed. 6.0.0,
   Table 1; default order 2, the loosest, ``a = 1 m``, ``b = 0.023``) does not meet that order:
   hydrographic processing does not deliver it as a sounding (S-44 §3: the TVU limits apply to
   each sounding). On the suite's tuning scenes these are the pulses whose water surface the
   local fit could not pin down (an ill-conditioned fit at the edge of a Palmer swath over a
   10 m/s sea: slope sigmas of a degree, soundings metres off, and the TPU says so).
2. **Depth read on an implausible water surface** (``SURFACE_IMPLAUSIBLE``). A point's depth is
   the height of its pulse's local water plane at the point less the point's elevation
   (:mod:`pipeline.process.refraction`). Where the plane is extrapolated (a surface fit with
   nearly collinear neighbours at a swath edge, tilted by the waves) its height there can lie
   metres above or below every water-surface return the survey measured, while the point's
   elevation, set by its own surface-to-bottom time, is right: the depth is then not a
   measurement. Rejected when that height lies outside ``[min, max]`` of the survey's
   class-41 heights by more than ``surface_margin_m``. 0.25 m: at 0 the 4-cm envelope of a
   calm tuning scene (seed 56) put 245 good points out; at 0.25 m no point within 0.5 m of
   the true seabed in the tuning half is out, and on tuning seed 57 (Palmer, 10 m/s) every point
   out (203) was more than 1 m off.
3. **Far below the local seabed** (``SEABED_OUTLIER``). A pulse that met a false bottom (a
   noise or after-pulse excursion past the real bottom, a late candidate of a multi-peaked
   echo) lies deeper than the seabed its neighbours measured by far more than its own
   uncertainty. As CUBE (Calder & Mayer 2003, *Automatic processing of high-rate,
   high-density multibeam echosounder data*, G³ 4(6)) keeps the soundings that agree with
   a depth hypothesis within a multiple of their TPU, the point is tested against the robust
   local plane of the object detector (:func:`pipeline.process.objects.detect_objects`:
   cell-median reference points, Tukey-biweight plane, robust scale ``s`` of its ``m``
   neighbours), fitted to the class-40 points only (objects do not pull it up), with the
   same ``sigma = sqrt(sigma_TPU² + s² (1 + 1/m))``: outlier when its height above the plane
   ``h < -k_sigma sigma`` and ``-h >= min_offset_m``.

**Cubes are not blunders.** Rule 3 tests the *deep* side only and its ``k_sigma`` may not be
below the object detector's (checked): a point standing above the seabed by more than the
object threshold is a submerged object (class 43), and class-43 points are never tested by
either rule, so neither can eat the points on a cube.

A rejected point does not vanish: it keeps its position, depth and TPU, becomes ASPRS class 7
(low noise) with its rule's :class:`~pipeline.process.returns.PointFlag` and the LAS 1.4
*withheld* bit (:mod:`pipeline.outputs.las`); the grid leaves it out and the evaluation counts
it (``seabed_rejected`` in ``evaluation.json``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline import iho
from pipeline.config import setting
from pipeline.process.classify import BATHYMETRIC_POINT, LOW_NOISE, WATER_SURFACE
from pipeline.process.objects import ObjectDetections, ObjectSettings, SeabedFit, detect_objects
from pipeline.process.returns import PointFlag, Points, ReturnKind

__all__ = [
    "REJECTED",
    "OutlierSettings",
    "tvu_exceeded",
    "water_surface_range_m",
    "implausible_surface",
    "seabed_outliers",
    "reject_seabed_outliers",
]

#: flags of the rejected points (either rule)
REJECTED = PointFlag.TVU_EXCEEDED | PointFlag.SURFACE_IMPLAUSIBLE | PointFlag.SEABED_OUTLIER


@dataclass(frozen=True, kw_only=True)
class OutlierSettings:
    """Rejection of class-40 gross errors (``[process.outliers]``)."""

    enabled: bool = setting(True, doc="rejected class-40 points become class 7 (withheld)")
    max_order: str = setting(
        "2",
        choices=(*iho.IHO_ORDERS, "off"),
        doc="IHO S-44 order whose TVU each sounding's own 95 % TPU must meet (off: no test)",
    )
    surface_margin_m: float | None = setting(
        0.25,
        ge=0.0,
        le=100.0,
        doc="a point's local water plane beyond the measured surface heights by more: rejected "
        "(None: no test)",
    )
    # 5: one sigma above the object detector's 4, so a point its test keeps is never near
    # ours; on the suite's tuning scenes no point within 0.5 m of the truth was rejected
    k_sigma: float = setting(
        5.0, gt=0.0, le=100.0, doc="depth below the seabed fit in test sigmas (>= objects')"
    )
    min_offset_m: float = setting(
        0.5, ge=0.0, le=100.0, doc="smallest depth below the local seabed that is rejected"
    )


def tvu_exceeded(depth_m, sigma_v_m, order: str) -> np.ndarray:
    """``(n,)`` bool: the sounding's ``1.96 sigma_v`` exceeds the order's TVU at its depth.

    Non-finite sigmas count as exceeded (a sounding without an uncertainty meets no order).
    """
    d = np.maximum(np.asarray(depth_m, dtype=np.float64), 0.0)
    tvu = iho.tvu95_m(np.asarray(sigma_v_m, dtype=np.float64))
    with np.errstate(invalid="ignore"):
        return ~(tvu <= iho.tvu_allowance_m(d, order))


def water_surface_range_m(points: Points) -> tuple[float, float] | None:
    """``(min, max)`` of the class-41 water-surface heights of ``points``; None without any.

    What :func:`implausible_surface` tests against: the survey's (a block of a survey is
    handed its survey's, :mod:`pipeline.survey_blocks`).
    """
    s = (points.classification == WATER_SURFACE) & (points.kind == ReturnKind.SURFACE)
    if not s.any():
        return None
    zs = points.xyz_m[s, 2]
    return float(zs.min()), float(zs.max())


def implausible_surface(
    points: Points, margin_m: float, surface_range_m: tuple[float, float] | None = None
) -> np.ndarray:
    """``(n,)`` bool: the point's local water plane lies beyond the measured surface heights.

    The plane's height at the point is ``z + depth_m``; beyond: outside the range of the
    survey's class-41 water-surface heights by more than ``margin_m`` (all False without
    class-41 points). ``surface_range_m``: that range, measured elsewhere (default: from
    ``points``, :func:`water_surface_range_m`).
    """
    rng = water_surface_range_m(points) if surface_range_m is None else surface_range_m
    if rng is None:
        return np.zeros(len(points), dtype=bool)
    lo, hi = rng
    plane = points.xyz_m[:, 2] + points.depth_m
    return (plane > hi + margin_m) | (plane < lo - margin_m)


def seabed_outliers(
    xy_m, z_m, sigma_z_m, settings: OutlierSettings, fit: ObjectSettings, tested=None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which points lie far below the robust local seabed of the others.

    Parameters
    ----------
    xy_m : (n, 2) array_like
        Horizontal positions of the class-40 points (local frame).
    z_m : (n,) array_like
        Their elevations (up positive).
    sigma_z_m : (n,) array_like
        Their vertical 1-sigma TPU.
    settings : OutlierSettings
    fit : ObjectSettings
        The neighbourhood and robust plane of the object detector (same fit, same sigma).
    tested : (n,) bool, optional
        The points tested (default: all); every point is still a reference point of the
        others' planes. The others are not outliers (height and sigma NaN).

    Returns
    -------
    outlier : (n,) bool
    height_m, sigma_m : (n,) float64
        Height above the local seabed fit and the test's sigma (NaN: too few neighbours,
        not tested).
    """
    return _below(detect_objects(xy_m, z_m, sigma_z_m, fit, tested), settings)


def _below(found: ObjectDetections, settings: OutlierSettings):
    """:func:`seabed_outliers`' verdict on the fits ``found``: ``(outlier, height, sigma)``."""
    h, s = found.height_m, found.sigma_m
    with np.errstate(invalid="ignore"):
        out = (h < -settings.k_sigma * s) & (-h >= settings.min_offset_m)
    return out, h, s


def reject_seabed_outliers(
    points: Points,
    settings: OutlierSettings,
    fit: ObjectSettings,
    surface_range_m: tuple[float, float] | None = None,
    tested=None,
    fitted: SeabedFit | None = None,
) -> tuple[Points, dict[str, int]]:
    """Class-40 bottom points either rule rejects set to class 7 and flagged; counts.

    Parameters
    ----------
    points : Points
        Classified points with their TPU (``uncertainty_v_m``) and objects (class 43).
    settings : OutlierSettings
    fit : ObjectSettings
        The object detector's settings (its fit; its ``k_sigma`` bounds ours from below).
    surface_range_m : (float, float), optional
        The survey's class-41 height range (:func:`water_surface_range_m`), when ``points``
        are a block of it; default: measured from ``points``.
    tested : (n_points,) bool, optional
        The points the far-below test (rule 3) is made at (default: all): a block of a
        survey tests the points whose class it keeps (:mod:`pipeline.survey_blocks`). Every
        class-40 point the rules before keep is still a reference point of its plane; the
        other rules are per point and test all.
    fitted : SeabedFit, optional
        The object test's fits of these points
        (:func:`~pipeline.process.objects.classify_objects_fit`): read instead of fitting
        again where rule 3 tests the very points they fitted, at the same positions, TPU,
        tested rows and ``fit`` (the same planes to the bit); otherwise fitted again.

    Returns
    -------
    Points
        A copy: rejected points get class 7 and their rule's flag.
    dict
        ``tvu_exceeded``, ``surface_implausible``, ``seabed_outlier`` (points per rule, in
        this order; each rule tests what the ones before kept).
    """
    if settings.k_sigma < fit.k_sigma:
        raise ValueError(
            f"process.outliers.k_sigma ({settings.k_sigma:g}) must be at least "
            f"process.objects.k_sigma ({fit.k_sigma:g}): a point the object test keeps must "
            "not be rejected by a looser one"
        )
    sea = (points.classification == BATHYMETRIC_POINT) & (points.kind == ReturnKind.BOTTOM)
    counts = {"tvu_exceeded": 0, "surface_implausible": 0, "seabed_outlier": 0}
    if not settings.enabled or not sea.any():
        return points, counts
    flags = points.flags.copy()
    if settings.max_order != "off":
        over = sea & tvu_exceeded(points.depth_m, points.uncertainty_v_m, settings.max_order)
        flags[over] |= np.uint16(PointFlag.TVU_EXCEEDED)
        counts["tvu_exceeded"] = int(over.sum())
        sea &= ~over
    if settings.surface_margin_m is not None:
        out = sea & implausible_surface(points, settings.surface_margin_m, surface_range_m)
        flags[out] |= np.uint16(PointFlag.SURFACE_IMPLAUSIBLE)
        counts["surface_implausible"] = int(out.sum())
        sea &= ~out
    idx = np.flatnonzero(sea)
    if idx.size:
        xyz = points.xyz_m[idx]
        sig = points.uncertainty_v_m[idx]
        test = None if tested is None else np.asarray(tested, dtype=bool)[idx]
        if (
            fitted is not None
            and np.array_equal(fitted.rows, idx)
            and fitted.reads(xyz, sig, test, fit)
        ):
            out, _, _ = _below(fitted.found, settings)
        else:
            out, _, _ = seabed_outliers(xyz[:, :2], xyz[:, 2], sig, settings, fit, test)
        flags[idx[out]] |= np.uint16(PointFlag.SEABED_OUTLIER)
        counts["seabed_outlier"] = int(out.sum())
    rejected = (flags & np.uint16(REJECTED)) != 0
    cls = np.where(rejected, np.uint8(LOW_NOISE), points.classification).astype(np.uint8)
    return points.replace(classification=cls, flags=flags), counts
