"""Water-surface points (measured and derived) and the return numbering of LAS points."""

from __future__ import annotations

import numpy as np

from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.refraction_settings import RefractionSettings
from pipeline.process.returns import DetectedReturns, PointFlag, Points, ReturnKind
from pipeline.process.surface_fit import WaterSurface

__all__ = ["returns_numbering", "timing_sigma", "water_surface_points"]

_C = SPEED_OF_LIGHT_M_S


def returns_numbering(returns: DetectedReturns, idx: np.ndarray, bottom: bool):
    """Return number and number of returns of the rows ``idx`` (bottom or surface), uint8."""
    hs = returns.has_surface[idx]
    n_ret = hs.astype(np.uint8) + returns.has_bottom[idx].astype(np.uint8)
    number = (1 + hs.astype(np.uint8)) if bottom else np.ones(len(idx), dtype=np.uint8)
    return number.astype(np.uint8), n_ret


def timing_sigma(returns: DetectedReturns, idx: np.ndarray, which: str, default: float):
    """The detector's ``t_{which}_sigma_s`` of the rows ``idx``, else ``default`` for all."""
    sig = getattr(returns, f"t_{which}_sigma_s")
    return np.full(len(idx), default) if sig is None else sig[idx]


def water_surface_points(
    returns: DetectedReturns,
    surface: WaterSurface,
    settings: RefractionSettings | None = None,
    *,
    derived: bool = False,
) -> Points:
    """Surface-return points (``derived=False``) or derived water-surface points (``True``).

    Measured surface points lie on the beam at ``c t_s / (2 n_air)``, one per pulse with a
    surface return (``kind = SURFACE``). Derived points are the water entry points of the
    water pulses, on the fitted surface (``kind = DERIVED_SURFACE``, flagged ``SYNTHETIC``,
    depth 0, confidence 1, vertical uncertainty = fitted height standard error).
    """
    st = settings or RefractionSettings()
    point = np.radians(st.pointing_sigma_deg)
    if derived:
        idx = np.flatnonzero(surface.is_water)
        xyz = surface.entry_m[idx]
        m = len(idx)
        return Points(
            pulse_id=returns.pulse_id[idx],
            xyz_m=xyz,
            depth_m=np.zeros(m),
            classification=np.ones(m, dtype=np.uint8),
            kind=np.full(m, ReturnKind.DERIVED_SURFACE, dtype=np.uint8),
            flags=surface.flags[idx] | np.uint16(PointFlag.SYNTHETIC),
            detector_flags=returns.flags[idx],
            return_number=np.ones(m, dtype=np.uint8),
            number_of_returns=np.ones(m, dtype=np.uint8),
            confidence=np.ones(m),
            uncertainty_v_m=np.hypot(surface.height_sigma_m[idx], st.position_sigma_v_m),
            uncertainty_h_m=np.hypot(st.position_sigma_h_m, surface.range_to_entry_m[idx] * point),
        )
    idx = np.flatnonzero(returns.has_surface)
    xyz = surface.surface_point_m[idx]
    d, nrm = returns.direction_meas[idx], surface.normal[idx]
    sin_i = np.linalg.norm(np.cross(d, nrm), axis=1)
    cos_i = np.sqrt(np.maximum(1.0 - sin_i**2, 0.0))
    r = _C * returns.t_surface_s[idx] / (2.0 * surface.air_index)
    sig_r = _C * timing_sigma(returns, idx, "surface", st.timing_sigma_s) / 2.0
    number, n_ret = returns_numbering(returns, idx, bottom=False)
    amp = None if returns.surface_amplitude is None else returns.surface_amplitude[idx]
    return Points(
        pulse_id=returns.pulse_id[idx],
        xyz_m=xyz,
        depth_m=surface.surface_z_m(idx, xyz[:, 0], xyz[:, 1]) - xyz[:, 2],
        classification=np.ones(len(idx), dtype=np.uint8),
        kind=np.full(len(idx), ReturnKind.SURFACE, dtype=np.uint8),
        flags=surface.flags[idx],
        detector_flags=returns.flags[idx],
        return_number=number,
        number_of_returns=n_ret,
        confidence=returns.surface_confidence[idx],
        uncertainty_v_m=np.sqrt(
            st.position_sigma_v_m**2 + (sig_r * cos_i) ** 2 + (r * sin_i * point) ** 2
        ),
        uncertainty_h_m=np.sqrt(st.position_sigma_h_m**2 + (sig_r * sin_i) ** 2 + (r * point) ** 2),
        amplitude=amp,
    )
