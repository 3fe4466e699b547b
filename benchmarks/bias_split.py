"""Where a run's depth bias sits: the water surface over the sounding, or the seabed's height.

A sounding's depth is the sea's height above it, read on the pulse's fitted plane, less the
seabed point's height: ``depth = s - z``. Its error is ``e_d = e_s - e_z``, where ``e_s`` is the
sea read over the sounding against the true sea there at the pulse's time and ``e_z`` the
seabed point's height against the true seabed. Both carry the pulse's vertical navigation error
(the simulator's injected GNSS error, which the depth cancels) and are read against the
truth where they would lie without its horizontal part; both removed here, from the same
keyed streams the simulator drew it from (:func:`pipeline.simulate.noise.navigation_errors`),
so what is left is what processing read of the surface and of the seabed. As a check the
land points (class 2), where a scene has them, are split the same way: their height error
less the navigation's is the land detection's own, ~0.

Evaluation-side: it reads the truth (the scene's seabed and sea, the injected noise), never
processing's inputs. Usage (a finished run of a scene file)::

    PYTHONPATH=. python benchmarks/bias_split.py SCENE.toml RUN_DIR [SCENE.toml RUN_DIR ...]

prints per run: the depth bias, the surface's and the seabed's share, by depth band.
"""

from __future__ import annotations

import sys
from pathlib import Path

import laspy
import numpy as np

from pipeline.run_survey import survey_extent_m
from pipeline.scene import load_scene
from pipeline.simulate import survey
from pipeline.simulate.noise import navigation_errors
from pipeline.simulate.world import build_truth, wave_surface

#: Depth bands of the table (m).
BANDS_M = ((1.0, 3.0), (3.0, 6.0), (6.0, 10.0), (10.0, 15.0), (15.0, 40.0))


def _sea_m(water, x, y, t):
    """The true sea's height at local ``(x, y)`` at times ``t`` (a still one: no time)."""
    if not hasattr(water, "evolving"):
        return np.asarray(water.height_m(x, y), dtype=np.float64)
    out = np.empty(x.size)
    order = np.argsort(t, kind="stable")  # a moving sea meets its time slabs in order
    for a in range(0, x.size, 4096):
        b = order[a : a + 4096]
        out[b] = water.height_m(x[b], y[b], t[b])
    return out


def split(scene_path: str | Path, run_dir: str | Path) -> dict:
    """The run's class-40 depth errors split into surface and seabed parts (m).

    Returns
    -------
    dict
        ``depth``, ``surface``, ``seabed``, ``navigation`` (the mean vertical navigation
        error removed), ``land`` (class-2 height error less the navigation's, NaN without
        land), ``n``, and ``bands``: ``[(lo, hi, n, depth, surface, seabed), ...]``. Means,
        over soundings at least 1 m deep; ``surface`` positive: read high, ``seabed``
        positive: read high (a high seabed makes the depth shallow).
    """
    scene = load_scene(scene_path)
    lines = survey.plan_lines(scene.flight, scene.scanner)
    extent = survey_extent_m(scene, lines)
    water = wave_surface(scene) if scene.water_surface.kind == "waves" else None
    truth = build_truth(scene, extent, water=water)
    las = laspy.read(Path(run_dir) / "points.laz")
    fr = scene.frame
    x = np.asarray(las.x) - fr.origin_easting_m
    y = np.asarray(las.y) - fr.origin_northing_m
    z = np.asarray(las.z, dtype=np.float64)
    t = np.asarray(las.gps_time, dtype=np.float64)
    pid = np.asarray(las.pulse_id, dtype=np.int64)
    cls = np.asarray(las.classification)
    nav = navigation_errors(pid, t, scene.navigation, scene.scene.seed)[0]
    nav_up = nav[:, 2]
    # the truth where the point would lie without the navigation's error (it moves every
    # point of a pulse alike: over a slope its horizontal part would read as a height error)
    x, y = x - nav[:, 0], y - nav[:, 1]
    sea = cls == 40
    xs, ys, ts = x[sea], y[sea], t[sea]
    e_z = z[sea] - np.asarray(truth.seabed.height_m(xs, ys)) - nav_up[sea]
    e_s = np.asarray(las.depth_m)[sea] + z[sea] - _sea_m(truth.water, xs, ys, ts) - nav_up[sea]
    true_d = _sea_m(truth.water, xs, ys, ts) - np.asarray(truth.seabed.height_m(xs, ys))
    keep = true_d >= 1.0
    land = cls == 2
    e_land = z[land] - np.asarray(truth.seabed.height_m(x[land], y[land])) - nav_up[land]
    bands = []
    for lo, hi in BANDS_M:
        m = keep & (true_d >= lo) & (true_d < hi)
        if np.count_nonzero(m) >= 30:
            bands.append(
                (lo, hi, int(m.sum()), (e_s - e_z)[m].mean(), e_s[m].mean(), e_z[m].mean())
            )
    return {
        "n": int(keep.sum()),
        "depth": float((e_s - e_z)[keep].mean()),
        "surface": float(e_s[keep].mean()),
        "seabed": float(e_z[keep].mean()),
        "navigation": float(nav_up[sea][keep].mean()),
        "land": float(e_land.mean()) if e_land.size else float("nan"),
        "bands": bands,
    }


def main(argv: list[str]) -> int:
    if len(argv) < 2 or len(argv) % 2:
        print("usage: bias_split.py SCENE.toml RUN_DIR [SCENE.toml RUN_DIR ...]", file=sys.stderr)
        return 2
    print("| run | n | depth bias | surface read | seabed read | navigation (removed) | land |")
    print("|---|---|---|---|---|---|---|")
    rows = []
    for scene_path, run_dir in zip(argv[::2], argv[1::2], strict=True):
        r = split(scene_path, run_dir)
        rows.append((Path(run_dir).name, r))
        print(
            f"| {Path(run_dir).name} | {r['n']} | {r['depth']:+.4f} | {r['surface']:+.4f} | "
            f"{r['seabed']:+.4f} | {r['navigation']:+.4f} | {r['land']:+.4f} |"
        )
    print("\nBy depth band (depth bias / surface / seabed, m):")
    for name, r in rows:
        cells = "; ".join(
            f"{lo:g}-{hi:g} m (n {n}): {d:+.4f} / {s:+.4f} / {b:+.4f}"
            for lo, hi, n, d, s, b in r["bands"]
        )
        print(f"  {name}: {cells}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
