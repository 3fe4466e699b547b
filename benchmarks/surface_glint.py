"""Flat water in a light wind: the detector's surface times against the truth, wind by wind.

The simulator's flat-water beams (:func:`pipeline.simulate.flat_paths.flat_paths`: no ray
tracer) at a scene's geometry, its receiver's waveforms, the full-waveform detector with its
weak-echo resampling (:mod:`pipeline.process.surface_echo_null`). The truth is each beam's
air range to the level water. For each wind: the survey's weak-echo test, the clear-echo
weight, and the mean error (ns) of the ambiguous echoes' onset-alone, echo-kept and mixed
surface times. Usage::

    PYTHONPATH=. python benchmarks/surface_glint.py SCENE.toml WINDS [--c C] [--altitude M]
        [--off-nadir DEG] [--pulses N] [--every K]

``WINDS``: comma-separated m/s. ``--c`` replaces the water's beam attenuation.
"""

from __future__ import annotations

import argparse
import dataclasses
import math

import numpy as np
from scipy import constants

from pipeline.process.context import instrument
from pipeline.process.detect import detect_full_waveform
from pipeline.process.surface_echo_mix import echo_weight, weak_echo_test
from pipeline.scene import load_scene
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.waveform import simulate_waveforms

N_AIR = 1.000277


def one_wind(scene, wind, args) -> str:
    """The table row of one wind."""
    water = dataclasses.replace(scene.water, wind_speed_m_s=wind)
    if args.c is not None:
        water = dataclasses.replace(water, extinction_per_m=args.c)
    detect = dataclasses.replace(scene.process.detect, surface_echo_null_every=args.every)
    process = dataclasses.replace(scene.process, detect=detect)
    scene = dataclasses.replace(scene, water=water, process=process)
    n = args.pulses
    rng = np.random.default_rng(1)
    paths = flat_paths(
        n,
        altitude_m=args.altitude or scene.flight.altitude_m,
        depth_m=rng.uniform(4.0, 6.0, n),
        off_nadir_rad=math.radians(
            scene.scanner.off_nadir_deg if args.off_nadir is None else args.off_nadir
        ),
        azimuth_rad=rng.uniform(0.0, 2.0 * math.pi, n),
        divergence_rad=scene.scanner.beam_divergence_mrad * 1e-3,
    )
    wf = simulate_waveforms(paths, scene, scene.detector, scene.returns)
    ins = instrument(scene, N_AIR)
    det = detect_full_waveform(
        wf.samples,
        wf.sample_interval_s,
        ins.system_fwhm_s,
        detect,
        noise_samples=ins.noise_samples,
        shot_noise_counts=ins.shot_noise_counts,
        top_code=ins.amplitude_full_scale - 1.0,
        pulse_id=wf.pulse_id,
    )
    t_true = 2.0 * N_AIR * paths.air_range_m[:, 0] / constants.c - wf.t0_s
    mix = det.surface_echo_state < 0
    pair = mix & np.isfinite(det.surface_echo_null_shift_s)
    weak, fig = weak_echo_test(
        det.surface_echo_shift_s[pair],
        det.surface_echo_null_shift_s[pair],
        detect.surface_echo_null_z,
        detect.surface_echo_null_excess,
    )
    n_clear = int(np.count_nonzero(det.surface_echo_state == 1))
    w_clear = echo_weight(n_clear, int(mix.sum()), detect.surface_echo_prevalence_half)
    few_clear = n_clear < detect.surface_echo_null_max_clear * (n_clear + int(mix.sum()))
    w = 1.0 if weak and few_clear else w_clear

    def err(t):
        return f"{1e9 * np.mean(t - t_true[mix]):+.3f}" if mix.any() else "-"

    t_on, shift = det.t_surface_onset_s[mix], det.surface_echo_shift_s[mix]
    z = "-" if fig["z"] is None else f"{fig['z']:+.1f}"
    ex = "-" if fig["excess"] is None else f"{100 * fig['excess']:+.0f} %"
    return (
        f"| {wind:g} | {n_clear} / {int(mix.sum())} | {fig['pairs']} | {z} | {ex} | "
        f"{'yes' if weak else 'no'} | {w_clear:.3f} | {err(t_on)} | {err(t_on + shift)} | "
        f"{err(t_on + w_clear * shift)} | {err(t_on + w * shift)} |"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("winds")
    ap.add_argument("--c", type=float, default=None)
    ap.add_argument("--altitude", type=float, default=None)
    ap.add_argument("--off-nadir", type=float, default=None)
    ap.add_argument("--pulses", type=int, default=4000)
    ap.add_argument("--every", type=int, default=4)
    args = ap.parse_args()
    scene = load_scene(args.scene)
    print(
        "| wind m/s | clear / ambiguous | resampled | z | excess | echoes? | clear-share w | "
        "onset err ns | echo-kept err ns | before (clear share) ns | after ns |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for wind in (float(w) for w in args.winds.split(",")):
        print(one_wind(scene, wind, args), flush=True)


if __name__ == "__main__":
    main()
