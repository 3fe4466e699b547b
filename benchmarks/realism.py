"""Penetration and forward-scattering range bias of the presets (issue 12, items 3-5).

For each preset, over flat water and a flat seabed at a sweep of depths (closed-form paths,
`flat_paths`, the preset's off-nadir angle, 400 m altitude), simulates the receiver and runs the
processing detector (full waveform: `detect_full_waveform`; photon counting:
`detect_photon_events` on windows of `shots_per_window` shots). A pulse (or window) counts as a
bottom detection when a bottom is reported within 0.5 m of the true depth (depth from the
detected surface-bottom time with the group index along the refracted ray). The maximum
bottom-detection depth is the deepest depth of the sweep where at least half of them do; it is
given in Secchi depths ``Z_SD = 1.7 / K_d`` (Poole & Atkins 1926) with ``K_d = 0.2 c + 0.04``.

The water is the built-in default scene's (c = 0.15 1/m, wind 5 m/s, sand seabed 0.25): run
with the code before and after the change on the path to compare. `--bias` (new code only)
also prints the forward-scattering model's range bias at 5/10/20 m and the bias of the depth
the processing detector finds on noise-free waveforms with and without the delay.

`--cost FS/ATT` times the budget and noisy full waveforms of 20 000 pulses (3-30 m, 20 deg off
nadir, CPU time, best of 3) with ``returns.forward_scatter = FS`` and
``returns.lidar_attenuation = ATT`` (``--cost scene``: the scene's own, also on the old code).

Run: PYTHONPATH=. .venv/bin/python benchmarks/realism.py [--pulses 200] [--seed 1] [--bias]
     [--cost small_angle/fov] [--altitude 400]

`--altitude 75` is the altitude at which RIEGL's VQ-840-GL datasheet states its depth penetration
(1.7 / 1.8 / 2.0 Secchi depths at 200 / 100 / 50 kHz).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time
import tomllib

import numpy as np

from pipeline.process.detect import detect_full_waveform
from pipeline.process.detect_photons import detect_photon_events
from pipeline.scene import DEFAULT_SCENE_PATH, parse_scene
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.waveform import simulate_photon_events, simulate_waveforms

C = 299_792_458.0
ALTITUDE_M = 400.0
PRESETS = ("topobathy_full_waveform", "photon_counting")


def scene_of(preset: str, seed: int):
    """The default scene with ``preset`` (its flight table and run-in are irrelevant here)."""
    data = tomllib.loads(DEFAULT_SCENE_PATH.read_text(encoding="utf-8"))
    data["scene"]["preset"] = preset
    data["scene"]["seed"] = seed
    data.pop("scanner", None)  # the preset's own pulse rate
    scene = parse_scene(data)
    if scene.detector.mode == "full_waveform":
        # the preset's window (a chosen value) holds ~30 m of water; the sweep goes to 60 m
        data.setdefault("detector", {})["window_s"] = max(scene.detector.window_s, 6.0e-7)
        scene = parse_scene(data)
    return scene


def _paths(scene, n, depth, first_id):
    theta = math.radians(scene.scanner.off_nadir_deg)
    return flat_paths(
        n,
        altitude_m=ALTITUDE_M,
        depth_m=depth,
        off_nadir_rad=theta,
        water_phase_index=scene.water.phase_index,
        air_index=scene.atmosphere.refractive_index,
        divergence_rad=scene.scanner.beam_divergence_mrad * 1e-3,
        first_pulse_id=first_id,
        spacing_m=0.01,
    )


def _cos_w(scene):
    theta = math.radians(scene.scanner.off_nadir_deg)
    s = scene.atmosphere.refractive_index * math.sin(theta) / scene.water.phase_index
    return math.sqrt(1.0 - s * s)


def measured_depths(scene, n, depth, first_id, noise=True):
    """(found, depth_m) per pulse (full waveform) or per window (photon counting)."""
    paths = _paths(scene, n, depth, first_id)
    det = scene.detector
    n_g, cos_w = scene.water.group_index, _cos_w(scene)
    if det.mode == "photon_counting":
        ev = simulate_photon_events(paths, scene, det, scene.returns)
        axis = paths.direction[:, 0, :]
        found = detect_photon_events(ev.offsets, ev.times_s, paths.origin_m, axis,
                                     scene.atmosphere.refractive_index,
                                     scene.process.photon_detect, paths.pulse_id)  # fmt: skip
        spw = scene.process.photon_detect.shots_per_window
        first = np.arange(0, n, spw)  # one detection per window
        ok = found.has_bottom[first] & found.has_surface[first]
        dt = found.t_bottom_s[first] - found.t_surface_s[first]
    else:
        wf = simulate_waveforms(paths, scene, det, scene.returns, noise=noise)
        fwhm = math.hypot(scene.system.pulse_fwhm_s, det.impulse_response_fwhm_s)
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
        dt = found.t_bottom_s - found.t_surface_s
    return ok, C * dt / (2 * n_g) * cos_w


def max_depth(scene, n, depths):
    """Deepest depth of ``depths`` where >= half the pulses find the bottom within 0.5 m."""
    best, rows = 0.0, []
    for i, d in enumerate(depths):
        ok, z = measured_depths(scene, n, float(d), int(1e6 * (i + 1)))
        frac = float(np.mean(ok & (np.abs(z - d) < 0.5)))
        rows.append((d, frac))
        if frac >= 0.5:
            best = float(d)
    return best, rows


def main() -> None:
    global ALTITUDE_M
    ap = argparse.ArgumentParser()
    ap.add_argument("--pulses", type=int, default=200)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--bias", action="store_true")
    ap.add_argument("--cost", default="")
    ap.add_argument(
        "--altitude", type=float, default=ALTITUDE_M, help="flight altitude, m (datasheets: 75 m)"
    )
    args = ap.parse_args()
    ALTITUDE_M = args.altitude
    if args.cost:
        print_cost(args.cost)
        return
    depths = np.arange(10.0, 61.0, 1.0)
    kd = 0.2 * 0.15 + 0.04
    secchi = 1.7 / kd
    print(f"Secchi depth 1.7 / K_d = {secchi:.1f} m (K_d = {kd:.3f} 1/m), seed {args.seed},"
          f" altitude {ALTITUDE_M:g} m")  # fmt: skip
    for name in PRESETS:
        scene = scene_of(name, args.seed)
        n = args.pulses
        if scene.detector.mode == "photon_counting":
            n = 2 * scene.process.photon_detect.shots_per_window  # two windows per depth
        best, rows = max_depth(scene, n, depths)
        tail = " ".join(f"{d:.0f}:{f:.2f}" for d, f in rows if f > 0.0 and f < 1.0)
        print(f"{name}: max bottom-detection depth {best:.0f} m = {best / secchi:.2f} Secchi"
              f"  (partial: {tail})")  # fmt: skip
    if args.bias:
        print_bias(args.seed)


def print_bias(seed: int) -> None:
    """Model range bias and detected depth bias with and without the forward-scattering delay."""
    from pipeline.simulate.budget import return_budget

    scene = scene_of(PRESETS[0], seed)
    cos_w = _cos_w(scene)
    print("depth_m  model_range_bias_m  model_depth_bias_m  detected_bias_fs_m  without_fs_m")
    for d in (5.0, 10.0, 20.0):
        b = return_budget(_paths(scene, 1, d, 0), scene, scene.detector, scene.returns)
        delay_s = float(b.bottom_tail_weight[0, 0] * b.bottom_tail_s[0, 0])
        rng_bias = delay_s * C / (2 * scene.water.group_index)
        out = []
        for fs in ("small_angle", "none"):
            rs = dataclasses.replace(scene.returns, forward_scatter=fs)
            sc = dataclasses.replace(scene, returns=rs)
            ok, z = measured_depths(sc, 1, d, 0, noise=False)
            out.append(float(z[0] - d) if ok[0] else float("nan"))
        print(f"{d:7.1f}  {rng_bias:18.3f}  {rng_bias * cos_w:18.3f}  {out[0]:+18.3f}"
              f"  {out[1]:+12.3f}")  # fmt: skip


def print_cost(variant: str, n: int = 20_000) -> None:
    """Pulses per CPU second of the budget and noisy full waveforms (see module)."""
    scene = scene_of(PRESETS[0], 1)
    if variant != "scene":
        fs, att = variant.split("/")
        rs = dataclasses.replace(scene.returns, forward_scatter=fs, lidar_attenuation=att)
        scene = dataclasses.replace(scene, returns=rs)
    rng = np.random.default_rng(0)
    paths = flat_paths(
        n,
        altitude_m=ALTITUDE_M,
        depth_m=rng.uniform(3.0, 30.0, n),
        off_nadir_rad=math.radians(20.0),
        azimuth_rad=rng.uniform(0.0, 2.0 * math.pi, n),
        water_phase_index=scene.water.phase_index,
        air_index=scene.atmosphere.refractive_index,
        divergence_rad=1e-3,
        spacing_m=0.5,
    )
    simulate_waveforms(paths, scene, scene.detector, scene.returns)  # warm caches
    best = []
    for _ in range(3):
        t = time.process_time()
        simulate_waveforms(paths, scene, scene.detector, scene.returns)
        best.append(time.process_time() - t)
    print(f"{variant}: {n / min(best):.0f} pulses per CPU second")


if __name__ == "__main__":
    main()
