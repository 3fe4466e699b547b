"""What a full-waveform detection limit knows of the detector, and the assumed bottom's level.

Shared by the per-pulse limit (:mod:`pipeline.process.detection_limit`), the level at the
survey's decay (:mod:`pipeline.process.column_level`) and the stacked column
(:mod:`pipeline.process.column_stack`); the model is derived in
:mod:`pipeline.process.detection_limit`'s docstring.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.constants import FWHM_TO_SIGMA
from pipeline.optics import SPEED_OF_LIGHT_M_S
from pipeline.process.no_bottom_settings import NoBottomSettings
from pipeline.process.row_kernels import gaussian_rows, gaussian_weights

__all__ = [
    "DetectorModel",
    "bottom_to_column_ratio",
    "filtered_waveforms",
    "limit_time_s",
    "threshold_level",
]


@dataclass(frozen=True, kw_only=True)
class DetectorModel:
    """What the limit needs of the full-waveform detector (all known to processing).

    ``dt_s`` sample interval, ``pulse_fwhm_s`` system-response FWHM, ``noise_samples`` leading
    noise-only samples, ``threshold_sigma`` and ``min_separation_fwhm`` the detector's
    (:class:`~pipeline.process.detect.DetectSettings`), ``group_index`` of the water processing
    assumes, ``shot_noise_counts`` the detector's ``F·G`` (0: signal-independent noise).
    """

    dt_s: float
    pulse_fwhm_s: float
    noise_samples: int
    threshold_sigma: float
    min_separation_fwhm: float
    group_index: float
    shot_noise_counts: float = 0.0

    @property
    def sigma_samples(self) -> float:
        """σ of the system response, samples."""
        return self.pulse_fwhm_s * FWHM_TO_SIGMA / self.dt_s

    @property
    def correlation_samples(self) -> float:
        """``L = 2 √π σ``: the filtered noise's correlation length, samples (``1 / Σg²``)."""
        return 2.0 * math.sqrt(math.pi) * self.sigma_samples


def bottom_to_column_ratio(
    settings: NoBottomSettings, group_index: float, system_sigma_s: float
) -> float:
    """``r = ρ / (π^{3/2} β_π v σ_t)``: filtered bottom peak over column level, same depth."""
    v = SPEED_OF_LIGHT_M_S / group_index
    return settings.bottom_reflectance / (
        math.pi**1.5 * settings.backscatter_180_per_m_sr * v * system_sigma_s
    )


def filtered_waveforms(samples: np.ndarray, det: DetectorModel) -> np.ndarray:
    """Baseline-free, matched-filtered waveforms, float64 (n, m).

    The baseline is each pulse's median of its leading noise samples; the filter the system's
    Gaussian (the detector's matched filter) over ``samples`` (n, m).
    """
    y = np.asarray(samples)
    if y.dtype not in (np.float32, np.float64):
        y = y.astype(np.float64)
    m = y.shape[1]
    k = min(max(int(det.noise_samples), 4), max(m - 1, 1))
    base = np.median(np.asarray(y[:, :k], dtype=np.float64), axis=1)
    # gaussian_filter1d(y - base, σ, axis=1, mode="nearest"), compiled (row_kernels)
    return gaussian_rows(y, base, gaussian_weights(float(det.sigma_samples)))


def threshold_level(
    noise_sigma: np.ndarray, det: DetectorModel, settings: NoBottomSettings, z: float
) -> np.ndarray:
    """``C*``: the column level at which the assumed bottom's echo ``r C*`` is detected at ``z``.

    Its filtered peak stands ``z`` noise σ above the threshold: ``r C = (k + z) √(σ_f² + F G C
    Σg²)``, solved for ``C`` (``σ_f`` the filtered noise ``noise_sigma``, ``F G`` the shot
    noise, ``Σg²`` the kernel's sum of squares), shape of ``noise_sigma``.
    """
    r = bottom_to_column_ratio(settings, det.group_index, det.sigma_samples * det.dt_s)
    kern_sq = 1.0 / det.correlation_samples  # Σ of the kernel squared
    k = det.threshold_sigma + z
    q = k * k * det.shot_noise_counts * kern_sq
    nf = np.maximum(np.asarray(noise_sigma, dtype=np.float64), 1e-300)
    return (q + np.sqrt(q * q + 4.0 * r * r * k * k * nf**2)) / (2 * r * r)


def limit_time_s(
    log_margin: np.ndarray,
    decay_per_s: np.ndarray | float,
    t_max_s: np.ndarray,
    ok: np.ndarray,
    t_min_s: float,
) -> np.ndarray:
    """Detection-limit time after the surface echo, ``(n,)``; 0 where not ``ok``.

    ``log_margin / decay_per_s`` (``ln(C0 / C*)`` over the bottom's decay), clipped to the
    detector's least separation ``t_min_s`` and the last searched time ``t_max_s``.
    """
    t = log_margin / decay_per_s
    hi = np.maximum(t_max_s, t_min_s)
    return np.where(ok, np.clip(t, t_min_s, hi), 0.0)
