"""Flight settings and line planning, aircraft attitude motion and body-to-local rotations.

Frames and angles (see also :mod:`pipeline.simulate.survey`):

* Local frame: x east, y north, z up (m), relative to a local origin.
* Heading / azimuth: clockwise from north; a line with heading ``psi`` runs along
  ``(sin psi, cos psi)`` in (x, y); its right-hand side is ``(cos psi, -sin psi)``.
* Body frame: x forward, y right, z down. Attitude = aerospace Z-Y-X Euler angles: yaw ``psi``
  (= heading, about the down axis), then pitch ``theta`` (positive nose up), then roll ``phi``
  (positive right wing down). Body-to-NED: ``R = Rz(psi) Ry(theta) Rx(phi)``; local (ENU)
  components are ``(N_y, N_x, -N_z)`` of the NED ones. Consequences: positive pitch tilts a
  nadir beam forward; positive roll (right wing down) tilts a nadir beam to the LEFT, e.g.
  heading north and roll +10 deg give ``(-sin 10 deg, 0, -cos 10 deg)``.

Attitude motion (true aircraft attitude about the line heading, per axis):
``sum_h a w_h sin(2 pi t / (P r_h) + phi_h)`` with period ratios ``r = (1, 0.382, 0.146)``,
weights ``w = (0.6, 0.3, 0.1)`` (so ``a`` = amplitude bounds the periodic part) and random phases
``phi_h`` drawn once from ``default_rng([seed, 4])``; plus a slow drift standing in for a random
walk: a first-order Gauss–Markov process (random walk on time scales below its correlation time,
but bounded), see :mod:`pipeline.simulate.noise`. Both are pure functions of absolute time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.config import setting
from pipeline.simulate.noise import STREAM_ATTITUDE_DRIFT, STREAM_ATTITUDE_PHASE, gauss_markov
from pipeline.simulate.scanner import ScannerSettings, swath_width_m

__all__ = [
    "FlightSettings",
    "AttitudeSettings",
    "FlightLines",
    "plan_lines",
    "attitude_motion",
    "body_to_local",
    "rotate_body_to_local",
]

_PERIOD_RATIOS = (1.0, 0.382, 0.146)
_WEIGHTS = (0.6, 0.3, 0.1)


@dataclass(frozen=True)
class FlightSettings:
    """Survey flight: height, speed, heading of the first line and the area to cover."""

    altitude_m: float = setting(
        400.0, ge=1.0, le=20000.0, doc="height of the laser above local z = 0 (m)"
    )
    speed_m_s: float = setting(60.0, ge=0.1, le=400.0, doc="ground speed along the lines (m/s)")
    heading_deg: float = setting(
        0.0, ge=0.0, lt=360.0, doc="heading of the first line, clockwise from north (deg)"
    )
    area_m: tuple[float, float, float, float] = setting(
        (-500.0, 500.0, -500.0, 500.0),
        length=4,
        ge=-1e7,
        le=1e7,
        doc="area to cover: (xmin, xmax, ymin, ymax) in local metres",
    )
    line_length_m: float | None = setting(
        None, gt=0.0, le=1e6, doc="line length centred on the area (m); default: the area's extent"
    )
    run_in_m: float = setting(0.0, ge=0.0, le=1e5, doc="extension of every line at both ends (m)")
    side_overlap_fraction: float = setting(
        0.3, ge=0.0, le=0.9, doc="fraction of the swath shared by adjacent lines"
    )
    n_lines: int | None = setting(
        None, ge=1, doc="number of lines centred on the area; default: enough to cover it"
    )
    start_time_s: float = setting(0.0, ge=0.0, le=1e9, doc="firing time of the first pulse (s)")
    turn_time_s: float = setting(0.0, ge=0.0, doc="time between lines, no pulses fired (s)")

    def __post_init__(self) -> None:
        xmin, xmax, ymin, ymax = self.area_m
        if not (xmin < xmax and ymin < ymax):
            raise ValueError(f"area_m must satisfy xmin < xmax and ymin < ymax; got {self.area_m}.")


@dataclass(frozen=True)
class AttitudeSettings:
    """True aircraft motion about the nominal level attitude along the line heading."""

    roll_amplitude_deg: float = setting(1.5, ge=0.0, lt=45.0, doc="peak roll oscillation (deg)")
    roll_period_s: float = setting(9.0, gt=0.0, doc="period of the main roll oscillation (s)")
    pitch_amplitude_deg: float = setting(0.8, ge=0.0, lt=45.0, doc="peak pitch oscillation (deg)")
    pitch_period_s: float = setting(14.0, gt=0.0, doc="period of the main pitch oscillation (s)")
    yaw_amplitude_deg: float = setting(0.8, ge=0.0, lt=45.0, doc="peak yaw oscillation (deg)")
    yaw_period_s: float = setting(25.0, gt=0.0, doc="period of the main yaw oscillation (s)")
    drift_sigma_deg: float = setting(
        0.2, ge=0.0, lt=10.0, doc="standard deviation of the slow drift on each axis (deg)"
    )
    drift_correlation_time_s: float = setting(
        60.0, ge=1e-3, doc="Gauss-Markov correlation time of the drift (s)"
    )


@dataclass(frozen=True, eq=False)
class FlightLines:
    """Planned survey lines, flown in order, alternating direction (boustrophedon).

    Attributes
    ----------
    start_xy, end_xy : numpy.ndarray
        ``(n_lines, 2)`` local (x, y) of the first and last pulse's nadir point (m).
    heading_rad : numpy.ndarray
        ``(n_lines,)`` heading of each line, clockwise from north, in [0, 2 pi).
    line_spacing_m, swath_width_m, length_m : float
        Distance between adjacent lines, flat-ground swath width, line length.
    n_pulses : numpy.ndarray
        ``(n_lines,)`` int64 pulses per line.
    pulse_offset : numpy.ndarray
        ``(n_lines + 1,)`` int64 global index of each line's first pulse; last = total.
    t_start_s : numpy.ndarray
        ``(n_lines,)`` firing time of each line's first pulse (s).
    """

    start_xy: np.ndarray
    end_xy: np.ndarray
    heading_rad: np.ndarray
    line_spacing_m: float
    swath_width_m: float
    length_m: float
    n_pulses: np.ndarray
    pulse_offset: np.ndarray
    t_start_s: np.ndarray

    @property
    def n_lines(self) -> int:
        """Number of lines."""
        return int(self.heading_rad.size)

    @property
    def n_pulses_total(self) -> int:
        """Pulses of the whole survey."""
        return int(self.pulse_offset[-1])


def _readonly(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


def plan_lines(flight: FlightSettings, scanner: ScannerSettings) -> FlightLines:
    """Plan parallel lines covering ``flight.area_m`` with the requested side overlap.

    Spacing = swath x (1 - overlap), with the flat-ground swath of
    :func:`~pipeline.simulate.scanner.swath_width_m`. Lines run along ``flight.heading_deg``
    (odd lines the opposite way) across the rectangle's full along-track extent (or
    ``line_length_m``) plus ``run_in_m`` at each end; they are ordered from left to right of the
    first line's heading and centred across track on the area, and unless ``n_lines`` is given
    there are just enough for the outer swath edges to reach the area's edges. Line ``j``
    starts ``j`` x (pulses-per-line / PRF + ``turn_time_s``) after ``start_time_s``.
    """
    swath = swath_width_m(scanner, flight.altitude_m)
    spacing = swath * (1.0 - flight.side_overlap_fraction)
    psi = math.radians(flight.heading_deg)
    along = np.array([math.sin(psi), math.cos(psi)])
    right = np.array([math.cos(psi), -math.sin(psi)])
    xmin, xmax, ymin, ymax = flight.area_m
    corners = np.array([[xmin, ymin], [xmin, ymax], [xmax, ymin], [xmax, ymax]])
    u, v = corners @ along, corners @ right
    umin, umax, vmin, vmax = u.min(), u.max(), v.min(), v.max()
    if flight.line_length_m is not None:
        uc = 0.5 * (umin + umax)
        umin, umax = uc - 0.5 * flight.line_length_m, uc + 0.5 * flight.line_length_m
    umin, umax = umin - flight.run_in_m, umax + flight.run_in_m
    if flight.n_lines is not None:
        n = flight.n_lines
    else:
        n = max(1, math.ceil((vmax - vmin - swath) / spacing - 1e-9) + 1)
    idx = np.arange(n)
    v_line = 0.5 * (vmin + vmax) + (idx - 0.5 * (n - 1)) * spacing
    odd = idx % 2 == 1
    u0 = np.where(odd, umax, umin)
    u1 = np.where(odd, umin, umax)
    start = u0[:, None] * along + v_line[:, None] * right
    end = u1[:, None] * along + v_line[:, None] * right
    heading = np.where(odd, np.mod(psi + math.pi, 2.0 * math.pi), psi)
    length = float(umax - umin)
    per_line = math.floor(length / flight.speed_m_s * scanner.prf_hz) + 1
    n_pulses = np.full(n, per_line, dtype=np.int64)
    offset = np.concatenate([[0], np.cumsum(n_pulses)]).astype(np.int64)
    line_time = per_line / scanner.prf_hz + flight.turn_time_s
    t_start = flight.start_time_s + idx * line_time
    return FlightLines(
        start_xy=_readonly(start),
        end_xy=_readonly(end),
        heading_rad=_readonly(heading),
        line_spacing_m=float(spacing),
        swath_width_m=float(swath),
        length_m=length,
        n_pulses=_readonly(n_pulses),
        pulse_offset=_readonly(offset),
        t_start_s=_readonly(t_start.astype(np.float64)),
    )


def attitude_motion(t_s: np.ndarray, attitude: AttitudeSettings, seed: int) -> np.ndarray:
    """Evaluate the true attitude perturbation (roll, pitch, yaw about the heading) at ``t_s``.

    Returns
    -------
    numpy.ndarray
        ``(n, 3)`` roll, pitch, yaw-offset (rad); yaw = line heading + yaw-offset.
    """
    t = np.asarray(t_s, dtype=np.float64)
    out = np.zeros((t.size, 3))
    phases = np.random.default_rng([seed, STREAM_ATTITUDE_PHASE]).uniform(0.0, 2 * math.pi, (3, 3))
    axes = (
        (attitude.roll_amplitude_deg, attitude.roll_period_s),
        (attitude.pitch_amplitude_deg, attitude.pitch_period_s),
        (attitude.yaw_amplitude_deg, attitude.yaw_period_s),
    )
    for axis, (amp_deg, period) in enumerate(axes):
        if amp_deg == 0.0:
            continue
        for h, (ratio, weight) in enumerate(zip(_PERIOD_RATIOS, _WEIGHTS, strict=True)):
            omega = 2.0 * math.pi / (period * ratio)
            out[:, axis] += math.radians(amp_deg) * weight * np.sin(omega * t + phases[axis, h])
    if attitude.drift_sigma_deg > 0.0:
        drift = gauss_markov(t, attitude.drift_correlation_time_s, seed, STREAM_ATTITUDE_DRIFT, 3)
        out += math.radians(attitude.drift_sigma_deg) * drift
    return out


def _rows(roll_rad, pitch_rad, yaw_rad):
    """Return the nine entries of the body-to-local matrices, row by row, as 1-D arrays."""
    r, p, y = (
        np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (roll_rad, pitch_rad, yaw_rad)
    )
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    spsy, spcy = sp * sy, sp * cy
    return (
        (cp * sy, sr * spsy + cr * cy, cr * spsy - sr * cy),
        (cp * cy, sr * spcy - cr * sy, cr * spcy + sr * sy),
        (sp, -sr * cp, -cr * cp),
    )


def body_to_local(roll_rad: np.ndarray, pitch_rad: np.ndarray, yaw_rad: np.ndarray) -> np.ndarray:
    """Rotation matrices from the body frame (x fwd, y right, z down) to local (E, N, U).

    Returns
    -------
    numpy.ndarray
        ``(n, 3, 3)``; ``v_local = R @ v_body``.
    """
    rows = _rows(roll_rad, pitch_rad, yaw_rad)
    return np.stack([np.stack(np.broadcast_arrays(*row), axis=-1) for row in rows], axis=-2)


def rotate_body_to_local(
    roll_rad: np.ndarray, pitch_rad: np.ndarray, yaw_rad: np.ndarray, v_body: np.ndarray
) -> np.ndarray:
    """Rotate body-frame vectors ``(n, 3)`` to the local frame, element by element.

    Same result as ``body_to_local(...) @ v`` without building the ``(n, 3, 3)`` array.
    """
    v = np.asarray(v_body, dtype=np.float64)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    out = np.empty(np.broadcast_shapes(x.shape, np.shape(np.atleast_1d(roll_rad))) + (3,))
    for i, (m0, m1, m2) in enumerate(_rows(roll_rad, pitch_rad, yaw_rad)):
        out[..., i] = m0 * x + m1 * y + m2 * z
    return out
