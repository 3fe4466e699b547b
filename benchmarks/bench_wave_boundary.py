"""A wave-field slab boundary: the surface and its rate together against the two calls apart.

Run: ``python benchmarks/bench_wave_boundary.py`` (a 4096-node tile, ~1 GB; asserts the pair
gives the same bits). Results: ``RESULTS_e2e.md``, section "Session 17".
"""

import time

import numpy as np

from terrain.water import WaveField


def main() -> None:
    """Time both ways at three instants on a 4096 x 4096 wind sea (6 m/s, 0.1 m nodes)."""
    f = WaveField(6.0, extent=(0.0, 409.6, 0.0, 409.6), spacing_m=0.1, rng=np.random.default_rng(3))
    print(f.shape)
    for t in (0.0, 0.37, 12.5):
        a, r = f.at_time(t), f.rate_at_time(t)
        t0 = time.perf_counter()
        b, q = f.surface_and_rate(t)
        t1 = time.perf_counter()
        assert np.array_equal(a.z_m, b.z_m) and np.array_equal(r.z_m, q.z_m)
        t2 = time.perf_counter()
        f.at_time(t)
        f.rate_at_time(t)
        t3 = time.perf_counter()
        print(f"{t} bit-identical; pair {t1 - t0:.2f} s vs separate {t3 - t2:.2f} s")


if __name__ == "__main__":
    main()
