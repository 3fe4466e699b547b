"""Detector and digitiser settings of the waveform stage, and the per-pulse quality flags.

The scene already holds the optics (:class:`~pipeline.scene.SystemSettings`: pulse energy,
efficiencies, aperture, pulse FWHM, filter, dark counts) and the scanner's field of view; this
module holds what turns photoelectrons into recorded data: the receiver kind, its gain and noise,
the digitiser, the range gate and the photon-counting dead time.

Flags
-----
Every pulse carries a ``uint16`` bit mask (:data:`PULSE_FLAG_NAMES`); a set bit means "do not
trust this pulse for that purpose", and the data stay finite whatever the flags say.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.config import setting
from pipeline.errors import SceneError

__all__ = [
    "DetectorSettings",
    "MODES",
    "SATURATED",
    "NO_SIGNAL",
    "BOTTOM_BELOW_NOISE",
    "MERGED_SURFACE_BOTTOM",
    "BOTTOM_OUTSIDE_WINDOW",
    "PARTIAL_FOOTPRINT",
    "LAND_RETURN",
    "PULSE_FLAG_NAMES",
    "PRESETS_DIR",
    "describe_pulse_flags",
    "load_preset",
]

#: Documented instrument presets (scene fragments with a source for every value).
PRESETS_DIR = Path(__file__).resolve().parents[1] / "scenes" / "presets"

MODES = ("full_waveform", "photon_counting")

#: A digitiser sample reached its top code (full waveform), or a return put more than
#: :data:`PC_SATURATION_PE_PER_CHANNEL` photoelectrons on a photon-counting channel, or the
#: photon-counting draw was capped: amplitudes (and first-photon ranges) are biased.
SATURATED = np.uint16(1)
#: No return (surface, land or bottom) reaches the detection SNR: nothing usable in the pulse.
NO_SIGNAL = np.uint16(2)
#: The pulse has a water path to the seabed but the bottom return is below the detection SNR.
BOTTOM_BELOW_NOISE = np.uint16(4)
#: Surface and bottom returns are closer in time than the wider return's FWHM: one peak.
MERGED_SURFACE_BOTTOM = np.uint16(8)
#: The bottom return's centre lies after the end of the recording window (range gate).
BOTTOM_OUTSIDE_WINDOW = np.uint16(16)
#: Some sub-rays missed, found no bottom or met total internal reflection on the way back.
PARTIAL_FOOTPRINT = np.uint16(32)
#: At least one sub-ray hit land (seabed above the water): a topographic return.
LAND_RETURN = np.uint16(64)
PULSE_FLAG_NAMES = {
    1: "saturated",
    2: "no_signal",
    4: "bottom_below_noise",
    8: "merged_surface_bottom",
    16: "bottom_outside_window",
    32: "partial_footprint",
    64: "land_return",
}
#: Expected photoelectrons of one return on one photon-counting channel above which the
#: channel is flagged saturated: at 10 the first photon almost surely comes from the leading
#: edge (range bias above one pulse sigma) and the return's strength is lost to dead time.
PC_SATURATION_PE_PER_CHANNEL = 10.0


@dataclass(frozen=True, kw_only=True)
class DetectorSettings:
    """The receiver after the optics: detector, gain, noise, digitiser and range gate.

    One photon model feeds both modes (see :mod:`pipeline.simulate.waveform`): in
    ``"full_waveform"`` photoelectrons are binned on the digitiser clock, amplified with gain
    noise and quantised; in ``"photon_counting"`` their arrival times are recorded, thinned by
    the dead time of each channel.
    """

    mode: str = setting("full_waveform", choices=MODES, doc="receiver kind")
    sample_rate_hz: float = setting(
        1.0e9, gt=1e6, le=1e11, doc="digitiser rate (full waveform) or range-gate clock"
    )
    window_s: float = setting(
        3.0e-7, ge=1e-8, le=1e-4, doc="length of the recorded window (range gate) per pulse"
    )
    pre_trigger_s: float = setting(
        2.0e-8, ge=0.0, le=1e-5, doc="window opens this long before the first surface/land echo"
    )
    bit_depth: int = setting(12, ge=1, le=24, doc="digitiser resolution; top code 2^bits - 1")
    baseline_counts: float = setting(100.0, ge=0.0, doc="digitiser offset with no light (counts)")
    counts_per_photoelectron: float = setting(
        1.0, ge=1e-3, le=1e6, doc="mean digitiser counts per photoelectron (detector gain x ADC)"
    )
    excess_noise_factor: float = setting(
        1.0, ge=1.0, le=100.0, doc="F = <g^2>/<g>^2 of the detector gain (PMT ~1.2, APD 2-5)"
    )
    electronic_noise_counts: float = setting(
        0.0, ge=0.0, le=1e6, doc="rms Gaussian noise per digitiser sample (counts)"
    )
    impulse_response_fwhm_s: float = setting(
        0.0, ge=0.0, le=1e-6, doc="detector + electronics timing spread (Gaussian jitter FWHM)"
    )
    dead_time_s: float = setting(
        0.0, ge=0.0, le=1e-5, doc="photon counting: non-paralyzable dead time per channel"
    )
    n_channels: int = setting(
        1, ge=1, le=10_000, doc="photon counting: independent detector channels per beam"
    )
    strong_return_photoelectrons: float = setting(
        1.0e4,
        gt=0.0,
        doc="returns with at least this many expected photoelectrons are drawn as expected "
        "shape + Gaussian noise (full waveform) or capped and flagged (photon counting)",
    )
    detection_snr: float = setting(
        3.0, ge=0.0, le=1e3, doc="SNR below which a return is flagged as below the noise"
    )

    def __post_init__(self) -> None:
        top = 2**self.bit_depth - 1
        if self.baseline_counts >= top:
            raise SceneError(
                f"`detector.baseline_counts` must be < the top code 2^bit_depth - 1 = {top}; "
                f"got {self.baseline_counts}."
            )
        n = self.n_samples
        if not 1 <= n <= 1_000_000:
            raise SceneError(
                "`detector.window_s` x `detector.sample_rate_hz` must give 1 to 1e6 samples; "
                f"got {self.window_s} s x {self.sample_rate_hz} Hz = {n}."
            )

    @property
    def sample_interval_s(self) -> float:
        """Digitiser (or gate clock) period, seconds."""
        return 1.0 / self.sample_rate_hz

    @property
    def n_samples(self) -> int:
        """Samples per recorded window: ``round(window_s * sample_rate_hz)``, at least 1."""
        return max(1, int(round(self.window_s * self.sample_rate_hz)))

    @property
    def top_code(self) -> int:
        """Largest digitiser value, ``2**bit_depth - 1``."""
        return 2**self.bit_depth - 1

    @property
    def gain_variance_factor(self) -> float:
        """``F - 1``: variance of one photoelectron's charge in units of its squared mean."""
        return self.excess_noise_factor - 1.0

    def noise_photoelectrons_per_sample(self) -> float:
        """Electronic noise variance expressed in photoelectrons², ``(sigma_e / G)²``."""
        if self.mode == "photon_counting":
            return 0.0
        return (self.electronic_noise_counts / self.counts_per_photoelectron) ** 2


def describe_pulse_flags(flags: np.ndarray) -> dict[str, int]:
    """Count the pulses carrying each flag (and ``ok`` for none)."""
    flags = np.asarray(flags)
    counts = {"ok": int(np.count_nonzero(flags == 0))}
    for bit, name in PULSE_FLAG_NAMES.items():
        counts[name] = int(np.count_nonzero(flags & bit))
    return counts


def load_preset(name: str) -> dict[str, Any]:
    """Parsed tables of a preset in :data:`PRESETS_DIR` (``"topobathy_full_waveform"`` ...).

    Returns
    -------
    dict
        The TOML tables (``system``, ``scanner``, ``detector``, ``returns``) as plain data, to
        merge into a scene mapping or validate with :func:`pipeline.config.from_mapping`.
    """
    path = PRESETS_DIR / f"{name}.toml"
    if not path.is_file():
        known = ", ".join(sorted(p.stem for p in PRESETS_DIR.glob("*.toml")))
        raise SceneError(f"Unknown preset `{name}`; known presets: {known}.")
    return tomllib.loads(path.read_text(encoding="utf-8"))
