"""Settings of the water-surface fit (:mod:`pipeline.process.surface_fit`)."""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.config import setting

__all__ = ["SurfaceFitSettings"]


@dataclass(frozen=True, kw_only=True)
class SurfaceFitSettings:
    """Settings of the water-surface fit."""

    air_index: float | None = setting(
        1.000277, ge=1.0, le=1.01, doc="index of air for the air range (None: the atmosphere's)"
    )
    k_neighbours: int = setting(16, ge=3, le=256, doc="surface points per local plane fit")
    radius_m: float = setting(5.0, ge=0.1, le=1000.0, doc="neighbour search radius")
    min_neighbours: int = setting(6, ge=3, le=256, doc="fewer: use the global plane")
    robust_iterations: int = setting(2, ge=0, le=10, doc="outlier-rejection passes")
    outlier_sigma: float = setting(3.0, gt=0.0, doc="rejection threshold in robust sigmas")
    own_outlier_sigma: float = setting(
        5.0, gt=0.0, doc="a pulse's own surface point further off its fit: SURFACE_OUTLIER"
    )
    outlier_floor_m: float = setting(
        0.02, ge=0.0, doc="residuals below this are never rejected (exact data)"
    )
    land_margin_m: float = setting(
        1.0, gt=0.0, doc="higher above the water level: land candidate (see surface_land)"
    )
    land_sea_sigmas: float = setting(
        4.0,
        ge=0.0,
        doc="land stands this many measured sea-height sigmas above the level (Hs ~ 4 sigma)",
    )
    land_radius_m: float = setting(
        5.0, gt=0.0, le=1000.0, doc="neighbour radius of the land support and height"
    )
    land_neighbours: int = setting(32, ge=1, le=1024, doc="neighbours of the land support")
    land_support_fraction: float = setting(
        0.25, ge=0.0, le=1.0, doc="fewer land candidates among the neighbours: not land"
    )
    land_link_m: float = setting(
        2.0,
        gt=0.0,
        le=1000.0,
        doc="land candidates this close to land above the sea state are land too",
    )
    land_extent_sigmas: float = setting(
        400.0,
        gt=0.0,
        doc="a region of linked land candidates this wide, in sea sigmas, is land (a crest "
        "region spans ~ a wavelength ~ 150 sigma)",
    )
    below_margin_m: float = setting(1.0, gt=0.0, doc="lower below the water level: not surface")
    below_sea_sigmas: float = setting(
        4.0,
        ge=0.0,
        doc="a trough reaches this many measured sea-height sigmas below the level: the "
        "not-surface band starts at max(below_margin_m, this x sigma_sea)",
    )
    water_level_hint_m: float | None = setting(
        None, doc="known water level (local z) to start from instead of the histogram mode"
    )
    level_bin_m: float = setting(0.25, gt=0.0, doc="histogram bin of the water-level search")
    min_wet_pulses: int = setting(
        3,
        ge=0,
        doc="pulses showing light under their surface return (a bottom or in-column return "
        "level_min_depth_m below it, a measured water column, a clipped plateau into the "
        "column) needed to conclude there is water; fewer, no water_level_hint_m, and surface "
        "returns dry_level_margin_m above fallback_water_level_m: every return is land "
        "(pipeline.process.surface_evidence). 0: off",
    )
    dry_level_margin_m: float = setting(
        2.0,
        ge=0.0,
        le=1000.0,
        doc="surface returns with no light under them are land only if their median height "
        "is this far above fallback_water_level_m (lower: a calm sea's seabed echoes, the "
        "surface unseen); the expected level's own uncertainty (tide, geoid)",
    )
    sea_min_wet_pulses: int = setting(
        30,
        ge=0,
        doc="the global water plane and the sea's height sigma (the troughs' reach, the land "
        "test) are measured on the surface returns with a bottom level_min_depth_m under them "
        "when at least this many (water for certain: a calm sea seen off nadir from high up "
        "returns only the seabed on many pulses, whose lone echoes otherwise pulled the plane "
        "down and read as troughs; suite tuning seed 7201); fewer: on every surface return",
    )
    level_min_depth_m: float = setting(
        1.0,
        ge=0.0,
        doc="water-level search: surface points with a bottom this far below (air range) first",
    )
    slope_prior_m: float = setting(
        0.05, ge=1e-3, le=100.0, doc="ridge towards the global slope, as an equivalent spread"
    )
    global_tilt_prior_rad: float = setting(
        1e-4,
        gt=0.0,
        le=1.0,
        doc="one-sigma prior on the global water plane's tilt: the mean sea surface is level to "
        "the deflection of the vertical (~1e-4 rad, 20 arcsec); a nearly collinear track "
        "(profiler) cannot tilt it with the waves",
    )
    min_spread_m: float = setting(
        0.25, ge=0.0, le=1000.0, doc="smaller neighbour spread across: flag ill-conditioned"
    )
    fallback_water_level_m: float = setting(
        0.0,
        doc="the water level processing expects (local z; the local frame's zero is the mean "
        "water level): used when there are fewer than 3 surface returns, and by the all-land "
        "rule (dry_level_margin_m)",
    )
    chunk_size: int = setting(131072, ge=1, doc="pulses per batched local fit")
    time_window_s: float | None = setting(
        1.0,
        gt=0.0,
        le=1e6,
        doc="neighbours within this time of the pulse (recorded emission times; None: any)",
    )

    kriging_neighbours: int = setting(
        12,
        ge=0,
        le=64,
        doc="surface echoes nearest a sounding in space-time that krige the sea above it at its "
        "pulse's time (pipeline.process.sea_kriging; 0: read the local plane). Set on the "
        "5 m/s wave scene, seed 7 (tuning): 8-20 change the RMSE by < 0.007 m",
    )
    kriging_window_s: float = setting(
        0.3,
        gt=0.0,
        le=10.0,
        doc="those echoes at most this far in time from the sounding's pulse (and the pairs "
        "whose covariance is measured). Set on the 5 m/s wave scene, seed 7 (tuning): "
        "0.2-0.5 s change the RMSE by < 0.007 m",
    )

    def __post_init__(self) -> None:
        if self.min_neighbours > self.k_neighbours:
            raise ValueError(
                f"`min_neighbours` ({self.min_neighbours}) must be <= `k_neighbours` "
                f"({self.k_neighbours})"
            )
