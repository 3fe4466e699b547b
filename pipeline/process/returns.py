"""The data handed between processing stages: detected returns in, classified points out.

:class:`DetectedReturns` is the contract between a detector (full-waveform or photon-counting)
and the geometric processing; :class:`Points` is what processing produces and what the writers
and the evaluation consume. Both are frozen dataclasses of numpy arrays, one row per pulse
(``DetectedReturns``) or per point (``Points``), validated on construction.

Conventions
-----------
* Local frame: x east, y north, z up, metres, float64.
* Times are round-trip times in seconds from the pulse's emission at the measured laser origin.
* No NaN anywhere: an absent return has its mask False and its time (and amplitude) 0.
* Flags are bit sets in ``uint16``: :class:`DetectorFlag` for what the detector saw,
  :class:`PointFlag` for what processing did.

A photon-counting detector fills the same dataclass: one row per aggregation (a shot, or a
segment of shots), the measured origin and direction of that aggregation (for a segment, of the
shot whose geometry the times refer to), the fitted surface/bottom times of the photon
histogram, the confidence from its signal-to-background test, and the photon counts of each
return in the amplitude fields.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

__all__ = ["DetectorFlag", "PointFlag", "ReturnKind", "DetectedReturns", "Points"]

#: Largest tolerated deviation of ``|direction_meas|`` from 1.
_UNIT_TOLERANCE = 1e-6


class DetectorFlag(enum.IntFlag):
    """Bits the detector sets per pulse (``DetectedReturns.flags``)."""

    #: Surface and bottom returns overlap and could not be separated cleanly (very shallow).
    MERGED = 1 << 0
    #: The receiver saturated on a return; its timing may be biased.
    SATURATED = 1 << 1
    #: Weak signal: a return was found, but close to the detection threshold.
    LOW_SNR = 1 << 2
    #: Several bottom candidates; the reported one is the detector's best guess.
    MULTIPLE_BOTTOM_CANDIDATES = 1 << 3
    # bits 4 and 5 (TRUNCATED, SURFACE_ESTIMATED) were never set by any detector: removed,
    # their values kept free so files written before read the same
    #: The surface echo is clipped (SATURATED) into a plateau that runs on into the water
    #: column and the bottom: the surface time is the plateau's leading edge, an early bound
    #: (not a timing reference), and the bottom is not measurable.
    CLIPPED_MERGED = 1 << 6
    #: Photon counting: the bottom lies deeper than its window's detection limit (where a
    #: bottom of the assumed reflectance would sink under the threshold) and is under twice the
    #: threshold: it cannot be told from an upward fluctuation of the background or column.
    BEYOND_DETECTION_LIMIT = 1 << 7


class PointFlag(enum.IntFlag):
    """Bits processing sets per point (``Points.flags``)."""

    #: Too few surface neighbours: the global water plane was used instead of a local fit.
    SURFACE_GLOBAL_FALLBACK = 1 << 0
    #: No usable surface return of its own: the water entry comes from the fitted surface and
    #: the in-water range from the bottom time alone.
    SURFACE_INTERPOLATED = 1 << 1
    #: The pulse's own surface point is far from the local fit (robust outlier).
    SURFACE_OUTLIER = 1 << 2
    #: Over land (above the water level): no refraction, air path only.
    LAND = 1 << 3
    #: The bottom return lies above the fitted water surface (before the beam enters).
    ABOVE_SURFACE = 1 << 4
    #: Computed without refraction correction (straight beam, speed of light in air).
    NOT_REFRACTED = 1 << 5
    #: The beam grazes the surface (or is totally reflected): no valid water entry.
    GRAZING = 1 << 6
    #: A point created by processing, not measured (derived water surface).
    SYNTHETIC = 1 << 7
    #: The neighbours of the local surface fit are nearly collinear; the slope is regularised.
    SURFACE_ILL_CONDITIONED = 1 << 8
    #: Left out of the propagated uncertainty (:mod:`pipeline.uncertainty.tpu_screen`): its
    #: uncertainty is the a-priori one.
    NO_TPU = 1 << 9
    #: A bathymetric point whose own 95 % TPU exceeds the TVU of the IHO order processing
    #: requires (:mod:`pipeline.process.seabed_outliers`): class 7, withheld.
    TVU_EXCEEDED = 1 << 10
    #: A bathymetric point far below the robust local seabed of its neighbours, in sigmas of
    #: its TPU (:mod:`pipeline.process.seabed_outliers`): class 7, withheld.
    SEABED_OUTLIER = 1 << 11
    #: A bathymetric point whose local water plane, where its depth is read, lies above or
    #: below every measured water-surface return of the survey (an extrapolated plane:
    #: :mod:`pipeline.process.seabed_outliers`): its depth is not measured; class 7, withheld.
    SURFACE_IMPLAUSIBLE = 1 << 12


class ReturnKind(enum.IntEnum):
    """Which return a point comes from."""

    SURFACE = 1
    BOTTOM = 2
    DERIVED_SURFACE = 3
    #: A return from inside the water column, between the surface and the bottom.
    WATER_COLUMN = 4


def _array(name: str, value: Any, dtype: Any, shape: tuple[int, ...]) -> np.ndarray:
    a = np.asarray(value)
    if a.shape != shape:
        raise ValueError(f"`{name}` must have shape {shape}; got {a.shape}")
    if dtype is bool:
        if a.dtype != np.bool_:
            raise ValueError(f"`{name}` must be a boolean array; got dtype {a.dtype}")
        return a
    if np.issubdtype(np.dtype(dtype), np.integer):
        if not np.issubdtype(a.dtype, np.integer) and a.dtype != np.bool_:
            raise ValueError(f"`{name}` must be an integer array; got dtype {a.dtype}")
        info = np.iinfo(dtype)
        if a.size and (a.min() < info.min or a.max() > info.max):
            raise ValueError(f"`{name}` does not fit in {np.dtype(dtype).name}")
        return a.astype(dtype, copy=False)
    a = a.astype(dtype, copy=False)
    if not np.all(np.isfinite(a)):
        bad = a[~np.isfinite(a)].flat[0]
        raise ValueError(f"`{name}` must be finite (no NaN: use the masks); got {bad!r}")
    return a


def _readonly(obj: Any) -> None:
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if isinstance(v, np.ndarray):
            v = v.view()
            v.flags.writeable = False
            object.__setattr__(obj, f.name, v)


def _rows(obj: Any, index: Any) -> dict[str, Any]:
    """Every per-row field of the dataclass ``obj`` at ``index`` (None fields stay None)."""
    return {
        f.name: (None if getattr(obj, f.name) is None else getattr(obj, f.name)[index])
        for f in dataclasses.fields(obj)
    }


def _in_unit_interval(name: str, a: np.ndarray) -> None:
    if a.size and (a.min() < 0.0 or a.max() > 1.0):
        raise ValueError(f"`{name}` must be in [0, 1]; got values in [{a.min()}, {a.max()}]")


@dataclass(frozen=True)
class DetectedReturns:
    """Per-pulse returns found by a detector, with the measured navigation of each pulse.

    Parameters
    ----------
    pulse_id : (n,) int64
        Global pulse number (or aggregation number for a photon-counting detector).
    origin_meas_m : (n, 3) float64
        Measured laser origin in the local frame (GNSS/INS solution), metres.
    direction_meas : (n, 3) float64
        Measured unit beam direction (pointing down for a bathymetric beam).
    has_surface, has_bottom : (n,) bool
        Whether a surface / bottom return was detected.
    t_surface_s, t_bottom_s : (n,) float64
        Round-trip times from emission, seconds; exactly 0 where the mask is False, and
        ``t_bottom_s > t_surface_s`` where both returns exist.
    surface_confidence, bottom_confidence : (n,) float64
        Detection confidence in [0, 1]; 0 where the mask is False.
    flags : (n,) uint16
        :class:`DetectorFlag` bits.
    surface_amplitude, bottom_amplitude : (n,) float64, optional
        Return strength >= 0 in detector units (peak amplitude, or photon count); 0 where absent.
    t_surface_sigma_s, t_bottom_sigma_s : (n,) float64, optional
        One-sigma timing uncertainty of each return (> 0 where the return exists); when absent
        processing uses its default timing uncertainty.
    has_column : (n,) bool, optional
        Whether an in-column return (between the surface and the bottom: a scattering layer,
        fish) was detected; left out (None), it is all False: no detector output is required
        to have one. Always an array after construction.
    t_column_s, column_confidence, column_amplitude : (n,) float64, optional
        Its round-trip time (``t_surface_s < t_column_s < t_bottom_s`` where those exist),
        confidence in [0, 1] and strength >= 0; 0 where ``has_column`` is False.
    t_no_bottom_s : (n,) float64, optional
        Round-trip time down to which a pulse without a bottom establishes there is none (its
        detection limit, :mod:`pipeline.process.detection_limit`); ``> t_surface_s`` where
        known, 0 where not estimated (and where there is a bottom).
    t_emit_s : (n,) float64, optional
        Emission (firing) time of the pulse on the survey clock, seconds: what the system's
        timing records per shot (the LAS GPS time of its points).
    line_id : (n,) int64, optional
        Index (>= 0) of the flight line the pulse was fired on, as the flight log records it.
    """

    pulse_id: np.ndarray
    origin_meas_m: np.ndarray
    direction_meas: np.ndarray
    has_surface: np.ndarray
    t_surface_s: np.ndarray
    has_bottom: np.ndarray
    t_bottom_s: np.ndarray
    surface_confidence: np.ndarray
    bottom_confidence: np.ndarray
    flags: np.ndarray
    surface_amplitude: np.ndarray | None = None
    bottom_amplitude: np.ndarray | None = None
    t_surface_sigma_s: np.ndarray | None = None
    t_bottom_sigma_s: np.ndarray | None = None
    has_column: np.ndarray | None = None
    t_column_s: np.ndarray | None = None
    column_confidence: np.ndarray | None = None
    column_amplitude: np.ndarray | None = None
    t_no_bottom_s: np.ndarray | None = None
    t_emit_s: np.ndarray | None = None
    line_id: np.ndarray | None = None

    #: The fields of the in-column return (a detector's output passes them on by these names).
    COLUMN_FIELDS: ClassVar[tuple[str, ...]] = (
        "has_column",
        "t_column_s",
        "column_confidence",
        "column_amplitude",
    )

    def __post_init__(self) -> None:
        pid = np.asarray(self.pulse_id)
        if pid.ndim != 1:
            raise ValueError(f"`pulse_id` must be one-dimensional; got shape {pid.shape}")
        n = pid.shape[0]
        s = object.__setattr__
        # no column returns unless given: callers that predate them need not know of them
        if self.has_column is None:
            s(self, "has_column", np.zeros(n, dtype=bool))
        for name in ("t_column_s", "column_confidence", "column_amplitude"):
            if getattr(self, name) is None:
                s(self, name, np.zeros(n))
        s(self, "pulse_id", _array("pulse_id", pid, np.int64, (n,)))
        s(self, "origin_meas_m", _array("origin_meas_m", self.origin_meas_m, np.float64, (n, 3)))
        d = _array("direction_meas", self.direction_meas, np.float64, (n, 3))
        norm = np.linalg.norm(d, axis=1)
        if n and np.max(np.abs(norm - 1.0)) > _UNIT_TOLERANCE:
            raise ValueError(
                "`direction_meas` must hold unit vectors; "
                f"got norms in [{norm.min()}, {norm.max()}]"
            )
        s(self, "direction_meas", d)
        for mask, t, conf in (
            ("has_surface", "t_surface_s", "surface_confidence"),
            ("has_bottom", "t_bottom_s", "bottom_confidence"),
            ("has_column", "t_column_s", "column_confidence"),
        ):
            m = _array(mask, getattr(self, mask), bool, (n,))
            tv = _array(t, getattr(self, t), np.float64, (n,))
            cv = _array(conf, getattr(self, conf), np.float64, (n,))
            if np.any(tv[m] <= 0.0):
                raise ValueError(f"`{t}` must be > 0 where `{mask}` is True")
            if np.any(tv[~m] != 0.0) or np.any(cv[~m] != 0.0):
                raise ValueError(f"`{t}` and `{conf}` must be 0 where `{mask}` is False")
            _in_unit_interval(conf, cv)
            s(self, mask, m)
            s(self, t, tv)
            s(self, conf, cv)
        both = self.has_surface & self.has_bottom
        if np.any(self.t_bottom_s[both] <= self.t_surface_s[both]):
            raise ValueError("`t_bottom_s` must be > `t_surface_s` where both returns exist")
        col_s = self.has_column & self.has_surface
        if np.any(self.t_column_s[col_s] <= self.t_surface_s[col_s]):
            raise ValueError("`t_column_s` must be > `t_surface_s` where both returns exist")
        col_b = self.has_column & self.has_bottom
        if np.any(self.t_column_s[col_b] >= self.t_bottom_s[col_b]):
            raise ValueError("`t_column_s` must be < `t_bottom_s` where both returns exist")
        s(self, "flags", _array("flags", self.flags, np.uint16, (n,)))
        if self.t_no_bottom_s is not None:
            tn = _array("t_no_bottom_s", self.t_no_bottom_s, np.float64, (n,))
            known = tn != 0.0
            if np.any(self.has_bottom & known) or np.any(
                tn[known] <= np.where(self.has_surface, self.t_surface_s, np.inf)[known]
            ):
                raise ValueError(
                    "`t_no_bottom_s` must be 0 where there is a bottom, and > `t_surface_s` "
                    "(with a surface) where not 0"
                )
            s(self, "t_no_bottom_s", tn)
        if self.t_emit_s is not None:
            s(self, "t_emit_s", _array("t_emit_s", self.t_emit_s, np.float64, (n,)))
        if self.line_id is not None:
            lid = _array("line_id", self.line_id, np.int64, (n,))
            if np.any(lid < 0):
                raise ValueError("`line_id` must be >= 0")
            s(self, "line_id", lid)
        for opt, mask in (
            ("surface_amplitude", "has_surface"),
            ("bottom_amplitude", "has_bottom"),
            ("t_surface_sigma_s", "has_surface"),
            ("t_bottom_sigma_s", "has_bottom"),
            ("column_amplitude", "has_column"),
        ):
            v = getattr(self, opt)
            if v is None:
                continue
            v = _array(opt, v, np.float64, (n,))
            m = getattr(self, mask)
            if np.any(v < 0.0) or np.any(v[~m] != 0.0):
                raise ValueError(f"`{opt}` must be >= 0, and 0 where `{mask}` is False")
            if opt.endswith("sigma_s") and np.any(v[m] <= 0.0):
                raise ValueError(f"`{opt}` must be > 0 where `{mask}` is True")
            s(self, opt, v)
        _readonly(self)

    def __len__(self) -> int:
        return int(self.pulse_id.shape[0])

    def select(self, index: Any) -> DetectedReturns:
        """The pulses picked by a boolean mask or an index array, as a new object."""
        return DetectedReturns(**_rows(self, index))


@dataclass(frozen=True)
class Points:
    """Georeferenced points in the local frame, one row per point.

    Parameters
    ----------
    pulse_id : (n,) int64
        Pulse the point comes from.
    xyz_m : (n, 3) float64
        Position in the local frame (x east, y north, z up), metres.
    depth_m : (n,) float64
        Depth below the fitted local water surface, positive down (negative above it, e.g.
        on land), metres.
    classification : (n,) uint8
        ASPRS class code (see :mod:`pipeline.process.classify`); 1 (unclassified) until
        classified.
    kind : (n,) uint8
        :class:`ReturnKind` of the point.
    flags : (n,) uint16
        :class:`PointFlag` bits set by processing.
    detector_flags : (n,) uint16
        :class:`DetectorFlag` bits of the pulse.
    return_number, number_of_returns : (n,) uint8
        LAS return numbering within the pulse, in time order: surface 1, then the in-column
        return and the bottom (surface 1, column 2, bottom 3 when all three exist).
    confidence : (n,) float64
        Detector confidence of the return, in [0, 1].
    uncertainty_v_m, uncertainty_h_m : (n,) float64
        A-priori one-sigma vertical and horizontal (radial) uncertainty, metres.
    amplitude : (n,) float64, optional
        Return strength in detector units.
    """

    pulse_id: np.ndarray
    xyz_m: np.ndarray
    depth_m: np.ndarray
    classification: np.ndarray
    kind: np.ndarray
    flags: np.ndarray
    detector_flags: np.ndarray
    return_number: np.ndarray
    number_of_returns: np.ndarray
    confidence: np.ndarray
    uncertainty_v_m: np.ndarray
    uncertainty_h_m: np.ndarray
    amplitude: np.ndarray | None = None

    def __post_init__(self) -> None:
        pid = np.asarray(self.pulse_id)
        if pid.ndim != 1:
            raise ValueError(f"`pulse_id` must be one-dimensional; got shape {pid.shape}")
        n = pid.shape[0]
        s = object.__setattr__
        s(self, "pulse_id", _array("pulse_id", pid, np.int64, (n,)))
        s(self, "xyz_m", _array("xyz_m", self.xyz_m, np.float64, (n, 3)))
        for name in ("depth_m", "confidence", "uncertainty_v_m", "uncertainty_h_m"):
            s(self, name, _array(name, getattr(self, name), np.float64, (n,)))
        _in_unit_interval("confidence", self.confidence)
        for name in ("uncertainty_v_m", "uncertainty_h_m"):
            if np.any(getattr(self, name) < 0.0):
                raise ValueError(f"`{name}` must be >= 0")
        for name in ("classification", "kind", "return_number", "number_of_returns"):
            s(self, name, _array(name, getattr(self, name), np.uint8, (n,)))
        for name in ("flags", "detector_flags"):
            s(self, name, _array(name, getattr(self, name), np.uint16, (n,)))
        if self.amplitude is not None:
            s(self, "amplitude", _array("amplitude", self.amplitude, np.float64, (n,)))
        _readonly(self)

    def __len__(self) -> int:
        return int(self.pulse_id.shape[0])

    def select(self, index: Any) -> Points:
        """The points picked by a boolean mask or an index array, as a new object."""
        return Points(**_rows(self, index))

    def replace(self, **changes: Any) -> Points:
        """A copy with some fields replaced (validated again)."""
        return dataclasses.replace(self, **changes)

    @staticmethod
    def concatenate(parts: Sequence[Points]) -> Points:
        """Join point sets in order; ``amplitude`` is kept only if every part has it."""
        if not parts:
            raise ValueError("`parts` must hold at least one Points object")
        kw = {}
        for f in dataclasses.fields(Points):
            values = [getattr(p, f.name) for p in parts]
            if any(v is None for v in values):
                kw[f.name] = None
            else:
                kw[f.name] = np.concatenate(values, axis=0)
        return Points(**kw)
