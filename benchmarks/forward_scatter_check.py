"""Forward-scattering delay: single-event and traced tables against a photon Monte Carlo.

Run: PYTHONPATH=. python benchmarks/forward_scatter_check.py  (RESULTS_realism.md, sixth session)

The Monte Carlo is the one written in tests/simulate/test_forward_scatter.py (Henyey-Greenstein
g = 0.9, c = 0.15, omega_0 = 0.8, 200 000 photons per case, absorbed along their path). Printed
per depth L and field-of-view radius R: the two-way mean excess path (Monte Carlo +- its standard
error, both models), its variance, and the probability of no scattering on either leg.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests" / "simulate"))

from test_forward_scatter import _hg_phase, _one_way_mc  # noqa: E402

from pipeline.forward_scatter import ScatterTables, bottom_delay  # noqa: E402
from pipeline.forward_scatter_mc import TracedTables  # noqa: E402

CASES = ((5, 2), (10, 2), (20, 2), (20, 0.5), (20, 5), (3, 0.3), (30, 3))


def main() -> None:
    t0 = time.process_time()
    traced = TracedTables.from_phase(_hg_phase)
    print(f"traced tables: {time.process_time() - t0:.2f} CPU-s")
    single = ScatterTables.from_phase(_hg_phase)
    c, albedo = 0.15, 0.8
    b, a = albedo * c, (1 - albedo) * c
    for depth, radius in CASES:
        rng = np.random.default_rng(int(depth * 10 + radius))
        excess, w = _one_way_mc(200_000, depth, b, a, radius, rng)
        keep = w > 0
        excess, w = excess[keep], w[keep] / w[keep].sum()
        n_eff = 1.0 / np.sum(w**2)
        m1 = float(np.sum(w * excess))
        v1 = float(np.sum(w * (excess - m1) ** 2))
        se = math.sqrt(2 * v1 / n_eff)
        p0 = float(np.sum(w * (excess == 0))) ** 2
        old = bottom_delay(np.array([depth]), np.array([radius]), [b], [single])
        new = bottom_delay(np.array([depth]), np.array([radius]), [b], [traced], a)
        mo, mn = old.mean_m[0], new.mean_m[0]
        print(
            f"L {depth} R {radius}: MC {2 * m1:.4f} +- {se:.4f} | single {mo:.4f}"
            f" ({mo / (2 * m1) - 1:+.1%}) | traced {mn:.4f} ({mn / (2 * m1) - 1:+.1%},"
            f" {(mn - 2 * m1) / se:+.1f} se) | var MC {2 * v1:.5f} single {old.var_m2[0]:.5f}"
            f" traced {new.var_m2[0]:.5f} | P0 MC {p0:.4f} single {old.unscattered[0]:.4f}"
            f" traced {new.unscattered[0]:.4f}"
        )


if __name__ == "__main__":
    main()
