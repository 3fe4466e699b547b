"""Surface, seabed and depth errors of a photon survey's windows, and the facet path's excess.

Usage::

    python benchmarks/wave_refraction/facet_bias.py OUT.npz SHOTS_PER_WINDOW [WIND_M_S]

``OUT.npz`` from ``facet_hook.py``. Errors per detection window (its shots' mean): the measured
surface against the true sea at the surface point, the seabed point against the true seabed,
both less the navigation's vertical error (measured origin less the flown altitude: common to
both, it leaves the depth alone); the depth as processing reads it (below the pulse's plane at
the sounding) against the true depth below the sea there.

With a wind: the second-order excess of the in-water path through wave facets the planes do
not follow, ``d (1 - 1/n_w)^2 mss / 2`` (a nadir beam through a facet of slope ``beta`` turns by
``beta (1 - 1/n_w)``; the range read along the vertical is long by ``d delta^2 / 2``), with the
Cox-Munk mean-square slope of that wind (what the simulated sea is calibrated to) and the mean
true depth of the windows: the prediction the seabed error is compared with.
"""

from __future__ import annotations

import sys

import numpy as np

N_WATER = 1.3415  # phase index of sea water at 532 nm (the presets')


def main(path, shots, wind=None):
    d = np.load(path)
    rows = d["bottom_rows"]
    nav = d["origin_z_m"] - float(d["altitude_m"])
    surf = d["surface_z_m"] - d["sea_at_surface_m"] - nav
    seabed = d["bottom_xyz_m"][:, 2] - d["seabed_true_m"] - nav[rows]
    true_depth = d["sea_at_bottom_m"] - d["seabed_true_m"]
    depth = (d["plane_at_bottom_m"] - d["bottom_xyz_m"][:, 2]) - true_depth
    _, inv = np.unique(d["pulse_id"][rows] // shots, return_inverse=True)
    cnt = np.bincount(inv)

    def per_window(v):
        return np.bincount(inv, weights=v) / cnt

    ok = d["has_surface"]
    print(f"windows with a seabed point: {cnt.size}; mean true depth {true_depth.mean():.2f} m")
    print(f"navigation vertical error: mean {nav.mean():+.4f} m")
    print(f"surface error (all water pulses, navigation removed): {surf[ok].mean():+.4f} m")
    for name, v in (("surface", surf[rows]), ("seabed", seabed), ("depth", depth)):
        w = per_window(v)
        # the median too: a full-waveform survey's bottom returns include false bottoms
        print(
            f"{name:8s} error per window: mean {w.mean():+.4f} m, sd {w.std():.4f} m,"
            f" median {np.median(w):+.4f} m"
        )
    if wind is not None:
        from pipeline.lidar_equation import cox_munk_mean_square_slope

        mss = float(cox_munk_mean_square_slope(wind))
        excess = true_depth.mean() * (1.0 - 1.0 / N_WATER) ** 2 * mss / 2.0
        print(f"facet path excess at {wind} m/s (Cox-Munk mss {mss:.4f}): {excess:.4f} m deep")


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]), float(sys.argv[3]) if len(sys.argv) > 3 else None)
