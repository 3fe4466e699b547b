"""The case table of ``bathy stress`` (:mod:`pipeline.stress`): each extreme case as data.

A case is a base scene (:data:`pipeline.stress_support.BASES`), the scene keys it overrides
and what it expects (:data:`pipeline.stress_support.CHECKS`). Known limits, measured on these
scenes, are written next to the case that shows them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

__all__ = ["StressCase", "CASES"]


@dataclass(frozen=True)
class StressCase:
    """One extreme case: a base scene, the keys it overrides, and what it expects.

    Attributes
    ----------
    name : str
        Short name (``bathy stress --only NAME``).
    why : str
        What the case exercises.
    overrides : tuple of (str, object)
        Dotted scene keys and their values, set on a copy of the base.
    expect : tuple of str
        Checks (:data:`CHECKS`), each ``"check"`` or ``"check:argument"``; a run case always
        also checks that it completes and that its outputs are finite.
    base : str
        ``"palmer"`` (full waveform) or ``"photon"`` (photon counting).
    exit_status : int
        0: run end to end with :func:`pipeline.run.run_scene`; 2: bad input, ``bathy run``
        must exit 2 with one line naming ``expect``'s key.
    fast : bool
        In the fast subset (``--fast``, the test suite).
    known_failure : str
        Non-empty: the case fails because of this known defect (reported, not PASS).
    """

    name: str
    why: str
    overrides: tuple[tuple[str, Any], ...] = ()
    expect: tuple[str, ...] = ()
    base: str = "palmer"
    exit_status: int = 0
    fast: bool = True
    known_failure: str = ""


# ---------------------------------------------------------------------------------------------
# the case table

_FLAT = (("seabed.slope_deg", 0.0), ("seabed.roughness_rms_m", 0.0))
#: Two equal Gaussian echoes show two peaks only more than 2 sigma apart; the base's system
#: response is the preset's 1.5 ns pulse and 1.0 ns detector response (FWHM in quadrature),
#: and depth = c dt / (2 n_group) at nadir (less off nadir): 0.168 m.
_RESOLVABLE_M = (
    (2.0 * math.hypot(1.5e-9, 1.0e-9) / (2.0 * math.sqrt(2.0 * math.log(2.0))))
    * 299_792_458.0
    / (2.0 * 1.3638)
)
#: 20 km up with the base's echo levels: energy x 50^2, the base's two-way air loss, and a
#: 100 m seabed mesh over the ~18.6 km extent (a 1 m one is meshed tile by tile as rays
#: reach it, each ray walking ~30 tiles from 20 km: slow, not refused)
_FAR = (
    ("flight.altitude_m", 20000.0),
    ("system.pulse_energy_j", 2.0e-5 * 50.0**2),
    ("atmosphere.extinction_per_m", 1.5e-4 / 50.0),
    ("seabed.mesh_resolution_m", 100.0),
)
_WIND_40 = (("water.wind_speed_m_s", 40.0), ("water_surface.kind", "waves"))
_TIR = (("scanner.off_nadir_deg", 58.0), *_WIND_40)
#: The fast variant of a 40 m/s sea: a 12 m line (400 pulses) over a sea frozen at t = 0.
#: The moving sea's cost is its synthesis per time slab (slabs of ~5 ms at 40 m/s), paid by the
#: tracer and again by the evaluation: ~130 s a case on the 40 m line, ~10 s CPU here.
_SMALL_SEA = (("flight.area_m", [0.0, 40.0, 0.0, 12.0]), ("water_surface.evolving", False))
#: Known limits (measured on these scenes).
CASES: tuple[StressCase, ...] = (
    StressCase(
        "baseline",
        "the base scene: water 0.5-18 m deep and land",
        expect=("class:40", "class:41", "class:2", "grid_cells:5"),
    ),
    StressCase(
        "penetration_edge",
        "the base scene in c = 0.25 /m water: the bottom fades out along the line, the pulses"
        " past it get class-45 limits (in the base's c = 0.15 /m every bottom is found since"
        " the lidar attenuation follows the field of view, issue 12)",
        overrides=(("water.extinction_per_m", 0.25),),
        expect=("class:40", "class:45", "class:2"),
    ),
    StressCase(
        "grazing",
        "oscillating scan at 59.9 deg with 30 deg roll: beams up to ~90 deg off nadir",
        overrides=(
            ("scanner.kind", "oscillating"),
            ("scanner.scan_half_angle_deg", 59.9),
            ("attitude.roll_amplitude_deg", 30.0),
            ("attitude.roll_period_s", 0.5),
        ),
        expect=("class:40", "subray_flag:miss"),
    ),
    StressCase(
        "tir",
        "58 deg Palmer over a 40 m/s wind sea, frozen, on a 12 m line: bottom echoes totally"
        " reflected on the way up",
        overrides=(*_TIR, *_SMALL_SEA),
        # 522 TIR sub-rays on seed 7: the return retraces the refracted ray, so it meets TIR
        # only where that ray crosses the wave mesh again (Snell at the facet normal: the sea's
        # motion during the 0.2 s line does not enter; tir_full keeps it)
        expect=("subray_flag:tir_return",),
    ),
    StressCase(
        "tir_full",
        "tir on the base's 40 m line over the moving sea (~130 s: evaluation per slab)",
        overrides=_TIR,
        # 3 TIR sub-rays on seed 7, none on seeds 8 and 9
        expect=("subray_flag:tir_return",),
        fast=False,
    ),
    StressCase(
        "clear_water",
        "water extinction 0: no attenuation, no column decay to measure",
        overrides=(("water.extinction_per_m", 0.0),),
        expect=("class:40", "rmse:0.1"),
    ),
    StressCase(
        "opaque_water",
        "water extinction 100 /m: no bottom; the column decays within the pulse, so no pulse"
        " measures a detection limit and none gets a class-45 point (README, class 45 depth)",
        overrides=(("water.extinction_per_m", 100.0),),
        expect=("no_class:40", "no_class:45"),
    ),
    StressCase(
        "zero_photons",
        "1e-30 J pulses, receiver efficiency 1e-30, no sun, no dark counts: noise only",
        overrides=(
            ("system.pulse_energy_j", 1e-30),
            ("system.receiver_efficiency", 1e-30),
            ("system.dark_count_rate_hz", 0.0),
            ("background.solar_irradiance_w_m2_nm", 0.0),
        ),
        # a per-sample 5-sigma threshold passes noise alone now and then (1.3e-4 of 120 000
        # synthetic noise-only pulses, 3 of 6670 here on seeds 7-11): those must come out as
        # noise, with no surface, bottom or land among them
        expect=("only_noise",),
    ),
    StressCase(
        "saturation",
        "1 J pulses: the digitiser reaches its top code in every pulse",
        overrides=(("system.pulse_energy_j", 1.0),),
        # every water pulse clips from the surface to the bottom into one plateau: only bounds
        # of the two times are in the data, so the survey flags it and abstains (no bottom
        # claimed more than 1 m off); the surface's early bounds set the water level and the
        # datum, which says it is a bound (was a known failure: the clipped land echoes taken
        # for the water level, datum +6.37 m, no class 2); the clipped land echoes are timed
        expect=(
            "detector_flag:SATURATED",
            "datum_source:clipped_bound",
            "datum_error:0.3",
            "max_error:1.0",
            "class:2",
        ),
    ),
    StressCase(
        "depth_0.05m",
        "a flat seabed 5 cm deep: surface and bottom echoes merge",
        overrides=(("seabed.depth_m", 0.05), *_FLAT),
        expect=(f"min_depth:40:{_RESOLVABLE_M:.3f}",),
    ),
    StressCase(
        "depth_100m",
        "a flat seabed 100 m deep, 1 us window: exp(-30) round trip, no bottom",
        overrides=(("seabed.depth_m", 100.0), ("detector.window_s", 1.0e-6), *_FLAT),
        expect=("no_class:40", "class:45", "max_depth:45:100.0"),
    ),
    StressCase(
        "altitude_1m",
        "flight altitude at its lower bound, 1 m, the base's pulses: the echoes clip",
        overrides=(("flight.altitude_m", 1.0),),
        # was a known failure (no SATURATED flag; surfaces timed at the plateau's end, grid
        # datum -4.7 m): every pulse is flagged and no clipped plateau times the surface
        expect=("detector_flag:SATURATED", "datum_error:0.2"),
    ),
    StressCase(
        "altitude_1m_dim",
        "1 m altitude, pulse energy x (1/400)^2: the base's echo levels at 1/400 of its range",
        overrides=(("flight.altitude_m", 1.0), ("system.pulse_energy_j", 2.0e-5 / 400.0**2)),
        expect=("class:40", "class:41", "datum_error:0.2"),
    ),
    StressCase(
        "altitude_20000m",
        "20 km altitude (the upper bound), flat 2 m seabed, the base's echo levels at 50 x its"
        " range (pulse energy x 50^2, air extinction / 50): the 7 km Palmer circle puts no"
        " pulse in the 40 m area",
        overrides=(*_FAR, *_FLAT),
        expect=("class:41", "class:40", "datum_error:0.2", "rmse:0.1"),
        fast=False,
    ),
    StressCase(
        "altitude_20000m_land",
        "the same over the base's 5.33 deg plane: land rising to ~680 m west of x = -21 m",
        overrides=(*_FAR, ("seabed.roughness_rms_m", 0.0)),
        expect=("class:2", "class:41", "datum_error:0.2"),
        fast=False,
    ),
    StressCase(
        "wind_40",
        "a 40 m/s wind sea (significant wave height ~34 m), frozen, under the base Palmer scan"
        " on a 12 m line",
        overrides=(*_WIND_40, *_SMALL_SEA),
        expect=("class:40",),
    ),
    StressCase(
        "wind_40_full",
        "wind_40 on the base's 40 m line over the moving sea (~130 s: evaluation per slab)",
        overrides=_WIND_40,
        expect=("class:40",),
        fast=False,
    ),
    StressCase(
        "coordinates_1e7",
        "frame origin at 1e7 m easting and northing",
        overrides=(("frame.origin_easting_m", 1.0e7), ("frame.origin_northing_m", 1.0e7)),
        expect=("class:40", "world_offset:1e7"),
    ),
    StressCase(
        "all_land",
        "the seabed 5 m above the water everywhere, no water level given",
        overrides=(("seabed.depth_m", -5.0), *_FLAT),
        # was a known failure (land taken for the water level: 1334 class 41, datum +4.95 m):
        # no light under any surface return, and the returns stand 5 m above the expected level
        expect=("no_class:40", "class:2", "no_class:41"),
    ),
    StressCase(
        "all_land_known_level",
        "the seabed 5 m above the water everywhere, the water level given (0 m)",
        overrides=(
            ("seabed.depth_m", -5.0),
            ("process.surface_fit.water_level_hint_m", 0.0),
            ("process.datum.water_level_m", 0.0),
            *_FLAT,
        ),
        expect=("no_class:40", "class:2", "no_class:41"),
    ),
    StressCase(
        "empty_area",
        "the smallest area, 1 mm x 1 mm: one pulse",
        overrides=(("flight.area_m", [0.0, 0.001, 0.0, 0.001]),),
    ),
    StressCase("photon", "the photon-counting base", base="photon", expect=("class:40",)),
    StressCase(
        "photon_seed12",
        "the photon-counting base drawn with seed 12",
        base="photon",
        overrides=(("scene.seed", 12),),
        # was a known failure (the highest histogram bin, the 2 m seabed, taken for the
        # surface): passes since the surface is the first significant return
        expect=("class:40", "datum_error:0.2"),
    ),
    StressCase(
        "photon_zero_photons",
        "photon counting, 1e-30 J pulses, no sun, no dark counts: no event at all",
        base="photon",
        overrides=(
            ("system.pulse_energy_j", 1e-30),
            ("system.dark_count_rate_hz", 0.0),
            ("background.solar_irradiance_w_m2_nm", 0.0),
        ),
        expect=("no_detections",),
    ),
    StressCase(
        "photon_opaque_water",
        "photon counting in water of extinction 100 /m over the 2 m seabed",
        base="photon",
        overrides=(("water.extinction_per_m", 100.0),),
        # was a known failure (class 45 at the end of the range gate, 77 m over a 2 m
        # seabed): the photon limit is where the histogram last shows the column
        expect=("no_class:40", "max_depth:45:2.0"),
    ),
    StressCase(
        "photon_saturation",
        "photon counting with 20 x the pulse energy: the receiver flags every shot saturated",
        base="photon",
        overrides=(("system.pulse_energy_j", 1e-6),),
        # was a known failure (no DetectorFlag.SATURATED from photon detections): a window
        # whose surface box has an event in ~every shot (dead-time pile-up) is flagged
        expect=("receiver_flag:saturated", "detector_flag:SATURATED"),
    ),
    StressCase(
        "posteriors",
        "the base scene with emcee depth posteriors on 8 points",
        overrides=(("process.posterior_min_pulses", 8),),
        expect=("posteriors:8",),
    ),
    StressCase(
        "photon_posteriors",
        "the photon-counting base with depth posteriors on its window histograms",
        base="photon",
        overrides=(("process.posterior_min_pulses", 4),),
        expect=("class:40", "posteriors:2"),
    ),
    StressCase(
        "bad_mesh_extent",
        "20 km altitude with a 1 um seabed mesh: the grid's axes over the 18.6 km extent alone"
        " would hold ~3e10 nodes (a 1 m mesh runs: the seabed is meshed in tiles)",
        overrides=(("flight.altitude_m", 20000.0), ("seabed.mesh_resolution_m", 1e-6)),
        expect=("seabed.mesh_resolution_m",),
        exit_status=2,
    ),
) + tuple(
    StressCase(name, why, overrides=((key, value),), expect=(key,), exit_status=2)
    for name, why, key, value in (
        ("bad_altitude_low", "flight altitude below its bound", "flight.altitude_m", 0.5),
        ("bad_altitude_high", "flight altitude above its bound", "flight.altitude_m", 20001.0),
        ("bad_wind", "wind above its bound", "water.wind_speed_m_s", 41.0),
        ("bad_extinction", "extinction above its bound", "water.extinction_per_m", 101.0),
        ("bad_pulse_energy", "zero pulse energy (bound > 0)", "system.pulse_energy_j", 0.0),
        ("bad_depth_nan", "a NaN seabed depth", "seabed.depth_m", math.nan),
    )
)
