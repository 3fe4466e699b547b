"""Calibration of the depth posterior on the simulator's own waveforms, against the truth.

Run: .venv/bin/python benchmarks/calibrate_posterior_sim.py [--pulses-per-water 200]
Prints a markdown table; results are recorded in benchmarks/RESULTS_posterior.md.

Unlike ``bench_posterior.py`` (waveforms drawn from the process-side model), the waveforms here
come from the simulator (:func:`pipeline.simulate.waveform.simulate_waveforms`: sub-rays
across the Gaussian beam, Kirchhoff facets and whitecaps at the surface, the water column,
forward-scattering stretch of the bottom echo, photon-by-photon or Gaussian detector noise,
12-bit digitiser) with the default scene's system (the topobathy full-waveform preset), over
flat water and a flat seabed whose depth is the truth. The processing knows the system (pulse
and detector widths, gain, noise, group index) and the measured beam, nothing of the water
or the bottom: attenuation, column and bottom strength and the bottom echo's width are
nuisance parameters. Starts come from the survey's own detector; only pulses whose bottom the
detector found are sampled (the population whose points the survey reports).

Waters: three beam attenuations (clear, coastal, turbid); depths uniform from 1.5 m to the
depth where the bottom is still detected most of the time; 20° off nadir (a Palmer scan) at
random azimuths, 400 m above the water.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import time

import numpy as np

from pipeline.process.context import processing_context
from pipeline.process.detect import detect_full_waveform
from pipeline.scene import load_scene
from pipeline.simulate.flat_paths import flat_paths
from pipeline.simulate.waveform import simulate_waveforms
from pipeline.uncertainty.posterior import (
    PosteriorFlag,
    PosteriorSettings,
    interval_summary,
    sample_batch,
)
from pipeline.uncertainty.waveform_model import WaveformSystem

WATERS = (  # (name, beam attenuation 1/m, backscatter 1/(m sr), deepest depth drawn m)
    ("clear", 0.08, 1.0e-3, 22.0),
    ("coastal", 0.15, 2.0e-3, 14.0),
    ("turbid", 0.30, 4.0e-3, 7.0),
)


def system_of(scene) -> WaveformSystem:
    """The processing's knowledge of the instrument (system values, no water, no bottom)."""
    det = scene.detector
    return WaveformSystem(
        sample_interval_s=1.0 / det.sample_rate_hz,
        pulse_fwhm_s=processing_context(scene).instrument.system_fwhm_s,
        group_index=scene.water.group_index,
        offset_counts=det.baseline_counts,
        counts_per_photoelectron=det.counts_per_photoelectron,
        excess_noise_factor=det.excess_noise_factor,
        electronic_noise_counts=det.electronic_noise_counts,
    )


def run_water(base, name, ext, bsc, d_max, n, seed, subrays, off_nadir_deg):
    """Simulate ``n`` pulses over one water; sample the posteriors of those with a bottom."""
    sc = dataclasses.replace(
        base,
        water=dataclasses.replace(base.water, extinction_per_m=ext, backscatter_180_per_m_sr=bsc),
        scene=dataclasses.replace(base.scene, seed=seed),
    )
    rng = np.random.default_rng(seed)
    depth = rng.uniform(1.5, d_max, n)
    off = math.radians(off_nadir_deg)
    paths = flat_paths(
        n,
        altitude_m=400.0,
        depth_m=depth,
        off_nadir_rad=off,
        azimuth_rad=rng.uniform(0.0, 2.0 * math.pi, n),
        n_sub=subrays,
        divergence_rad=sc.scanner.beam_divergence_mrad * 1e-3,
        water_phase_index=sc.water.phase_index,
        air_index=sc.atmosphere.refractive_index,
        spacing_m=10.0,
    )
    det = sc.detector
    wf = simulate_waveforms(paths, sc, det, sc.returns)
    system = system_of(sc)
    quiet_s = det.pre_trigger_s - 2.0 * system.pulse_fwhm_s
    noise = (max(4, int(quiet_s / wf.sample_interval_s)), det.excess_noise_factor)
    found = detect_full_waveform(
        wf.samples,
        wf.sample_interval_s,
        system.pulse_fwhm_s,
        sc.process.detect,
        noise_samples=noise[0],
        shot_noise_counts=noise[1] * det.counts_per_photoelectron,
    )
    rows = np.flatnonzero(found.has_bottom)
    sin_w = math.sin(off) * sc.atmosphere.refractive_index / sc.water.phase_index
    cos_w = np.full(rows.size, math.sqrt(1.0 - sin_w**2))
    t0 = time.perf_counter()
    chains = sample_batch(
        wf.samples[rows].astype(np.float64),
        system,
        PosteriorSettings(),
        cos_water=cos_w,
        seed=seed,
        detect_settings=sc.process.detect,
        detect_noise=(noise[0], noise[1] * det.counts_per_photoelectron),
    )
    cost = time.perf_counter() - t0
    s = interval_summary(chains.draws[:, :, 0], axis=1)
    return {
        "water": np.full(rows.size, name),
        "depth": depth[rows],
        "s": s,
        "flags": chains.flags,
        "converged": chains.converged,
        "lw": np.median(chains.draws[:, :, 7], axis=1),
        "found": float(np.mean(found.has_bottom)),
        "cost_s": cost,
        "n_sim": n,
    }


def cover(s, d, mask):
    c68 = (s["lo68"] <= d) & (d <= s["hi68"])
    c95 = (s["lo95"] <= d) & (d <= s["hi95"])
    return int(mask.sum()), float(np.mean(c68[mask])), float(np.mean(c95[mask]))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pulses-per-water", type=int, default=230)
    ap.add_argument("--subrays", type=int, default=16)
    ap.add_argument("--off-nadir-deg", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args()
    base = load_scene("pipeline/scenes/default.toml")
    parts = []
    for k, (name, ext, bsc, d_max) in enumerate(WATERS):
        r = run_water(
            base, name, ext, bsc, d_max, a.pulses_per_water, a.seed + k, a.subrays, a.off_nadir_deg
        )
        parts.append(r)
        print(
            f"{name}: bottom found on {r['found']:.1%} of {r['n_sim']}; "
            f"{r['depth'].size} posteriors in {r['cost_s']:.0f} s",
            flush=True,
        )
    d = np.concatenate([p["depth"] for p in parts])
    s = {k: np.concatenate([p["s"][k] for p in parts]) for k in parts[0]["s"]}
    water = np.concatenate([p["water"] for p in parts])
    conv = np.concatenate([p["converged"] for p in parts])
    flags = np.concatenate([p["flags"] for p in parts])
    cost = sum(p["cost_s"] for p in parts)
    z = (s["median"] - d) / s["std"]
    print(f"\n{d.size} pulses, {cost / d.size:.2f} s per pulse posterior")
    print("\n| subset | pulses | 68 % coverage | 95 % coverage |")
    print("|---|---|---|---|")
    rows = [("**all**", np.ones(d.size, bool)), ("converged", conv), ("flagged", ~conv)]
    rows += [(f"water {w}", water == w) for w, *_ in WATERS]
    rel = np.concatenate([p["depth"] / w[3] for p, w in zip(parts, WATERS, strict=True)])
    rows += [
        ("shallow third of each water's range", rel < 1 / 3),
        ("deep third of each water's range", rel >= 2 / 3),
        ("started from a depth scan", (flags & np.uint16(PosteriorFlag.START_SCANNED)) > 0),
    ]
    for label, m in rows:
        if m.any():
            n, c68, c95 = cover(s, d, m)
            print(f"| {label} | {n} | {c68:.3f} | {c95:.3f} |")
    print(
        f"\nnormalised errors (median - truth) / sd: mean {np.mean(z):+.3f}, sd {np.std(z):.3f};"
        f" median |error| {np.median(np.abs(s['median'] - d)) * 100:.2f} cm,"
        f" median posterior sd {np.median(s['std']) * 100:.2f} cm;"
        f" converged {np.mean(conv):.1%}"
    )
    lw = np.concatenate([p["lw"] for p in parts])
    print(
        f"bottom echo width over the response (posterior median): "
        f"{np.percentile(np.exp(lw), [5, 50, 95]).round(2)} (5/50/95 %)"
    )


if __name__ == "__main__":
    main()
