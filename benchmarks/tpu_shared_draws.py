"""Whether the TPU's shared terms are as large as the errors scenes share, scene by scene.

Usage: ``python benchmarks/tpu_shared_draws.py SUITE_OUT [--half tuning|heldout]`` on a
``bathy suite`` folder. Evaluation side only (it reads the truth in ``evaluation_points.npz``).

The terms a survey shares (navigation, attitude, heading, forward scattering, temperature,
salinity: :data:`pipeline.suite.chance_tpu.SHARED_TERMS`) are drawn once per scene, so each
scene's coverage is one draw of them and says little alone. Over many scenes, the mean error
of each scene's soundings (true depth 1 m to 0.8 D_ext) divided by the root-mean-square of its
shared terms, ``z``, should scatter with a standard deviation of about 1 (a little more: the
soundings' own errors do not average out entirely): much less and the shared terms are too
wide, much more and too narrow. Prints each scene's ``z`` with its three largest shared terms,
then the mean and standard deviation of ``z``.
"""

from __future__ import annotations

import numpy as np

from benchmarks.suite_scenes import suite_scenes
from pipeline.suite.chance_tpu import SHARED_TERMS


def main() -> None:
    print("| seed | surface | wind m/s | c 1/m | points | mean error m | shared m | z | largest |")
    print("|---|---|---|---|---|---|---|---|---|")
    zs = []
    for d, z, m in suite_scenes(__doc__):
        s, e = d["seed"], z["tpu_error_m"]
        if m.size < 50:
            continue
        terms = {
            k[len("tpu_term_") :]: float(np.sqrt(np.mean(z[k][m] ** 2)))
            for k in z.files
            if k.startswith("tpu_term_") and k[len("tpu_term_") :] in SHARED_TERMS
        }
        shared = float(np.sqrt(sum(v**2 for v in terms.values())))
        zs.append(float(e[m].mean()) / shared)
        top = sorted(terms.items(), key=lambda kv: -kv[1])[:3]
        print(
            f"| {s} | {d['surface']} | {d['wind_m_s']:.1f} | {d['attenuation_per_m']:.2f} |"
            f" {m.size} | {e[m].mean():+.4f} | {shared:.4f} | {zs[-1]:+.2f} | "
            + ", ".join(f"{k} {v:.4f}" for k, v in top)
            + " |"
        )
    if zs:
        a = np.asarray(zs)
        print(f"\n{a.size} scenes: z mean {a.mean():+.2f}, standard deviation {a.std(ddof=1):.2f}")


if __name__ == "__main__":
    main()
