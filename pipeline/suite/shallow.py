"""The shoal subset: where, per receiver, calm and 5 m/s water stop biasing the depth.

The issue asks for the shallowest depth with ``|bias| <= 0.10 m``, per receiver, in calm water
and at 5 m/s. The random suite seldom draws that: a shoal of a few metres, under one receiver,
at one of two winds. This subset forces it and leaves every other condition to the seed's own
draw (:func:`pipeline.suite.generate.draw`): water clarity, altitude, scanner (full waveform),
pulse rate, seabed reflectance, line length, the survey's wind log.

=================  ==============================================================================
receivers          full waveform (its seed's scanner) and photon counting (nadir profiler)
water              calm: flat, wind 1 m/s; 5 m/s: a wind sea (``waves``) raised by 5 m/s
seabed             one smooth plane from :data:`SHORE_DEPTH_M` (above the water: a shoreline)
                   to :data:`DEEP_DEPTH_M` across the scan: along the line under a profiler, across
                   the swath under a scanner (:func:`shallow_force`)
features           none (the random suite measures the IHO cubes' detection)
halves             :data:`SEEDS_PER_HALF` tuning and as many held-out seeds per receiver and
                   water, by the suite's own split (:func:`pipeline.suite.generate.half`)
=================  ==============================================================================

Seeds start at :data:`FIRST_SEED` and are taken in order, each combination its own, so the
subset is fixed once. ``bathy suite --subset shallow`` runs it; its report's table "Shallowest
depth with |bias| <= 0.10 m" is the figure (:func:`pipeline.suite.strata.shallowest_unbiased_m`).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from pipeline.suite.generate import Draw, draw, half_swath_m, suite_seeds

__all__ = [
    "FIRST_SEED",
    "SEEDS_PER_HALF",
    "SHORE_DEPTH_M",
    "DEEP_DEPTH_M",
    "WATERS",
    "RECEIVERS",
    "shallow_force",
    "shallow_seeds",
    "shallow_draws",
]

#: First seed looked at (clear of the random suite's 0-2000 and the CI subset's 9001-9008)
FIRST_SEED = 7000
#: Tuning seeds, and as many held-out seeds, per receiver and water
SEEDS_PER_HALF = 2
#: The plane's depth at the scan's two ends (m): a few decimetres of beach, then the shoal
SHORE_DEPTH_M = -0.3
DEEP_DEPTH_M = 4.9
#: (name, surface, wind m/s) of the two waters the issue names
WATERS: tuple[tuple[str, str, float], ...] = (("calm", "flat", 1.0), ("5 m/s", "waves", 5.0))
RECEIVERS = ("full_waveform", "photon_counting")


def shallow_force(d: Draw) -> dict[str, Any]:
    """The seabed that puts :data:`SHORE_DEPTH_M`-:data:`DEEP_DEPTH_M` under ``d``'s scan.

    A profiler's beam walks the line (``0 <= y <= line_length_m``): the plane deepens along it
    (aspect 0). A scanner's footprints reach ``x = +-altitude tan(20 deg)`` on every line
    position: the plane deepens across it (aspect 90), so each depth is sounded the whole line
    long. The depth at the scan's centre is the two ends' mean.
    """
    span = DEEP_DEPTH_M - SHORE_DEPTH_M
    if d.scanner == "profiler":
        reach, aspect = 0.5 * d.line_length_m, 0.0
    else:
        reach, aspect = half_swath_m(d.scanner, d.altitude_m), 90.0
    return {
        "depth_centre_m": 0.5 * (SHORE_DEPTH_M + DEEP_DEPTH_M),
        "slope_deg": math.degrees(math.atan(0.5 * span / reach)),
        "aspect_deg": aspect,
        "roughness_rms_m": 0.0,
    }


def shallow_seeds() -> list[tuple[int, str, tuple[str, str, float]]]:
    """``(seed, receiver, water)`` of the subset, in seed order (see the module docstring)."""
    out, seed = [], FIRST_SEED
    for receiver in RECEIVERS:
        for water in WATERS:
            seeds = suite_seeds(2 * SEEDS_PER_HALF, "both", seed)
            out += [(s, receiver, water) for s in seeds]
            seed = seeds[-1] + 1
    return out


def shallow_draws() -> list[Draw]:
    """The subset's scenes (``suite`` size), each with :func:`shallow_force`'s seabed."""
    draws = []
    for seed, receiver, (_, surface, wind) in shallow_seeds():
        force: dict[str, Any] = {"receiver": receiver, "surface": surface, "wind_m_s": wind}
        first = draw(seed, "suite", force)  # the scanner, line and altitude the seabed needs
        # no IHO cubes: their walls would put horizontal errors into the shoal's depth bands
        # (the random suite measures their detection)
        d = draw(seed, "suite", {**force, **shallow_force(first)})
        draws.append(dataclasses.replace(d, cubes=()))
    return draws
