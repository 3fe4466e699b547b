"""How much true relief the TPU's pair scatter reads as timing noise, per full-waveform scene.

Usage: ``python benchmarks/tpu_pair_relief.py SUITE_OUT [--half tuning|heldout]`` on a
``bathy suite`` folder. Evaluation side only (it reads the truth in ``evaluation_points.npz``).

The TPU raises each sounding's timing sigma to the scatter of successive soundings' depth
differences about the local slope, less a rise ``a h²`` measured over the survey
(:func:`pipeline.uncertainty.tpu_neighbours.pair_scatter`). Per scene, over successive class-40
soundings within 2 m in the floors' window (true depth 1 m to 0.8 D_ext), this prints the
median pair separation ``h`` and three root-mean halves of squared differences about a plane
fitted to the true depths: of the measured depths, of the true depths (relief and sea height:
real, no error) and of the errors (what the timing terms should hold), beside the rms of the
TPU's timing terms (own and excess, surface and bottom) and of every per-sounding term. Where
the true relief at ``h`` is large against the errors and ``a h²`` does not remove it, the
timing terms exceed the errors.
"""

from __future__ import annotations

import numpy as np

from benchmarks.suite_scenes import suite_scenes
from pipeline.suite.chance_tpu import SHARED_TERMS

_TIMING = ("timing_surface", "timing_bottom", "timing_surface_excess", "timing_bottom_excess")


def _rms_half(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(v**2) / 2.0)) if v.size else float("nan")


def main() -> None:
    print(
        "| seed | scanner | surface | wind m/s | rough m | pairs | h m | measured | true relief"
        " | errors | TPU timing | TPU per-sounding |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for d, z, m in suite_scenes(__doc__, receiver="full_waveform"):
        s = d["seed"]
        e, t = z["tpu_error_m"], z["tpu_true_depth_m"]
        xy = np.column_stack([z["tpu_x_m"], z["tpu_y_m"]])
        i, j = m[:-1], m[1:]
        h = np.linalg.norm(xy[i] - xy[j], axis=1)
        ok = (j - i == 1) & (h < 2.0)  # successive soundings (the TPU's pairs), within 2 m
        i, j = i[ok], j[ok]
        if i.size < 50:
            continue
        plane = np.linalg.lstsq(np.column_stack([xy[m], np.ones(m.size)]), t[m], rcond=None)[0]
        step = (xy[i] - xy[j]) @ plane[:2]
        true_d = t[i] - t[j] - step
        names = [k[len("tpu_term_") :] for k in z.files if k.startswith("tpu_term_")]
        timing = sum(z[f"tpu_term_{k}"][i] ** 2 for k in names if k in _TIMING)
        own = sum(z[f"tpu_term_{k}"][i] ** 2 for k in names if k not in SHARED_TERMS)
        print(
            f"| {s} | {d['scanner']} | {d['surface']} | {d['wind_m_s']:.1f} |"
            f" {d['roughness_rms_m']:.2f} | {i.size} | {np.median(h[ok]):.2f} |"
            f" {_rms_half(true_d + e[i] - e[j]):.3f} | {_rms_half(true_d):.3f} |"
            f" {_rms_half(e[i] - e[j]):.3f} | {np.sqrt(np.mean(timing)):.3f} |"
            f" {np.sqrt(np.mean(own)):.3f} |"
        )


if __name__ == "__main__":
    main()
