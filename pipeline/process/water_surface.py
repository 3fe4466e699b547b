"""The fitted water surface seen by each pulse (made by :mod:`pipeline.process.surface_fit`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["WaterSurface"]


@dataclass(frozen=True)
class WaterSurface:
    """The fitted water surface seen by each pulse (``n`` rows, one per pulse).

    Attributes
    ----------
    entry_m : (n, 3)
        Where the measured beam meets the fitted surface (land pulses: the global plane; grazing
        pulses: the origin).
    range_to_entry_m : (n,)
        Distance along the beam from the measured origin to ``entry_m`` (0 when grazing).
    normal : (n, 3)
        Upward unit normal of the local plane.
    is_water, is_land : (n,) bool
        The pulse enters water / hits land. Neither: no valid entry (grazing).
    surface_point_m : (n, 3)
        Measured surface-return point (zeros where there is no surface return); photon
        windows: the window's one height carried to the shot (``own_shift_m``).
    surface_residual_m : (n,)
        Signed distance of the pulse's own surface point above its local plane (0 if none).
    fit_sigma_m : (n,)
        Residual standard deviation of the local fit (global fit where it fell back).
    height_sigma_m : (n,)
        Standard error of the fitted surface height at the entry point.
    normal_sigma_rad : (n,)
        Standard error of the surface tilt.
    n_used : (n,) int64
        Surface points used by the local fit (0 where the global plane was used).
    flags : (n,) uint16
        :class:`~pipeline.process.returns.PointFlag` bits (fallback, outlier, land, grazing,
        ill-conditioned).
    global_plane : (3,)
        ``(z0_m, dz_dx, dz_dy)``: the global water plane ``z = z0 + dz_dx x + dz_dy y``.
    global_sigma_m : float
        Residual standard deviation of the global plane fit.
    air_index : float
        Index of air used for every air range.
    time_window_s : float or None
        The fit's time window (neighbours this close in time); None: none.
    own_weight : (n,) or None
        Weight in [0, 1] of the pulse's own surface echo against its local plane in the height
        the pulse met (:func:`~pipeline.process.surface_land.own_echo_weight`): 1 where the
        detector gives no timing sigma. None (older objects): 1.
    own_shift_m : (n,) or None
        Range added along the beam to the pulse's own surface return before it is read as the
        sea the pulse met: photon-counting windows, whose shots share one height measured at
        the window's centre, carry it along the local plane's slope to each shot
        (:mod:`pipeline.process.surface_fit`, step 3). None: 0.
    sea_correlation : SeaCorrelation or None
        How far the own echo's sea tells the sea above the sounding
        (:mod:`pipeline.process.sea_correlation`); None: not at all (the plane alone).
    sea_field : SeaField or None
        The echoes that krige the sea above each sounding at its pulse's time
        (:mod:`pipeline.process.sea_kriging`); None: the plane (and ``sea_correlation``) is read.
    sea_change_m : (n,) or None
        The kriged change of the sea from each pulse's entry to above its sounding, held
        (:func:`~pipeline.process.refraction.kriged_sea_change`; NaN: the plane's reading);
        None: kriged where the points are made (the TPU holds it while it moves its inputs).
    facet_slope_var : (n, 2) or None
        Slope variance (rad²) of the wave facets about each pulse's plane, along and across
        its flight line ``track_xy`` (:mod:`pipeline.process.facet_excess`); None: none.
    track_xy : (n, 2) or None
        Unit horizontal direction of each pulse's flight line (with ``facet_slope_var``).
    wide : SurfaceWide or None
        The survey-wide figures the fit used (measured from its pulses, or handed in:
        :mod:`pipeline.process.surface_wide`).
    """

    entry_m: np.ndarray
    range_to_entry_m: np.ndarray
    normal: np.ndarray
    is_water: np.ndarray
    is_land: np.ndarray
    surface_point_m: np.ndarray
    surface_residual_m: np.ndarray
    fit_sigma_m: np.ndarray
    height_sigma_m: np.ndarray
    normal_sigma_rad: np.ndarray
    n_used: np.ndarray
    flags: np.ndarray
    global_plane: np.ndarray
    global_sigma_m: float
    air_index: float
    time_window_s: float | None = None
    own_weight: np.ndarray | None = None
    own_shift_m: np.ndarray | None = None
    sea_correlation: object | None = None
    sea_field: object | None = None
    sea_change_m: np.ndarray | None = None
    facet_slope_var: np.ndarray | None = None
    track_xy: np.ndarray | None = None
    wide: object | None = None

    #: The fields that are not one row per pulse (the rest are taken row by row).
    SURVEY_FIELDS = (
        "global_plane",
        "global_sigma_m",
        "air_index",
        "time_window_s",
        "sea_correlation",
        "sea_field",
        "wide",
    )

    def __len__(self) -> int:
        return int(self.entry_m.shape[0])

    def surface_z_m(self, index: np.ndarray, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Height of the local planes of pulses ``index`` at ``(x_m, y_m)``.

        Land pulses use the global water plane; grazing pulses (no entry) too.
        """
        e = self.entry_m[index]
        nrm = self.normal[index]
        z = e[:, 2] - (nrm[:, 0] * (x_m - e[:, 0]) + nrm[:, 1] * (y_m - e[:, 1])) / nrm[:, 2]
        valid = self.is_water[index] | self.is_land[index]
        return np.where(valid, z, self.global_z_m(x_m, y_m))  # grazing: no local entry

    def level_z_m(self, index: np.ndarray, at_xy_m: np.ndarray, xy_m: np.ndarray) -> np.ndarray:
        """The level of pulses' local planes at ``at_xy_m``, carried level to ``xy_m``; ``(n,)``.

        The local plane's height at ``at_xy_m`` (where the pulse met the sea) plus the global
        plane's rise from there to ``xy_m``: the local plane's own tilt is left out (how much
        of it to carry is measured, :meth:`SeaCorrelation.tilt_at
        <pipeline.process.sea_correlation.SeaCorrelation.tilt_at>`); the global plane's tilt
        (a datum's slope) is kept.
        """
        at, xy = np.asarray(at_xy_m, dtype=np.float64), np.asarray(xy_m, dtype=np.float64)
        z = self.surface_z_m(index, at[:, 0], at[:, 1])
        return z + self.global_z_m(xy[:, 0], xy[:, 1]) - self.global_z_m(at[:, 0], at[:, 1])

    def global_z_m(self, x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
        """Height of the global water plane at ``(x_m, y_m)``."""
        z0, gx, gy = self.global_plane
        return z0 + gx * np.asarray(x_m) + gy * np.asarray(y_m)
