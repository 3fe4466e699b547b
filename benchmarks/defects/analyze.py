"""Figures of the defects issue from a run's outputs; every truth is an analytic plane written here.

Usage: python benchmarks/defects/analyze.py KIND OUT_DIR
KIND: steep150 | deep | slope15 | turbid (plane seabeds deepening eastward under flat water at
level 0), ramp (0.2 m + 1:50), waves10 (flat 10 m under a 10 m/s sea), nadir (photon ramp, 200
shots a window), tide (flat 8 m seabed: prints median z and depth).
"""

import json
import math
import sys

import numpy as np

from pipeline.outputs.las import read_points_laz

#: depth at x = 0 (m) and slope (deg) of each scene's plane, from its scene file
PLANES = {
    "steep150": (3.0, 11.31),
    "slope15": (3.0, 11.31),
    "turbid": (10.0, 11.31),
    "deep": (5.0, 8.2),
    "ramp": (0.2, 1.146),
}


def main(kind, out):
    p = read_points_laz(f"{out}/points.laz").points
    ev = json.load(open(f"{out}/evaluation.json"))
    c, x, z = p.classification, p.xyz_m[:, 0], p.xyz_m[:, 2]
    b = c == 40
    err = ev["error"]
    print(f"== {kind} {out}")
    print("  points", {k: round(err["points"][k], 4) for k in ("n", "bias_m", "rmse_m")})
    print("  grid", {k: round(err["grid"][k], 4) for k in ("n", "bias_m", "rmse_m")})
    print("  tpu_left_out", ev.get("tpu_left_out", {}).get("pulses"))
    if kind in PLANES:
        d0, slope = PLANES[kind]
        td = d0 + math.tan(math.radians(slope)) * x
        bad = b & (p.depth_m < 1.0) & (td > 5.0)
        print(f"  class-40 shallower than 1 m over water deeper than 5 m: {int(bad.sum())}")
        c45 = c == 45
        if c45.any() and b.any():
            print(
                f"  class 45: median depth {np.median(p.depth_m[c45]):.2f} m, above the true"
                f" seabed {np.mean(p.depth_m[c45] <= td[c45]):.1%}; class-40 depth p99"
                f" {np.percentile(p.depth_m[b], 99):.2f} m"
            )
        if kind == "ramp":
            for lo, hi in ((0.2, 0.5), (0.5, 1.5), (1.5, 3.0)):
                m = b & (td >= lo) & (td < hi)
                e = p.depth_m[m] - td[m]
                print(
                    f"  class-40 at {lo}-{hi} m: {int(m.sum())}, median error {np.median(e):+.4f} m"
                )
    if kind == "waves10":
        print(f"  class-2 points (all water): {int((c == 2).sum())}")
    if kind == "nadir":
        w, s = p.pulse_id // 200, c == 41
        ok = 0
        for i in np.unique(w):
            m = s & (w == i)
            ok += bool(m.any() and abs(np.median(z[m])) <= 0.25)
        print(f"  windows with the surface at the water level: {ok}/{np.unique(w).size}")
    if kind == "tide":
        zm, dm = np.median(z[b]), np.median(p.depth_m[b])
        print(f"  class-40 median z {zm:.3f} m, median depth {dm:.3f} m")


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
