"""CPU of one posterior depth scan (``posterior_start._scan_start``) by waveform length.

    PYTHONPATH=. python benchmarks/bench_scan_start.py

A waveform of the model (surface at 30 ns, bottom 8 m down, noise 2 counts) scanned 20 times
after one warm-up call; milliseconds per scan and the depth it starts at.
"""

from __future__ import annotations

import math
import time

import numpy as np

from pipeline.uncertainty import posterior_start
from pipeline.uncertainty.waveform_model import WaveformSystem, expected_waveform

if __name__ == "__main__":
    system = WaveformSystem(
        sample_interval_s=1e-9, pulse_fwhm_s=3e-9, offset_counts=100.0, electronic_noise_counts=2.0
    )
    rng = np.random.default_rng(0)
    theta = np.array(
        [8.0, 30.0, math.log(500.0), math.log(300.0), math.log(80.0), math.log(0.1), 5.0, 0, 0]
    )
    for m in (150, 400, 800):
        y = expected_waveform(theta, m, system, 0.95) + rng.normal(0.0, 2.0, m)
        posterior_start._scan_start(y, system, 0.95, 30e-9, 5.0)
        t0, n = time.perf_counter(), 20
        for _ in range(n):
            start = posterior_start._scan_start(y, system, 0.95, 30e-9, 5.0)
        ms = (time.perf_counter() - t0) / n * 1e3
        print(f"{m} samples: {ms:.2f} ms per scan, depth {start[0]:.3f} m")
