"""Shallow limit of the default system: depth bias and detection against depth.

For each depth, simulates noisy full waveforms of pulses at the default scene's off-nadir angle
over flat water and a flat seabed (closed-form paths, `flat_paths`), runs the processing
detector, and converts the detected surface-bottom time difference to depth with the group index
along the refracted ray. Prints, per depth, the fraction of pulses with a bottom, the fraction
flagged MERGED, and the bias and spread of the retrieved depth.

Run: .venv/bin/python benchmarks/shallow_limit.py [--pulses 400]
"""

from __future__ import annotations

import argparse
import math

import numpy as np

from pipeline.process.context import processing_context
from pipeline.process.detect import detect_full_waveform
from pipeline.process.returns import DetectorFlag
from pipeline.scene import DEFAULT_SCENE_PATH, load_scene
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.waveform import simulate_waveforms

C = 299_792_458.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--pulses", type=int, default=400)
    args = ap.parse_args()
    scene = load_scene(DEFAULT_SCENE_PATH)
    theta = math.radians(scene.scanner.off_nadir_deg)
    n_w, n_g, n_a = (
        scene.water.phase_index,
        scene.water.group_index,
        scene.atmosphere.refractive_index,
    )
    cos_w = math.sqrt(1 - (n_a * math.sin(theta) / n_w) ** 2)
    det = scene.detector
    fwhm = processing_context(scene).instrument.system_fwhm_s
    print(
        f"default system: pulse FWHM {scene.system.pulse_fwhm_s * 1e9:.2f} ns, system "
        f"{fwhm * 1e9:.2f} ns, {scene.scanner.off_nadir_deg:g} deg off nadir, "
        f"{det.sample_rate_hz / 1e9:g} GS/s"
    )
    print("depth_m  bottom_found  merged_flag  bias_m   std_m")
    for depth in (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0, 1.5, 2.0, 3.0):
        paths = flat_paths(
            args.pulses,
            altitude_m=scene.flight.altitude_m,
            depth_m=depth,
            off_nadir_rad=theta,
            water_phase_index=n_w,
            air_index=n_a,
            divergence_rad=scene.scanner.beam_divergence_mrad * 1e-3,
            first_pulse_id=int(depth * 1e6),
        )
        wf = simulate_waveforms(paths, scene, det, scene.returns)
        quiet = det.pre_trigger_s - 2 * fwhm
        found = detect_full_waveform(
            wf.samples,
            wf.sample_interval_s,
            fwhm,
            scene.process.detect,
            noise_samples=max(4, int(quiet / wf.sample_interval_s)),
            shot_noise_counts=det.excess_noise_factor * det.counts_per_photoelectron,
        )
        ok = found.has_bottom & found.has_surface
        d = C * (found.t_bottom_s - found.t_surface_s) / (2 * n_g) * cos_w
        merged = (found.flags & DetectorFlag.MERGED) > 0
        bias = float(np.mean(d[ok]) - depth) if ok.any() else float("nan")
        std = float(np.std(d[ok])) if ok.any() else float("nan")
        print(f"{depth:7.2f}  {ok.mean():12.2f}  {merged.mean():11.2f}  {bias:+7.3f}  {std:6.3f}")


if __name__ == "__main__":
    main()
