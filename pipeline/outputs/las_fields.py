"""The LAS 1.4 standard fields of each point that come from its pulse, and the file's CRS.

* **GPS time**: the pulse's emission time (``DetectedReturns.t_emit_s``), seconds on the survey
  clock (the simulator's t = 0 is the survey start; no absolute GPS epoch is simulated, so the
  global-encoding GPS-time bit is left at "GPS week time").
* **Intensity**: the detected amplitude of the point's own return normalised as LAS 1.4 R15
  asks, ``amplitude x 65536 / dynamic range`` rounded and clipped to 0..65535
  (:attr:`pipeline.process.context.Instrument.amplitude_full_scale`: a 12-bit digitiser's count
  is x 16; a photon count x 1). Synthetic points (class 45, derived surface) have no echo: 0.
* **Scan angle** (point format 6: int16, 0.006 degree units): the rotation of the *measured*
  beam direction from the data frame's down, about the along-track axis, counter-clockwise seen
  from behind the sensor looking along the track (so positive = starboard, right of track):
  ``atan2(d . right, -d_z)``. Along-track is the direction the line was flown, from the measured
  trajectory: the laser origin of the line's last pulse minus its first (a line with one
  pulse in the file: north).
* **Point source ID**: the flight line, ``line_id + 1`` (1-based: 0 reads as "not assigned").
* **CRS**: the horizontal CRS and a local vertical CRS, compound, as OGC WKT 1 (what LAS 1.4
  R15 specifies for the WKT VLR); z is height above the scene's mean water level in the
  scene's local vertical frame, which the vertical CRS's name says.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pyproj
from pyproj.crs import CompoundCRS

from pipeline.process.returns import DetectedReturns, PointFlag, Points

__all__ = [
    "VERTICAL_CRS_NAME",
    "SCAN_ANGLE_UNIT_DEG",
    "PulseFields",
    "LineEnds",
    "pulse_fields",
    "scan_angle_rad",
    "las_crs",
]

#: Name of the vertical CRS of the points' z.
VERTICAL_CRS_NAME = "Local height above scene mean water level"
_VERTICAL_WKT2 = (
    f'VERTCRS["{VERTICAL_CRS_NAME}",'
    'VDATUM["Scene mean water level (local vertical frame, not a tidal datum)"],'
    'CS[vertical,1],AXIS["gravity-related height (H)",up,LENGTHUNIT["metre",1]]]'
)
#: LAS 1.4 point format 6 scan angle quantum (degrees).
SCAN_ANGLE_UNIT_DEG = 0.006


@dataclass(frozen=True)
class PulseFields:
    """Per-point LAS fields, ``(n_points,)`` each, ready for the writer."""

    gps_time_s: np.ndarray
    intensity: np.ndarray
    scan_angle: np.ndarray
    point_source_id: np.ndarray


def las_crs(crs: Any) -> pyproj.CRS:
    """The compound CRS of the points: ``crs``'s horizontal part + the local vertical CRS."""
    crs = pyproj.CRS.from_user_input(crs)
    horizontal = crs.sub_crs_list[0] if crs.is_compound else crs
    return CompoundCRS(
        name=f"{horizontal.name} + {VERTICAL_CRS_NAME}",
        components=[horizontal, pyproj.CRS.from_wkt(_VERTICAL_WKT2)],
    )


@dataclass
class LineEnds:
    """Each flight line's first and last pulse origin, gathered part by part.

    A line's flown direction (:func:`scan_angle_rad`) is from its first to its last pulse: a
    survey read block by block (:mod:`pipeline.survey_blocks`) gathers them over its stored
    chunks (:meth:`add`), so every block's scan angles use its lines' whole length.
    """

    line: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    t_first: np.ndarray = field(default_factory=lambda: np.zeros(0))
    xy_first: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    t_last: np.ndarray = field(default_factory=lambda: np.zeros(0))
    xy_last: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))

    @classmethod
    def of(cls, returns: DetectedReturns) -> LineEnds:
        """The ends of each line among ``returns`` (``t_emit_s``, ``line_id``)."""
        line, t = returns.line_id, returns.t_emit_s
        order = np.lexsort((t, line))
        ls = line[order]
        first = np.flatnonzero(np.r_[True, ls[1:] != ls[:-1]])
        last = np.r_[first[1:], ls.size] - 1
        xy = returns.origin_meas_m[:, :2]
        return cls(
            ls[first].astype(np.int64),
            t[order[first]],
            xy[order[first]],
            t[order[last]],
            xy[order[last]],
        )

    def add(self, returns: DetectedReturns) -> None:
        """Take in more pulses' ends (the earlier and the later of each line)."""
        new = LineEnds.of(returns)
        line = np.union1d(self.line, new.line)
        m = line.size
        t0, x0 = np.full(m, np.inf), np.zeros((m, 2))
        t1, x1 = np.full(m, -np.inf), np.zeros((m, 2))
        for part in (self, new):
            at = np.searchsorted(line, part.line)
            early = part.t_first < t0[at]
            t0[at[early]], x0[at[early]] = part.t_first[early], part.xy_first[early]
            late = part.t_last > t1[at]
            t1[at[late]], x1[at[late]] = part.t_last[late], part.xy_last[late]
        self.line, self.t_first, self.xy_first, self.t_last, self.xy_last = line, t0, x0, t1, x1


def scan_angle_rad(returns: DetectedReturns, lines: LineEnds | None = None) -> np.ndarray:
    """LAS scan angle of every pulse from its measured beam and the line's flown direction.

    Parameters
    ----------
    returns : DetectedReturns
        With ``t_emit_s`` and ``line_id``, ``(n,)``.
    lines : LineEnds, optional
        The survey's line ends, when ``returns`` are a part of it; default: of ``returns``.

    Returns
    -------
    (n,) float64
        Radians, positive to starboard (LAS: counter-clockwise seen from the rear).
    """
    ends = LineEnds.of(returns) if lines is None else lines
    along = ends.xy_last - ends.xy_first
    norm = np.hypot(along[:, 0], along[:, 1])
    along = np.where(norm[:, None] > 0.0, along / np.where(norm > 0.0, norm, 1.0)[:, None], [0, 1])
    row = np.searchsorted(ends.line, returns.line_id)
    # right of track = along x up: (a_y, -a_x)
    right = np.column_stack([along[row, 1], -along[row, 0]])
    d = returns.direction_meas
    return np.arctan2(np.sum(d[:, :2] * right, axis=1), -d[:, 2])


def pulse_fields(
    points: Points,
    returns: DetectedReturns,
    amplitude_full_scale: float,
    lines: LineEnds | None = None,
) -> PulseFields:
    """GPS time, intensity, scan angle and point source ID of every point, from its pulse.

    Parameters
    ----------
    points : Points
        ``(n_points,)``; every ``pulse_id`` must be one of ``returns``'.
    returns : DetectedReturns
        The detections the points were made from, with ``t_emit_s`` and ``line_id``.
    amplitude_full_scale : float
        The receiver's dynamic range in amplitude units (> 0).
    lines : LineEnds, optional
        The survey's line ends when ``returns`` are a part of it (:func:`scan_angle_rad`).
    """
    if returns.t_emit_s is None or returns.line_id is None:
        raise ValueError("`returns` must carry `t_emit_s` and `line_id` for the LAS fields")
    if not amplitude_full_scale > 0.0:
        raise ValueError(f"`amplitude_full_scale` must be > 0; got {amplitude_full_scale!r}")
    by_id = np.argsort(returns.pulse_id, kind="stable")
    sorted_id = returns.pulse_id[by_id]
    pos = np.minimum(np.searchsorted(sorted_id, points.pulse_id), max(len(sorted_id) - 1, 0))
    if len(points) and (len(sorted_id) == 0 or np.any(sorted_id[pos] != points.pulse_id)):
        raise ValueError("every point's `pulse_id` must be a pulse of `returns`")
    row = by_id[pos]
    angle_deg = np.degrees(scan_angle_rad(returns, lines))[row]
    amp = np.zeros(len(points))
    if points.amplitude is not None:
        # derived (synthetic) points carry no echo of their own
        synthetic = (points.flags & np.uint16(PointFlag.SYNTHETIC)) != 0
        amp = np.where(synthetic, 0.0, points.amplitude)
    intensity = np.clip(np.round(amp * (65536.0 / amplitude_full_scale)), 0, 65535)
    return PulseFields(
        gps_time_s=returns.t_emit_s[row],
        intensity=intensity.astype(np.uint16),
        scan_angle=np.clip(np.round(angle_deg / SCAN_ANGLE_UNIT_DEG), -30000, 30000).astype(
            np.int16
        ),
        point_source_id=(returns.line_id[row] + 1).astype(np.uint16),
    )
