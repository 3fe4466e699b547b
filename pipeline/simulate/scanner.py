"""Scanner settings and scan patterns (beam directions in the aircraft body frame).

Body frame: x forward, y right (starboard), z down. The scan azimuth ``alpha`` is measured from
the forward axis towards the right wing, i.e. clockwise seen from above. Patterns are pure
functions of the absolute firing time ``t`` (s), so they need no state between chunks:

* ``"palmer"`` (elliptical / conical scanner): the beam rotates on a cone of half-angle
  ``theta = off_nadir_deg`` around the body z axis, ``alpha(t) = 2 pi frac(f t)`` with
  ``f = scan_rate_hz`` revolutions per second;
  ``d = (sin theta cos alpha, sin theta sin alpha, cos theta)``. Over level flat ground at
  height ``H`` the footprints lie on a circle of radius ``H tan theta`` around the nadir point
  (an ideal cone: the slight ellipticity of a real wedge scanner is not modelled).
* ``"oscillating"`` mirror: the beam sweeps across track in the body y–z plane with a
  triangular angle-versus-time law (constant angular speed),
  ``beta(t) = A (1 - 4 |frac(f t + 1/4) - 1/2|)``, ``A = scan_half_angle_deg``: ``beta = 0`` at
  ``t = 0`` moving right, ``+A`` at ``f t = 1/4``, ``-A`` at ``f t = 3/4``; ``f`` full
  (right-and-back) cycles per second; ``d = (0, sin beta, cos beta)``.
* ``"profiler"``: fixed nadir beam ``d = (0, 0, 1)``.

The returned scan angle is ``alpha`` (Palmer), ``beta`` (oscillating, positive = right) or 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.config import setting
from pipeline.errors import SceneError

__all__ = ["ScannerSettings", "beam_directions_body", "footprint_diameter_m", "swath_width_m"]

SCANNER_KINDS = ("palmer", "oscillating", "profiler")
POLARISATIONS = ("unpolarised", "circular", "linear_across_track", "linear_along_track")


@dataclass(frozen=True, kw_only=True)
class ScannerSettings:
    """Laser scanner: pattern, pulse rate, scan rate and beam/receiver angles."""

    kind: str = setting("palmer", choices=SCANNER_KINDS, doc="scan pattern")
    off_nadir_deg: float = setting(
        20.0, ge=0.0, lt=60.0, doc="Palmer cone half-angle: off-nadir angle of the beam (deg)"
    )
    scan_half_angle_deg: float = setting(
        20.0, ge=0.0, lt=60.0, doc="oscillating mirror: largest across-track angle (deg)"
    )
    prf_hz: float = setting(35000.0, gt=0.0, doc="pulse repetition frequency (Hz)")
    scan_rate_hz: float = setting(
        20.0, ge=0.0, doc="Palmer revolutions or oscillating full cycles per second (Hz)"
    )
    beam_divergence_mrad: float = setting(
        1.0, gt=0.0, doc="laser beam divergence, full angle at 1/e^2 irradiance (mrad)"
    )
    receiver_fov_mrad: float = setting(
        10.0, gt=0.0, doc="receiver field of view, full angle (mrad)"
    )
    polarisation: str = setting(
        "unpolarised",
        choices=POLARISATIONS,
        doc="transmitted polarisation; sets the Fresnel s/p split at the water surface",
    )

    def __post_init__(self) -> None:
        if self.receiver_fov_mrad < self.beam_divergence_mrad:
            raise SceneError(
                "`scanner.receiver_fov_mrad` must be >= `scanner.beam_divergence_mrad` "
                f"({self.beam_divergence_mrad}) so the receiver sees the whole footprint; "
                f"got {self.receiver_fov_mrad}."
            )


def footprint_diameter_m(scanner: ScannerSettings, range_m: float) -> float:
    """Laser footprint diameter (1/e^2) at ``range_m`` for a beam perpendicular to the target."""
    return 2.0 * range_m * math.tan(0.5e-3 * scanner.beam_divergence_mrad)


def swath_width_m(scanner: ScannerSettings, altitude_m: float) -> float:
    """Across-track swath width over level flat ground ``altitude_m`` below the aircraft.

    ``2 H tan(off_nadir)`` for Palmer, ``2 H tan(half_angle)`` for the oscillating mirror, the
    footprint diameter for the profiler; never less than the footprint diameter.
    """
    if scanner.kind == "palmer":
        width = 2.0 * altitude_m * math.tan(math.radians(scanner.off_nadir_deg))
    elif scanner.kind == "oscillating":
        width = 2.0 * altitude_m * math.tan(math.radians(scanner.scan_half_angle_deg))
    else:
        width = 0.0
    return max(width, footprint_diameter_m(scanner, altitude_m))


def beam_directions_body(
    scanner: ScannerSettings, t_s: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Compute unit beam directions in the body frame at firing times ``t_s``.

    Parameters
    ----------
    scanner : ScannerSettings
        Pattern and rates.
    t_s : numpy.ndarray
        ``(n,)`` absolute firing times (s).

    Returns
    -------
    direction_body : numpy.ndarray
        ``(n, 3)`` unit vectors (x forward, y right, z down).
    scan_angle_rad : numpy.ndarray
        ``(n,)`` Palmer azimuth from forward (clockwise from above), oscillating mirror angle
        (positive to the right) or zeros for the profiler.
    """
    t = np.asarray(t_s, dtype=np.float64)
    d = np.zeros((t.size, 3))
    if scanner.kind == "palmer":
        angle = 2.0 * math.pi * np.mod(scanner.scan_rate_hz * t, 1.0)
        theta = math.radians(scanner.off_nadir_deg)
        d[:, 0] = math.sin(theta) * np.cos(angle)
        d[:, 1] = math.sin(theta) * np.sin(angle)
        d[:, 2] = math.cos(theta)
    elif scanner.kind == "oscillating":
        phase = np.mod(scanner.scan_rate_hz * t + 0.25, 1.0)
        angle = math.radians(scanner.scan_half_angle_deg) * (1.0 - 4.0 * np.abs(phase - 0.5))
        d[:, 1] = np.sin(angle)
        d[:, 2] = np.cos(angle)
    else:
        angle = np.zeros(t.size)
        d[:, 2] = 1.0
    return d, angle
