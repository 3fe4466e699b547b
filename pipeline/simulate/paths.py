"""Paths: where each sub-ray of each pulse meets the water surface and the seabed.

The trace stage (:mod:`pipeline.simulate.trace`) produces one :class:`Paths` per chunk of
pulses; the waveform stage reads it. Each pulse is sampled by ``n_sub`` sub-rays spread across
its divergence cone, so the waveform sees the spread of surface slopes and depths inside one
footprint; ``subray_weight`` is the fraction of the pulse energy each sub-ray carries.

Flags are a bit mask per sub-ray (:data:`FLAG_NAMES`); a sub-ray with any flag set has no
usable water path, and the fields that do not apply hold 0 (never NaN).
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

__all__ = [
    "OK",
    "MISS",
    "LAND",
    "NO_BOTTOM",
    "TIR_RETURN",
    "FLAG_NAMES",
    "Paths",
    "describe_flags",
]

OK = np.uint8(0)
#: The sub-ray met neither the water surface nor land inside the world.
MISS = np.uint8(1)
#: The sub-ray met land (seabed above the water surface) before any water.
LAND = np.uint8(2)
#: The refracted sub-ray left the seabed mesh without meeting it.
NO_BOTTOM = np.uint8(4)
#: The return from the bottom met total internal reflection at the water surface.
TIR_RETURN = np.uint8(8)
FLAG_NAMES = {1: "miss", 2: "land", 4: "no_bottom", 8: "tir_return"}


@dataclass(frozen=True)
class Paths:
    """Traced geometry of a chunk of pulses, shapes ``(n_pulses, n_sub)`` unless stated.

    Attributes
    ----------
    pulse_id : (n_pulses,) int64
        Global pulse index (matches :class:`~pipeline.simulate.survey.Pulses`).
    subray_weight : (n_sub,) float64
        Fraction of pulse energy per sub-ray; sums to 1.
    subray_offset_rad : (n_sub, 2) float64
        Angular offset of each sub-ray from the beam axis (two orthogonal components).
    flags : uint8
        Bit mask: :data:`MISS`, :data:`LAND`, :data:`NO_BOTTOM`, :data:`TIR_RETURN`.
    origin_m : (n_pulses, 3) float64
        Laser position (local frame), the receiver too (monostatic).
    direction : (n_pulses, n_sub, 3) float64
        Unit direction of each sub-ray in air.
    air_range_m : float64
        Distance from the laser to the water surface (or to land for :data:`LAND`).
    surface_xyz_m : (n_pulses, n_sub, 3) float64
        Water-surface hit (land hit for :data:`LAND`).
    surface_normal : (n_pulses, n_sub, 3) float64
        Upward unit normal of the water surface at the hit (of land for :data:`LAND`).
    incidence_rad : float64
        Angle between the sub-ray and the upward surface normal, radians.
    transmittance_down : float64
        Fresnel power transmittance air → water for the pulse's polarisation.
    reflectance_surface : float64
        Fresnel power reflectance at the surface hit (specular).
    refracted_dir : (n_pulses, n_sub, 3) float64
        Unit direction in water (vector Snell with the phase index).
    water_path_m : float64
        Geometric path length in water from the surface hit to the seabed hit.
    bottom_xyz_m : (n_pulses, n_sub, 3) float64
        Seabed hit.
    bottom_normal : (n_pulses, n_sub, 3) float64
        Upward unit normal of the seabed at the hit.
    bottom_incidence_rad : float64
        Angle between the reversed refracted ray and the seabed normal.
    transmittance_up : float64
        Fresnel power transmittance water → air of the return (unpolarised).
    """

    pulse_id: np.ndarray
    subray_weight: np.ndarray
    subray_offset_rad: np.ndarray
    flags: np.ndarray
    origin_m: np.ndarray
    direction: np.ndarray
    air_range_m: np.ndarray
    surface_xyz_m: np.ndarray
    surface_normal: np.ndarray
    incidence_rad: np.ndarray
    transmittance_down: np.ndarray
    reflectance_surface: np.ndarray
    refracted_dir: np.ndarray
    water_path_m: np.ndarray
    bottom_xyz_m: np.ndarray
    bottom_normal: np.ndarray
    bottom_incidence_rad: np.ndarray
    transmittance_up: np.ndarray

    @property
    def n_pulses(self) -> int:
        """Number of pulses in the chunk."""
        return int(self.pulse_id.shape[0])

    @property
    def n_sub(self) -> int:
        """Sub-rays per pulse."""
        return int(self.subray_weight.shape[0])

    @property
    def valid(self) -> np.ndarray:
        """(n_pulses, n_sub) bool: sub-rays with a complete air-water-seabed path."""
        return self.flags == OK

    def equals(self, other: Paths) -> bool:
        """True when every array of ``other`` is bit-for-bit equal to this one's."""
        return all(
            np.array_equal(getattr(self, f.name), getattr(other, f.name)) for f in fields(self)
        )

    @staticmethod
    def concatenate(parts: list[Paths]) -> Paths:
        """Join chunks along the pulse axis (the sub-ray pattern must be the same)."""
        first = parts[0]
        out = {}
        for f in fields(Paths):
            if f.name in ("subray_weight", "subray_offset_rad"):
                out[f.name] = (
                    first.subray_weight if f.name == "subray_weight" else (first.subray_offset_rad)
                )
            else:
                out[f.name] = np.concatenate([getattr(p, f.name) for p in parts], axis=0)
        return Paths(**out)


def describe_flags(flags: np.ndarray) -> dict[str, int]:
    """Count the sub-rays carrying each flag (and ``ok``)."""
    flags = np.asarray(flags)
    counts = {"ok": int(np.count_nonzero(flags == 0))}
    for bit, name in FLAG_NAMES.items():
        counts[name] = int(np.count_nonzero(flags & bit))
    return counts
