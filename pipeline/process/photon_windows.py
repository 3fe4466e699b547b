"""Which shots a photon-counting detection accumulates: windows of shots, by time and by place.

A shot holds a handful of photons; the detector histograms the events of a *window* of shots
and reports one surface and one bottom for all of them
(:mod:`pipeline.process.detect_photons`). Every stage that meets those shared detections (the
surface fit's one sample per window, the TPU's window terms, the posteriors of window
histograms, the evaluation's draws) must group the shots exactly as the detector did: this
module is the one place that says how.

* ``cell_m = 0``: ``shots_per_window`` consecutive shots (``pulse_id // shots_per_window``).
  Under a nadir profiler they lie along ~0.4-0.8 m of track (200-400 shots at 32 kHz and
  60 m/s), as ICESat-2's along-track aggregates do.
* ``cell_m > 0``: shots grouped by where their measured beams meet the frame's datum
  ``z = 0`` (the water's nominal level), in square cells of ``cell_m`` on the frame's axes,
  within slabs of time of ``slab_shots`` consecutive shots. A scanner sweeps its consecutive
  shots over tens of metres (a Palmer circle of 134 m radius at 20 Hz: 84 m per 200 shots at
  32 kHz), so consecutive windows would histogram a seabed and a sea that change under them; a
  cell keeps the window on one patch of the sea and seabed, as the gridded photon aggregation
  of airborne single-photon bathymetry does. A shot's cell depends on its own measured beam
  only, and its slab on its own number: the windows do not depend on the chunking, provided
  chunks hold whole slabs (:mod:`pipeline.run_survey`).

:func:`resolve_windows` sizes a scan's cells from the plan (``process.photon_detect.
window_cell_m`` unset): a cell holds about ``shots_per_window`` shots of one look of the scan
(the profiler's photon statistics per window), ``side = sqrt(shots_per_window / density)``
with the plan's shot density per look ``prf / (swath x speed x looks)`` (a Palmer circle looks
at a place twice, forward and backward, in different slabs); a slab lasts the flight over
:data:`SLAB_CELLS` cell sides, so few cells are cut by a slab's ends.

The key of a cell window packs its slab and cell indices into one int64 (:func:`window_keys`);
only equality of keys matters to the stages that group by them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "MAX_CELL_INDEX",
    "MAX_SLABS",
    "SLAB_CELLS",
    "PhotonWindows",
    "crossing_xy",
    "resolve_windows",
    "sea_band_m",
    "slab_of",
    "window_keys",
]

#: A slab of cell windows lasts the flight over this many cell sides (a cell's shots of one
#: look come within one cell side of flight: about 1 in this many windows is cut in two).
SLAB_CELLS = 10.0
#: Bits of each cell index and of the slab number in a cell window's key.
_CELL_BITS = 20
_SLAB_BITS = 63 - 2 * _CELL_BITS
#: Largest cell index from the frame's origin and number of slabs a key holds.
MAX_CELL_INDEX, MAX_SLABS = 2 ** (_CELL_BITS - 1) - 1, 2**_SLAB_BITS


def window_keys(
    pulse_id: np.ndarray,
    origin_m: np.ndarray | None,
    direction: np.ndarray | None,
    shots_per_window: int,
    cell_m: float = 0.0,
) -> np.ndarray:
    """The window of each shot (module notes), an int64 key equal for the shots of one window.

    Parameters
    ----------
    pulse_id : (n,) int
        Global shot numbers.
    origin_m, direction : (n, 3) float, optional
        Measured laser position and unit beam of each shot (needed only when ``cell_m > 0``).
    shots_per_window : int
        Consecutive shots per window (``cell_m = 0``) or per slab.
    cell_m : float
        Side of the horizontal cells that split each slab; 0: no split.

    Returns
    -------
    (n,) int64
        ``pulse_id // shots_per_window`` when ``cell_m = 0`` (so a profiler's windows are
        numbered as they always were), else the slab and the cell packed into one key.

    Raises
    ------
    ValueError
        When a cell index or a slab number does not fit its bits (cells more than ~500 000
        cells from the frame's origin, or more than 2**23 slabs).
    """
    slab = np.asarray(pulse_id, dtype=np.int64) // int(shots_per_window)
    if cell_m <= 0.0:
        return slab
    cells = np.floor(crossing_xy(origin_m, direction) / cell_m)
    half = 2 ** (_CELL_BITS - 1)
    if slab.size and (np.abs(cells).max() >= half or slab.min() < 0 or slab.max() >= 2**_SLAB_BITS):
        raise ValueError(
            f"photon windows: cells of {cell_m:g} m reach {np.abs(cells).max():.0f} cells from "
            f"the frame's origin (at most {half - 1}) or slab numbers leave 0..{2**_SLAB_BITS - 1}"
            " (process.photon_detect.window_cell_m, shots_per_window)"
        )
    ix = cells[:, 0].astype(np.int64) + half
    iy = cells[:, 1].astype(np.int64) + half
    return (slab << (2 * _CELL_BITS)) | (ix << _CELL_BITS) | iy


def crossing_xy(origin_m, direction) -> np.ndarray:
    """Where each measured beam meets ``z = 0``, ``(n, 2)``; the laser's position if it is level."""
    o = np.asarray(origin_m, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(direction, dtype=np.float64).reshape(-1, 3)
    down = d[:, 2] < -1e-9
    along = np.where(down, -o[:, 2] / np.where(down, d[:, 2], -1.0), 0.0)
    return o[:, :2] + along[:, None] * d[:, :2]


def slab_of(keys: np.ndarray) -> np.ndarray:
    """The slab number of cell windows' keys (:func:`window_keys` with ``cell_m > 0``)."""
    return np.asarray(keys, dtype=np.int64) >> (2 * _CELL_BITS)


@dataclass(frozen=True)
class PhotonWindows:
    """How a photon-counting survey's shots were accumulated (processing's one definition).

    Attributes
    ----------
    shots_per_window : int
        Consecutive shots per window (``cell_m = 0``), or about as many per cell window.
    cell_m : float
        Side of the cells (0: windows of consecutive shots).
    slab_shots : int
        Consecutive shots per slab of cell windows (``shots_per_window`` without cells).
    sea_band_m : float
        Cells only: the height band the sea's waves spread a cell's surface echo over
        (:func:`sea_band_m`); a bottom must lie at least this far below the surface peak.
    """

    shots_per_window: int
    cell_m: float = 0.0
    slab_shots: int = 0
    sea_band_m: float = 0.0

    @property
    def chunk_unit(self) -> int:
        """Shots a chunk must hold a whole multiple of (a window, or a slab of cells)."""
        return self.slab_shots if self.cell_m > 0.0 else self.shots_per_window

    def of(self, pulse_id, origin_m=None, direction=None) -> np.ndarray:
        """:func:`window_keys` of these shots, ``(n,)`` int64."""
        return window_keys(pulse_id, origin_m, direction, self.chunk_unit, self.cell_m)

    def of_returns(self, returns) -> np.ndarray:
        """The window of each pulse of ``returns`` (its measured beams), ``(n_pulses,)``."""
        return self.of(returns.pulse_id, returns.origin_meas_m, returns.direction_meas)

    def of_points(self, point_pulse_id, returns) -> np.ndarray:
        """The window of each point, from its pulse's row of ``returns``, ``(n_points,)``."""
        pid = np.asarray(point_pulse_id, dtype=np.int64)
        if self.cell_m <= 0.0:  # the pulse number alone
            return self.of(pid)
        order = np.argsort(returns.pulse_id, kind="stable")
        rows = order[np.searchsorted(returns.pulse_id[order], pid)]
        return self.of(pid, returns.origin_meas_m[rows], returns.direction_meas[rows])


def sea_band_m(wind_speed_m_s: float) -> float:
    """Height band a wind sea spreads a cell's surface echo over: its significant wave height.

    A cell's shots meet the sea at many phases of its waves, so its surface echo is as wide
    as the waves (a profiler's window, 0.4 m of track in milliseconds, sees one height): a
    return within it cannot be told from the sea's own troughs. The band is the significant
    wave height of a fully developed sea at the logged wind (Pierson and Moskowitz 1964:
    ``H_s = 0.21 U² / g``; 2.7 m at 11.3 m/s, 0.5 m at 5 m/s), an upper bound for a sea still
    growing (a shorter fetch or duration). On suite tuning seed 40 (Palmer, 11.3 m/s) a
    band of ``min_separation_m`` (0.3 m) let the cells' surface echoes read as bottoms
    0.3-0.5 m below the crests over 20 m of water.
    """
    return 0.21 * float(wind_speed_m_s) ** 2 / 9.80665


def resolve_windows(shots_per_window, cell_m, scanner, altitude_m, speed_m_s) -> PhotonWindows:
    """The survey's windows: ``cell_m`` (None: sized from the plan, module notes) and slabs.

    Parameters
    ----------
    shots_per_window : int
    cell_m : float or None
        The user's cell side (0: consecutive shots); None: 0 under a profiler, else sized.
    scanner : ScannerSettings
        The scan (its kind, angles and pulse rate): the plan's shot density.
    altitude_m, speed_m_s : float
        The flight plan's height above the water and ground speed.
    """
    spw = int(shots_per_window)
    looks = 1
    if cell_m is None:
        if scanner.kind == "profiler" or scanner.scan_rate_hz == 0.0:
            return PhotonWindows(spw)
        if scanner.kind == "palmer":
            half_angle, looks = scanner.off_nadir_deg, 2
        else:
            half_angle = scanner.scan_half_angle_deg
        swath = 2.0 * altitude_m * math.tan(math.radians(half_angle))
        cell_m = math.sqrt(spw * swath * speed_m_s * looks / scanner.prf_hz)
        cell_m = float(np.round(cell_m, 2))  # a readable figure in the manifest
    if cell_m <= 0.0:
        return PhotonWindows(spw)
    slab = int(math.ceil(scanner.prf_hz * SLAB_CELLS * cell_m / speed_m_s))
    return PhotonWindows(spw, float(cell_m), max(slab, 1))
