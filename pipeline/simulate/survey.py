"""Survey simulation, aircraft and scanner side: which pulse leaves from where, in which direction.

This module is the entry point; settings and helpers live in :mod:`.trajectory`,
:mod:`.scanner` and :mod:`.noise` and are re-exported here.

Conventions
-----------
* Local frame: x east, y north, z up, metres, float64, relative to a local origin; the laser
  flies at ``z = altitude_m``.
* Heading and azimuth: clockwise from north. Settings hold angles in DEGREES; all code,
  arrays and returned values are in radians.
* Body frame: x forward, y right, z down (aerospace). Attitude: Z-Y-X Euler angles, yaw
  (= heading) then pitch (positive nose up) then roll (positive right wing down), body-to-NED
  ``Rz(yaw) Ry(pitch) Rx(roll)``, then NED -> ENU. Sign consequences: positive pitch tilts a
  nadir beam forward; positive roll tilts a nadir beam to the LEFT (heading north, roll
  +10 deg: direction ``(-sin 10 deg, 0, -cos 10 deg)``).
* The laser origin is the navigation reference point (lever arm and boresight are zero); the
  true trajectory is the straight planned line at constant height and speed, and the aircraft
  attitude oscillates about level flight with yaw about the line heading (crab-free track).
* Timing: pulses are numbered globally from 0 over the lines flown in order; pulse ``i`` on
  line ``j`` fires at ``t = t_start_s[j] + (i - pulse_offset[j]) / prf_hz``; the lines are
  separated by ``turn_time_s`` without pulses (see :func:`plan_lines`).
* Scan patterns: see :mod:`.scanner` (Palmer cone, triangular oscillating mirror, profiler).
* Measured navigation = truth + errors of :class:`NavigationNoiseSettings` (first-order
  Gauss–Markov or white); ``direction_meas`` is the body-frame beam (scanner angle assumed
  exact) rotated with the measured attitude.

Chunk invariance
----------------
Everything about pulse ``i`` is a pure, element-wise function of ``i``, its time ``t`` and the
seed: attitude sinusoids are evaluated at ``t`` with phases drawn once from the seed; white noise
comes from fixed 4096-pulse blocks seeded by ``(seed, stream, block)``; correlated noise from a
fixed knot grid whose knot values depend only on a fixed window of blocked innovations (details
in :mod:`.noise`). No state is carried between chunks and no reduction mixes pulses, so any
chunking gives bit-identical arrays, and a chunk allocates O(chunk_size) memory (plus fixed-size
noise blocks).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np

from pipeline.simulate.noise import NavigationNoiseSettings, navigation_errors
from pipeline.simulate.scanner import (
    ScannerSettings,
    beam_directions_body,
    footprint_diameter_m,
    swath_width_m,
)
from pipeline.simulate.trajectory import (
    AttitudeSettings,
    FlightLines,
    FlightSettings,
    attitude_motion,
    body_to_local,
    plan_lines,
    rotate_body_to_local,
)

__all__ = [
    "AttitudeSettings",
    "FlightLines",
    "FlightSettings",
    "NavigationNoiseSettings",
    "Pulses",
    "ScannerSettings",
    "attitude_motion",
    "beam_directions_body",
    "body_to_local",
    "flat_ground_hits",
    "footprint_diameter_m",
    "generate_pulses",
    "iter_pulse_chunks",
    "n_chunks",
    "navigation_errors",
    "plan_lines",
    "pulse_times_s",
    "pulses_for_range",
    "rotate_body_to_local",
    "swath_width_m",
]


@dataclass(frozen=True, eq=False)
class Pulses:
    """A batch of laser pulses: true geometry and what the navigation system measured.

    All arrays have ``n`` rows, are read-only, and are float64 unless stated.

    Attributes
    ----------
    pulse_id : numpy.ndarray
        ``(n,)`` int64 global pulse index (0-based over the whole survey).
    line_id : numpy.ndarray
        ``(n,)`` int64 index of the flight line.
    t_s : numpy.ndarray
        ``(n,)`` firing time (s).
    origin_m : numpy.ndarray
        ``(n, 3)`` true laser position in the local frame (m).
    direction : numpy.ndarray
        ``(n, 3)`` true unit beam direction in the local frame.
    scan_angle_rad : numpy.ndarray
        ``(n,)`` scanner angle (Palmer azimuth from forward, clockwise from above; oscillating
        mirror angle, positive right; 0 for the profiler).
    roll_rad, pitch_rad, yaw_rad : numpy.ndarray
        ``(n,)`` true attitude; yaw is the aircraft heading, clockwise from north (line
        heading in [0, 2 pi) plus the motion, not wrapped).
    origin_meas_m, direction_meas : numpy.ndarray
        ``(n, 3)`` measured laser position (GNSS) and beam direction (INS attitude).
    roll_meas_rad, pitch_meas_rad, yaw_meas_rad : numpy.ndarray
        ``(n,)`` measured attitude.
    """

    pulse_id: np.ndarray
    line_id: np.ndarray
    t_s: np.ndarray
    origin_m: np.ndarray
    direction: np.ndarray
    scan_angle_rad: np.ndarray
    roll_rad: np.ndarray
    pitch_rad: np.ndarray
    yaw_rad: np.ndarray
    origin_meas_m: np.ndarray
    direction_meas: np.ndarray
    roll_meas_rad: np.ndarray
    pitch_meas_rad: np.ndarray
    yaw_meas_rad: np.ndarray

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            getattr(self, f.name).flags.writeable = False

    def __len__(self) -> int:
        return int(self.pulse_id.size)

    @staticmethod
    def concatenate(parts: Sequence[Pulses]) -> Pulses:
        """Join batches end to end (e.g. the chunks of :func:`iter_pulse_chunks`)."""
        if not parts:
            raise ValueError("parts must hold at least one Pulses.")
        names = [f.name for f in dataclasses.fields(Pulses)]
        return Pulses(**{k: np.concatenate([getattr(p, k) for p in parts]) for k in names})


def pulse_times_s(lines: FlightLines, prf_hz: float, pulse_id) -> np.ndarray:
    """Emission times (s) of pulses by global index: ``t_start[line] + (i - offset) / prf``."""
    ids = np.asarray(pulse_id, dtype=np.int64)
    line = np.searchsorted(lines.pulse_offset, ids, side="right").astype(np.int64) - 1
    return lines.t_start_s[line] + (ids - lines.pulse_offset[line]) / prf_hz


def pulses_for_range(
    flight: FlightSettings,
    attitude: AttitudeSettings,
    nav_noise: NavigationNoiseSettings,
    scanner: ScannerSettings,
    lines: FlightLines,
    start: int,
    stop: int,
    seed: int,
) -> Pulses:
    """Pulses with global indices ``start <= i < stop`` (``0 <= start < stop <= total``).

    Parameters
    ----------
    flight, attitude, nav_noise, scanner
        Survey settings.
    lines : FlightLines
        Output of ``plan_lines(flight, scanner)``.
    start, stop : int
        Global pulse index range.
    seed : int
        Non-negative survey seed.
    """
    total = lines.n_pulses_total
    if not (0 <= start < stop <= total):
        raise ValueError(
            f"pulse range must satisfy 0 <= start < stop <= {total}; got {start}, {stop}."
        )
    ids = np.arange(start, stop, dtype=np.int64)
    line = np.searchsorted(lines.pulse_offset, ids, side="right").astype(np.int64) - 1
    dt = (ids - lines.pulse_offset[line]) / scanner.prf_hz
    t = pulse_times_s(lines, scanner.prf_hz, ids)
    heading = lines.heading_rad[line]
    along = dt * flight.speed_m_s
    origin = np.empty((ids.size, 3))
    origin[:, 0] = lines.start_xy[line, 0] + along * np.sin(heading)
    origin[:, 1] = lines.start_xy[line, 1] + along * np.cos(heading)
    origin[:, 2] = flight.altitude_m
    d_body, scan_angle = beam_directions_body(scanner, t)
    motion = attitude_motion(t, attitude, seed)
    roll, pitch, yaw = motion[:, 0], motion[:, 1], heading + motion[:, 2]
    pos_err, att_err = navigation_errors(ids, t, nav_noise, seed)
    roll_m, pitch_m, yaw_m = roll + att_err[:, 0], pitch + att_err[:, 1], yaw + att_err[:, 2]
    return Pulses(
        pulse_id=ids,
        line_id=line,
        t_s=t,
        origin_m=origin,
        direction=rotate_body_to_local(roll, pitch, yaw, d_body),
        scan_angle_rad=scan_angle,
        roll_rad=np.ascontiguousarray(roll),
        pitch_rad=np.ascontiguousarray(pitch),
        yaw_rad=yaw,
        origin_meas_m=origin + pos_err,
        direction_meas=rotate_body_to_local(roll_m, pitch_m, yaw_m, d_body),
        roll_meas_rad=roll_m,
        pitch_meas_rad=pitch_m,
        yaw_meas_rad=yaw_m,
    )


def n_chunks(lines: FlightLines, chunk_size: int) -> int:
    """Count the chunks of ``chunk_size`` pulses (the last one may be shorter)."""
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be >= 1; got {chunk_size}.")
    return -(-lines.n_pulses_total // chunk_size)


def generate_pulses(
    flight: FlightSettings,
    attitude: AttitudeSettings,
    nav_noise: NavigationNoiseSettings,
    scanner: ScannerSettings,
    lines: FlightLines,
    chunk_index: int,
    chunk_size: int,
    seed: int,
) -> Pulses:
    """Chunk ``chunk_index``: pulses ``chunk_index * chunk_size`` up to the next chunk's start.

    The result depends only on the global pulse indices, never on ``chunk_size`` itself.
    """
    count = n_chunks(lines, chunk_size)
    if not 0 <= chunk_index < count:
        raise ValueError(f"chunk_index must be in [0, {count}); got {chunk_index}.")
    start = chunk_index * chunk_size
    stop = min(start + chunk_size, lines.n_pulses_total)
    return pulses_for_range(flight, attitude, nav_noise, scanner, lines, start, stop, seed)


def iter_pulse_chunks(
    flight: FlightSettings,
    attitude: AttitudeSettings,
    nav_noise: NavigationNoiseSettings,
    scanner: ScannerSettings,
    lines: FlightLines,
    chunk_size: int,
    seed: int,
) -> Iterator[Pulses]:
    """Yield every pulse of the survey in order, ``chunk_size`` at a time."""
    for c in range(n_chunks(lines, chunk_size)):
        yield generate_pulses(flight, attitude, nav_noise, scanner, lines, c, chunk_size, seed)


def flat_ground_hits(origin_m: np.ndarray, direction: np.ndarray, ground_z_m: float) -> np.ndarray:
    """Intersections of rays with the horizontal plane ``z = ground_z_m``.

    Parameters
    ----------
    origin_m, direction : numpy.ndarray
        ``(n, 3)`` ray origins and directions (need not be unit).
    ground_z_m : float
        Height of the plane.

    Returns
    -------
    numpy.ndarray
        ``(n, 3)`` hit points; rows of NaN for rays that do not reach the plane going forward
        (parallel to it or pointing away).
    """
    o = np.asarray(origin_m, dtype=np.float64)
    d = np.asarray(direction, dtype=np.float64)
    dz = d[:, 2]
    gap = ground_z_m - o[:, 2]
    s = np.full(dz.shape, math.nan)
    ok = (dz != 0.0) & (gap * dz >= 0.0)
    s[ok] = gap[ok] / dz[ok]
    return o + s[:, None] * d
