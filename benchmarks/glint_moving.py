"""Mean surface echo over Cox-Munk at 20 deg: frozen sea (t = 0) against the moving sea.

Run: PYTHONPATH=. python benchmarks/glint_moving.py N U:SEED [U:SEED ...]
e.g. ``benchmarks/glint_moving.py 400000 3:12 3:13 3:14 2:12`` (RESULTS_realism.md, sixth
session). The shipped wave scene with the given wind and scene seed, one sub-ray per pulse at
random positions and azimuths, frozen (every pulse at t = 0) or moving (times uniform over 20 s);
the reference is Cox & Munk (1954) with whitecaps, written out here as in
tests/simulate/test_glint_convergence.py.
"""

from __future__ import annotations

import math
import sys
import time
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "simulate"))

from test_glint_convergence import EXTENT, OFF_NADIR, _Pulses  # noqa: E402
from waveform_support import common_pe  # noqa: E402

from pipeline.scene import parse_scene  # noqa: E402
from pipeline.simulate.budget import return_budget  # noqa: E402
from pipeline.simulate.trace import TraceSettings, trace  # noqa: E402
from pipeline.simulate.world import build_truth, build_world  # noqa: E402


def cox_munk_echo(scene) -> float:
    """Expected surface echo (pe) of a pulse at 20 deg over a Cox-Munk sea at 400 m."""
    u = scene.water.wind_speed_m_s
    s2, cover = 0.003 + 0.00512 * u, 2.95e-6 * u**3.52
    ratio_n = scene.water.phase_index / scene.atmosphere.refractive_index
    r0 = ((ratio_n - 1.0) / (ratio_n + 1.0)) ** 2
    c, t2 = math.cos(OFF_NADIR), math.tan(OFF_NADIR) ** 2
    per_sr = (1 - cover) * r0 * math.exp(-t2 / s2) / (4 * math.pi * s2 * c**5)
    per_sr += cover * 0.22 * c / math.pi
    r = 400.0 / c
    return common_pe(scene) * math.exp(-2 * scene.atmosphere.extinction_per_m * r) * per_sr / r**2


def main() -> None:
    n = int(sys.argv[1])
    path = ROOT / "data_synthetic" / "scenes" / "palmer_survey_waves.toml"
    base = parse_scene(tomllib.loads(path.read_text()))
    for spec in sys.argv[2:]:
        u, seed = float(spec.split(":")[0]), int(spec.split(":")[1])
        scene = replace(
            base,
            scene=replace(base.scene, seed=seed),
            water=replace(base.water, wind_speed_m_s=u),
            seabed=replace(base.seabed, roughness_rms_m=0.0),
        )
        truth = build_truth(scene, EXTENT)
        world = build_world(scene, truth, EXTENT)
        mss = truth.water.field.mean_square_slope(0.0)
        scene = replace(scene, returns=replace(scene.returns, resolved_mean_square_slope=mss))
        expected = cox_munk_echo(scene)
        out = []
        for label, t_max in (("frozen", 0.0), ("moving", 20.0)):
            pulses = _Pulses(n, 13)  # the test's pulses: times uniform over 2 s, rescaled
            pulses.t_s = pulses.t_s * (t_max / 2.0)
            t0 = time.process_time()
            div = scene.scanner.beam_divergence_mrad * 1e-3
            paths = trace(pulses, world, TraceSettings(subrays=1), div)
            cpu = time.process_time() - t0
            b = return_budget(paths, scene, scene.detector, scene.returns)
            ratio = np.exp(b.log_surface).sum(axis=1) / expected
            se = ratio.std() / math.sqrt(n)
            out.append(f"{label}: {ratio.mean():.4f} +- {se:.4f} (trace {cpu:.1f} CPU-s)")
        slab = getattr(truth.water, "slab_s", 0.0)
        print(
            f"U {u} seed {seed} slab {slab:.4f} s grid {truth.water.field.shape}: " + "; ".join(out)
        )


if __name__ == "__main__":
    main()
