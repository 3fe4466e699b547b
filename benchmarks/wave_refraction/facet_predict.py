"""Measured seabed error against the facet path's predicted excess, per pulse (evaluation side).

Usage::

    python benchmarks/wave_refraction/facet_predict.py OUT.npz [SHOTS_PER_WINDOW [DECAY_PER_M]]

``OUT.npz`` from ``facet_hook.py`` (a run whose soundings do not yet carry the correction, or
do: the prediction is printed either way). The excess is
:func:`pipeline.process.facet_excess.expected_facet_shift_m` with the slope variance of
:func:`~pipeline.process.facet_excess.unresolved_slope_var` at the Cox-Munk mean-square slope of
the scene's wind; the seabed error is the point's height less the true seabed's, less the
navigation's vertical error (common to surface and seabed).
"""

from __future__ import annotations

import sys

import numpy as np

from pipeline.lidar_equation import cox_munk_mean_square_slope
from pipeline.process.facet_excess import (
    expected_depth_excess_m,
    track_directions,
    unresolved_slope_var,
)

N_WATER, N_AIR = 1.3415, 1.0003


def main(path, shots=1, decay=0.0):
    d = np.load(path)
    rows = d["bottom_rows"]
    nav = d["origin_z_m"] - float(d["altitude_m"])
    err = d["bottom_xyz_m"][:, 2] - d["seabed_true_m"] - nav[rows]
    mss = float(cox_munk_mean_square_slope(float(d["wind_m_s"])))
    track = track_directions(d["origin_xy_m"], d["line_id"])
    var = unresolved_slope_var(
        mss, d["normal"], d["normal_sigma_rad"], d["is_water"], d["surface_flags"], track
    )
    length = np.linalg.norm(d["bottom_xyz_m"] - d["entry_m"][rows], axis=1)
    excess = expected_depth_excess_m(
        d["direction"][rows],
        d["normal"][rows],
        length,
        N_AIR,
        N_WATER,
        var[rows],
        track[rows],
        decay,
    )
    water = d["is_water"]
    print(f"wind {float(d['wind_m_s']):.2f} m/s, Cox-Munk mss {mss:.4f}")
    print(
        "slope variance per axis (along, across) mean over water pulses:",
        np.round(var[water].mean(axis=0), 5),
        " (mss/2 =",
        round(mss / 2, 5),
        ")",
    )
    _, inv = np.unique(d["pulse_id"][rows] // shots, return_inverse=True)
    cnt = np.bincount(inv)

    def per(v):
        return np.bincount(inv, weights=v) / cnt

    e, s = per(err), per(excess)
    print(f"soundings {rows.size}, windows {cnt.size}, mean in-water path {length.mean():.2f} m")
    print(f"seabed z error: mean {e.mean():+.4f}, median {np.median(e):+.4f} m")
    print(f"predicted rise (mean of the excess): {s.mean():+.4f} m")
    print(f"after the correction: mean {np.mean(e + s):+.4f}, median {np.median(e + s):+.4f} m")


if __name__ == "__main__":
    main(
        sys.argv[1],
        int(sys.argv[2]) if len(sys.argv) > 2 else 1,
        float(sys.argv[3]) if len(sys.argv) > 3 else 0.0,
    )
