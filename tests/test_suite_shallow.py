"""The shoal subset (``bathy suite --subset shallow``): what it promises, read off the scene files.

The seabed's depth at the scan's ends is read from the written TOML through the terrain's own
plane (the truth the simulator builds), not from the generator's arithmetic.
"""

from __future__ import annotations

import math
import tomllib
from collections import Counter

import numpy as np

import terrain
from pipeline.scene import parse_scene
from pipeline.suite.generate import CI_SCENES, half
from pipeline.suite.scene_file import scene_toml
from pipeline.suite.shallow import (
    DEEP_DEPTH_M,
    RECEIVERS,
    SEEDS_PER_HALF,
    SHORE_DEPTH_M,
    WATERS,
    shallow_draws,
    shallow_seeds,
)


def test_every_receiver_and_water_has_its_seeds_in_both_halves():
    seeds = shallow_seeds()
    counts = Counter((rec, water[0], half(seed)) for seed, rec, water in seeds)
    for rec in RECEIVERS:
        for name, _, _ in WATERS:
            for h in ("tuning", "heldout"):
                assert counts[(rec, name, h)] == SEEDS_PER_HALF, (rec, name, h)
    numbers = [s for s, _, _ in seeds]
    assert len(set(numbers)) == len(numbers)  # a seed is one scene
    assert not set(numbers) & {s for s, _ in CI_SCENES}
    assert min(numbers) > 2000  # clear of the random suite's seeds


def _depth_m(scene, x_m, y_m):
    sb = scene.seabed
    plane = terrain.plane_seabed(
        sb.depth_m - scene.water_surface.level_m,
        slope_rad=math.radians(sb.slope_deg),
        aspect_rad=math.radians(sb.aspect_deg),
    )
    return scene.water_surface.level_m - float(plane.height_m(x_m, y_m))


def test_the_scan_runs_from_the_shore_to_the_deep_end_in_each_scene():
    for d in shallow_draws():
        scene = parse_scene(tomllib.loads(scene_toml(d)), f"seed {d.seed}")
        assert scene.detector.mode == d.receiver
        rec, water = next((r, w) for s, r, w in shallow_seeds() if s == d.seed)
        assert (d.receiver, scene.water_surface.kind, d.wind_m_s) == (rec, water[1], water[2])
        assert scene.seabed.roughness_rms_m == 0.0 and not scene.seabed.features
        line = scene.flight.area_m[3]
        if d.scanner == "profiler":  # the beam walks the line: y = 0 .. line
            ends = [_depth_m(scene, 0.0, 0.0), _depth_m(scene, 0.0, line)]
        else:  # the swath's edges, halfway along the line
            reach = scene.flight.altitude_m * math.tan(math.radians(20.0))
            ends = [_depth_m(scene, -reach, 0.5 * line), _depth_m(scene, reach, 0.5 * line)]
        assert math.isclose(min(ends), SHORE_DEPTH_M, abs_tol=2e-3), (d.seed, ends)
        assert math.isclose(max(ends), DEEP_DEPTH_M, abs_tol=2e-3), (d.seed, ends)


def test_cube_subset_puts_a_dozen_separate_cubes_under_each_scan():
    from pipeline.suite.cubes import COPIES, MIN_SEPARATION_M, SEEDS_PER_HALF, SIZES_M, cube_draws

    draws = cube_draws()
    assert Counter(d.half for d in draws) == {"tuning": SEEDS_PER_HALF, "heldout": SEEDS_PER_HALF}
    for d in draws:
        scene = parse_scene(tomllib.loads(scene_toml(d)), f"seed {d.seed}")
        cubes = scene.seabed.features
        assert sorted(f.size_m for f in cubes) == sorted(SIZES_M * COPIES)
        assert scene.seabed.mesh_resolution_m <= 0.5  # two cells under the smallest cube
        xy = np.array([(f.x_m, f.y_m) for f in cubes])
        gaps = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
        assert gaps[~np.eye(len(xy), dtype=bool)].min() >= MIN_SEPARATION_M - 0.02
        line = scene.flight.area_m[3]
        reach = scene.flight.altitude_m * math.tan(math.radians(20.0))
        for x, y in xy:
            if d.scanner == "profiler":
                assert x == 0.0 and 0.0 <= y <= line
            elif d.scanner == "oscillating":
                assert abs(x) <= reach and 0.0 <= y <= line
            else:  # on the trailing arc of the circle of an aircraft inside the line
                y_aircraft = y + math.sqrt(max(reach**2 - x**2, 0.0))
                assert abs(x) <= reach and 0.0 <= y_aircraft <= line, (d.seed, x, y)
            depth = _depth_m(scene, x, y)  # the cube's base, on the true plane
            assert 1.0 <= depth <= 0.5 * 4.5 / scene.water.extinction_per_m, (d.seed, depth)
