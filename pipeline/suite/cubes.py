"""The cube subset: IHO S-44 cubes by the dozen, at the sounding densities surveys fly.

The issue's feature floor (2 m cubes detected >= 95 % where the soundings reach 1 per m², and
the density at which 1 m cubes are detected) needs tens of cubes per size at known densities.
The random suite puts three cubes in a scene, often past extinction or between a scan's arcs, so
few are dense (a handful per half). This subset forces what a feature search is flown over, and
leaves the rest to the seed's own draw (:func:`pipeline.suite.generate.draw`): receiver, scanner,
pulse rate, line, wind and waves, seabed reflectance, the survey's wind log.

=================  ==============================================================================
seabed             a smooth plane 5 m deep at the line's centre, deepening along the line at
                   the seed's slope scaled to 0-2 deg (:data:`MAX_SLOPE_DEG`), meshed at
                   :data:`MESH_M` so a 1 m cube keeps its top (the random suite meshes 1 m
                   under a scanner)
water              the seed's attenuation mapped log-uniformly onto 0.05 to
                   :data:`MAX_ATTENUATION_PER_M` (cubes well above the extinction depth)
altitude           the seed's 200-800 m mapped to 200-400 m (a feature search flies low; the
                   density still spans <0.25 to >4 soundings per m², measured, through the
                   pulse rate and the scan)
cubes              :data:`COPIES` of each of 0.5, 1 and 2 m, placed as the suite places its cubes
                   (:func:`pipeline.suite.generate._cube_xy`: under the scan, base 1.5 m to half
                   the planning extinction depth) from their own random stream, at least
                   :data:`MIN_SEPARATION_M` apart
halves             :data:`SEEDS_PER_HALF` tuning and as many held-out seeds (the suite's split)
=================  ==============================================================================

``bathy suite --subset cubes`` runs it; the report's "Cube detection by sounding density" table
is the figure (:func:`pipeline.suite.report.cube_density_table`).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from pipeline.suite.generate import (
    ALTITUDE_RANGE_M,
    ATTENUATION_RANGE_PER_M,
    Draw,
    _cube_xy,
    cube_base_range_m,
    draw,
    half_swath_m,
    suite_seeds,
)

__all__ = [
    "FIRST_SEED",
    "SEEDS_PER_HALF",
    "COPIES",
    "SIZES_M",
    "MIN_SEPARATION_M",
    "MESH_M",
    "MAX_SLOPE_DEG",
    "MAX_ATTENUATION_PER_M",
    "cube_seeds",
    "cube_draws",
]

#: First seed looked at (clear of the random suite, the shoal subset and the CI subset)
FIRST_SEED = 7100
SEEDS_PER_HALF = 8
COPIES = 4
SIZES_M = (0.5, 1.0, 2.0)
#: Between two cubes' centres (m): the largest cube's footprint grown by the density margin
MIN_SEPARATION_M = 6.0
MESH_M = 0.5
MAX_SLOPE_DEG = 2.0
MAX_ATTENUATION_PER_M = 0.3
_DEPTH_CENTRE_M = 5.0
_ALTITUDE_M = (200.0, 400.0)


def cube_seeds() -> list[int]:
    """The subset's seeds: the first :data:`SEEDS_PER_HALF` of each half from FIRST_SEED."""
    return suite_seeds(2 * SEEDS_PER_HALF, "both", FIRST_SEED)


def _cubes(d: Draw, ext_guess: float) -> tuple[tuple[float, float, float], ...]:
    """:data:`COPIES` cubes per size under ``d``'s scan, from the seed's own cube stream."""
    rng = np.random.default_rng([d.seed, 4242])
    half_swath = half_swath_m(d.scanner, d.altitude_m)
    base_lo, base_hi = cube_base_range_m(ext_guess)
    grad = math.tan(math.radians(d.slope_deg))
    placed: list[tuple[float, float, float]] = []
    for size_m in SIZES_M * COPIES:
        for _ in range(1000):  # rejection: a free place is found in a few tries
            ua, ub = rng.uniform(size=2)
            x, y = _cube_xy(
                ua,
                ub,
                half_swath,
                d.line_length_m,
                d.scanner == "palmer",
                d.depth_centre_m,
                d.slope_deg,
                d.aspect_deg,
                ext_guess,
            )
            # the base on the plane (aspect 0: deepening north from the line's centre)
            base_m = d.depth_centre_m + grad * (y - 0.5 * d.line_length_m)
            if not base_lo <= base_m <= base_hi:
                continue
            if all(math.hypot(x - px, y - py) >= MIN_SEPARATION_M for px, py, _ in placed):
                placed.append((round(float(x), 2), round(float(y), 2), size_m))
                break
        else:
            raise RuntimeError(f"seed {d.seed}: no free place for a {size_m} m cube")
    return tuple(placed)


def cube_draws() -> list[Draw]:
    """The subset's scenes (``suite`` size; see the module docstring)."""
    draws = []
    for seed in cube_seeds():
        own = draw(seed, "suite")
        a0, a1 = ALTITUDE_RANGE_M
        u_alt = (own.altitude_m - a0) / (a1 - a0)  # the seed's own altitude draw, in [0, 1)
        # the seed's log-uniform draw mapped log-uniformly onto its lower bound to MAX
        lo, hi = (math.log(v) for v in ATTENUATION_RANGE_PER_M)
        u_c = (math.log(own.attenuation_per_m) - lo) / (hi - lo)
        c = math.exp(lo + u_c * (math.log(MAX_ATTENUATION_PER_M) - lo))
        force = {
            "depth_centre_m": _DEPTH_CENTRE_M,
            "slope_deg": own.slope_deg * MAX_SLOPE_DEG / 20.0,
            # along the line: a slope across the swath would stack the cubes at its edges
            # (_cube_xy seeks their base depth across it)
            "aspect_deg": 0.0,
            "roughness_rms_m": 0.0,
            "attenuation_per_m": c,
            "altitude_m": _ALTITUDE_M[0] + u_alt * (_ALTITUDE_M[1] - _ALTITUDE_M[0]),
        }
        d = draw(seed, "suite", force)
        cubes = _cubes(d, min(4.5 / c, 60.0))
        draws.append(dataclasses.replace(d, cubes=cubes, mesh_m=MESH_M))
    return draws
