"""Settings, result type and closed-form pieces of the TPU (:mod:`pipeline.uncertainty.tpu`)."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.config import setting
from pipeline.constants import FWHM_TO_SIGMA
from pipeline.lidar_equation import cox_munk_mean_square_slope
from pipeline.optics import SPEED_OF_LIGHT_M_S, water_group_index, water_phase_index
from pipeline.uncertainty.tpu_screen import LeftOut

_C = SPEED_OF_LIGHT_M_S
#: Columns of a term: the point's x, y, z and its depth at the measured position.
X, Y, Z, DEPTH = 0, 1, 2, 3

RANDOM_TERMS = (
    "timing_surface",
    "timing_bottom",
    "pointing_a",
    "pointing_b",
    "wave_height",
    "wave_slope_x",
    "wave_slope_y",
    "footprint",
)
CORRELATED_TERMS = (
    "navigation",
    "attitude_x",
    "attitude_y",
    "heading",
    "surface_height",
    "surface_tilt_x",
    "surface_tilt_y",
    "temperature",
    "salinity",
    "forward_scatter",
)
#: The terms of the return timing (the part the detector's noise sets).
TIMING_TERMS = ("timing_surface", "timing_bottom")


@dataclass(frozen=True, kw_only=True)
class TpuSettings:
    """Input one-sigma uncertainties of the TPU.

    Defaults: navigation and attitude of a post-processed GNSS/INS of the Applanix POS AV 510
    class (datasheet, post-processed: roll/pitch 0.005°, heading 0.008°; position a few cm, as
    PP-RTX vs base-station solutions agree to 2 cm horizontally and 6 cm vertically, Applanix
    airborne accuracy assessment); scanner jitter at an encoder's 0.001°; water of ±2 °C and
    ±2 psu around the nominal (index derivatives by Quan & Fry 1995); a 1 mrad beam.

    In a scene (``[process.tpu]``) the navigation, attitude, beam and wavelength keys default
    to ``None``: the scene's own ``[navigation]``, ``[scanner]`` and ``[system]`` figures, filled
    in by :func:`pipeline.process.context.processing_context`; a value the user sets wins.
    """

    position_sigma_h_m: float | None = setting(
        0.05,
        ge=0.0,
        le=100.0,
        doc="navigation, per horizontal axis (None: navigation.gnss_horizontal_sigma_m)",
    )
    position_sigma_v_m: float | None = setting(
        0.08, ge=0.0, le=100.0, doc="navigation, vertical (None: navigation.gnss_vertical_sigma_m)"
    )
    attitude_sigma_deg: float | None = setting(
        0.005,
        ge=0.0,
        le=10.0,
        doc="IMU roll and pitch (None: the larger of navigation.ins_roll/pitch_sigma_deg)",
    )
    heading_sigma_deg: float | None = setting(
        0.008, ge=0.0, le=10.0, doc="IMU heading (None: navigation.ins_heading_sigma_deg)"
    )
    pointing_jitter_deg: float = setting(0.001, ge=0.0, le=10.0, doc="per-pulse beam jitter")
    timing_sigma_s: float = setting(
        1e-10, ge=0.0, le=1e-6, doc="per-return timing if not given (at most 1 us: 150 m of range)"
    )
    temperature_sigma_c: float = setting(2.0, ge=0.0, doc="water temperature uncertainty")
    salinity_sigma_psu: float = setting(2.0, ge=0.0, doc="salinity uncertainty")
    wavelength_nm: float | None = setting(
        532.0,
        ge=400.0,
        le=700.0,
        doc="for the water index and its derivatives (None: system.wavelength_nm)",
    )
    temperature_c: float = setting(20.0, ge=-2.0, le=35.0, doc="nominal water temperature")
    salinity_psu: float = setting(35.0, ge=0.0, le=40.0, doc="nominal salinity")
    wave_slope_sigma_rad: float = setting(0.0, ge=0.0, le=1.0, doc="residual facet slope/axis")
    wave_pool_cell_m: float = setting(
        25.0,
        ge=0.0,
        le=200.0,
        doc="cell the planes' wave residual is pooled over (0: pulse by pulse)",
    )
    beam_divergence_mrad: float | None = setting(
        1.0, ge=0.0, le=100.0, doc="full angle, 1/e² (None: scanner.beam_divergence_mrad)"
    )
    seabed_slope_deg: float = setting(0.0, ge=0.0, lt=90.0, doc="assumed seabed slope")
    gradient_neighbours: int = setting(
        16, ge=3, le=256, doc="soundings per local plane of the seabed gradient"
    )
    gradient_radius_m: float = setting(10.0, gt=0.0, doc="farthest sounding of that plane")
    gradient_regional_radius_m: float = setting(
        50.0, ge=0.0, doc="regional plane the local one leans on where it is blind (0: none)"
    )
    gradient_prior_slope_deg: float = setting(
        10.0, gt=0.0, lt=90.0, doc="seabed slope per axis (1 sigma) assumed where no sounding tells"
    )
    gradient_local_sigma: float | None = setting(
        None, ge=0.0, le=10.0, doc="local seabed slope's departure from regional (None: measured)"
    )
    pair_max_separation_m: float = setting(
        2.0, gt=0.0, doc="farthest partner of a sounding in the measured scatter"
    )
    scatter_neighbours: int = setting(
        64, ge=4, le=4096, doc="sounding pairs pooled per local scatter estimate"
    )
    surface_pair_max_dt_s: float = setting(
        0.2,
        gt=0.0,
        le=10.0,
        doc="surface points paired in the surface-height variogram at most this far apart in"
        " time (the sea moves: ~1 m at a 10 m/s wind sea's phase speed)",
    )
    surface_min_pairs: int = setting(
        200, ge=10, le=1_000_000, doc="pairs a lag bin of the surface-height variogram needs"
    )


def timing_sigma_s(snr: Any, pulse_fwhm_s: float) -> np.ndarray:
    """Cramér–Rao timing sigma ``sqrt(2) sigma_p / SNR`` of a Gaussian return in white noise.

    ``snr`` is the matched-filter SNR (the detector's filtered peak over the filtered noise
    sigma, :func:`pipeline.process.detect.detect_full_waveform`): with ``rho² = sum s_i² /
    sigma_n²`` the Fisher information on the centre is ``rho² / (2 sigma_p²)``.
    """
    snr = np.asarray(snr, dtype=np.float64)
    return math.sqrt(2.0) * pulse_fwhm_s * FWHM_TO_SIGMA / np.maximum(snr, 1e-12)


def cox_munk_slope_sigma(wind_speed_m_s: float) -> float:
    """Per-axis sea-surface slope sigma of Cox & Munk (1954): ``sqrt((0.003 + 5.12e-3 U) / 2)``.

    This is the slope of the capillary-scale facets; a footprint of several metres averages
    much of it, so use it as an upper bound for ``wave_slope_sigma_rad``.
    """
    return math.sqrt(float(cox_munk_mean_square_slope(wind_speed_m_s)) / 2.0)


def index_derivatives(settings: TpuSettings) -> dict[str, tuple[float, float]]:
    """``(d n_phase, d n_group)`` per unit of temperature (°C) and salinity (psu)."""
    lam = settings.wavelength_nm * 1e-9
    t, s = settings.temperature_c, settings.salinity_psu
    out = {}
    for name, lo, hi, step in (
        ("temperature", (lam, s, t - 0.5), (lam, s, t + 0.5), 1.0),
        ("salinity", (lam, max(s - 0.5, 0.0), t), (lam, min(s + 0.5, 40.0), t), None),
    ):
        h = step if step is not None else hi[1] - lo[1]
        dp = (float(water_phase_index(*hi)) - float(water_phase_index(*lo))) / h
        dg = (float(water_group_index(*hi)) - float(water_group_index(*lo))) / h
        out[name] = (dp, dg)
    return out


@dataclass(frozen=True)
class PointTpu:
    """Propagated one-sigma uncertainty of every bottom point.

    Attributes
    ----------
    row : (n,) int64
        Row of the pulse in the ``returns`` given (pulses with a bottom return, in order: the
        rows of :func:`~pipeline.process.refraction.seabed_points`).
    pulse_id : (n,) int64
    xyz_m : (n, 3) float64
        The nominal seabed points.
    terms : dict of str to (n, 4) float64
        One-sigma change per term (:data:`RANDOM_TERMS`, :data:`CORRELATED_TERMS`) of the
        point's x, y, z (columns 0-2) and of its depth below the measured water surface at the
        measured position (column 3, see the module notes); ``navigation`` holds the three
        axis sigmas and the depth sigma they make.
    sigma_x_m, sigma_y_m, sigma_v_m : (n,) float64
        Total one-sigma per coordinate (``sigma_v_m`` is z, the elevation).
    sigma_h_m : (n,) float64
        Per-axis horizontal sigma ``sqrt((s_x² + s_y²) / 2)``.
    sigma_v_random_m, sigma_v_correlated_m, sigma_h_random_m, sigma_h_correlated_m : (n,)
        The same split into random and correlated terms.
    sigma_depth_m, sigma_depth_random_m, sigma_depth_correlated_m : (n,) float64 or None
        One-sigma of the depth below the measured water surface at the measured position
        (what ``Points.depth_m`` reports), total and split; None only in a PointTpu built by
        hand without them.
    left_out : LeftOut
        The bottom pulses not propagated, with their reasons (:mod:`pipeline.process.
        tpu_screen`); they have no row.
    """

    row: np.ndarray
    pulse_id: np.ndarray
    xyz_m: np.ndarray
    terms: dict[str, np.ndarray]
    sigma_x_m: np.ndarray
    sigma_y_m: np.ndarray
    sigma_v_m: np.ndarray
    sigma_h_m: np.ndarray
    sigma_v_random_m: np.ndarray
    sigma_v_correlated_m: np.ndarray
    sigma_h_random_m: np.ndarray
    sigma_h_correlated_m: np.ndarray
    sigma_depth_m: np.ndarray | None = None
    sigma_depth_random_m: np.ndarray | None = None
    sigma_depth_correlated_m: np.ndarray | None = None
    left_out: LeftOut = dataclasses.field(default_factory=LeftOut.none)

    def __len__(self) -> int:
        return int(self.row.shape[0])


def take_tpu(tpu: PointTpu, index: np.ndarray, consume: bool = False) -> PointTpu:
    """Rows ``index`` of a PointTpu (every per-point array and term).

    ``consume``: each term is taken out of ``tpu``'s dicts as its rows are copied, so that
    the two sets of terms (~800 B a row each: 25 terms of 4 float64) are never held side by
    side; ``tpu`` is left without its terms and must not be read again.
    """
    kw = {}
    for f in dataclasses.fields(tpu):
        v = getattr(tpu, f.name)
        if isinstance(v, dict):
            if consume:
                kw[f.name] = {k: v.pop(k)[index] for k in list(v)}
            else:
                kw[f.name] = {k: a[index] for k, a in v.items()}
        elif isinstance(v, np.ndarray) and v.ndim >= 1 and v.shape[0] == len(tpu):
            kw[f.name] = v[index]
        else:
            kw[f.name] = v
    return dataclasses.replace(tpu, **kw)
