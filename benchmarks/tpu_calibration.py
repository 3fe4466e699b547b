"""Calibration of the propagated depth uncertainty against the truth, with a breakdown.

Runs a survey scene's simulation (cached with ``--cache``), processes it as ``bathy run`` does
(:func:`pipeline.run_survey.run_survey`'s steps, without the water-column points and the
posteriors, which do not touch the bathymetric points) and prints, for the bathymetric points,
how often the true depth lies within ``±sigma`` and ``±1.96 sigma`` of the measured depth, by
depth, with the error's bias and RMS against the RMS sigma, and the RMS of the main TPU terms
(depth column) per depth bin. ``--truth-terms`` (full-waveform scenes) also reprocesses with
the true navigation, to show the navigation's share of the realised depth error.

    .venv/bin/python benchmarks/tpu_calibration.py data_synthetic/scenes/palmer_survey.toml \\
        --cache /tmp/palmer.pkl

This script meets the truth (it is an evaluation tool, like :mod:`pipeline.evaluate`).
"""

from __future__ import annotations

import argparse
import dataclasses
import pickle
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

from pipeline.detection_store import DetectionStore
from pipeline.process.context import processing_context
from pipeline.process.grid import grid_seabed
from pipeline.process.refraction import seabed_points
from pipeline.process.survey_points import process_detections
from pipeline.run_survey import _measured_water, simulate_detections
from pipeline.scene import load_scene, parse_scene
from pipeline.stages import StageClock, plan
from pipeline.uncertainty.survey_uncertainty import survey_uncertainty

EDGES = (0.0, 1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 20.0, 30.0, 40.0)


def _scene(path: str, line_length: float | None, n_lines: int | None):
    if line_length is None and n_lines is None:
        return load_scene(path)
    data = tomllib.loads(Path(path).read_text())
    if line_length is not None:
        data["flight"]["line_length_m"] = line_length
    if n_lines is not None:
        data["flight"]["n_lines"] = n_lines
    return parse_scene(data)


def _simulate(scene, cache: Path | None):
    if cache is not None and cache.exists():
        with cache.open("rb") as f:
            return pickle.load(f)
    ctx = processing_context(scene)
    with (
        tempfile.TemporaryDirectory() as tmp,
        DetectionStore(Path(tmp), ctx.instrument.air_index) as st,
    ):
        sim = simulate_detections(scene, plan(scene), ctx, StageClock(), st, log=lambda s: None)
    if cache is not None:
        try:
            blob = pickle.dumps(sim)
        except (AttributeError, pickle.PicklingError) as exc:  # the truth's pulse-time lookup
            print(f"not cached ({exc})")
        else:
            cache.write_bytes(blob)
    return sim


def _true_pulses(scene, sim, pulse_id):
    """True origins and directions of the given pulses (full-waveform: one row per pulse)."""
    from pipeline.simulate import survey

    lines = sim.lines
    out_o = np.empty((len(pulse_id), 3))
    out_d = np.empty((len(pulse_id), 3))
    order = np.argsort(pulse_id)
    ids = pulse_id[order]
    lo = 0
    while lo < len(ids):
        hi = min(lo + 200_000, len(ids))
        p = survey.pulses_for_range(
            scene.flight,
            scene.attitude,
            scene.navigation,
            scene.scanner,
            lines,
            int(ids[lo]),
            int(ids[hi - 1]) + 1,
            scene.scene.seed,
        )
        k = ids[lo:hi] - int(ids[lo])
        out_o[order[lo:hi]] = p.origin_m[k]
        out_d[order[lo:hi]] = p.direction[k]
        lo = hi
    return out_o, out_d


def _row(name, err, sig):
    z = np.abs(err) / sig
    return (
        f"| {name} | {len(err)} | {np.mean(z <= 1.0):.1%} | {np.mean(z <= 1.96):.1%} "
        f"| {np.mean(err):+.4f} | {np.sqrt(np.mean(err**2)):.4f} | "
        f"{np.sqrt(np.mean(sig**2)):.4f} |"
    )


def process(scene, sim):
    """The bathymetric points, their TPU and the processed survey, as ``bathy run`` makes them."""
    ps = scene.process
    # as bathy run: the forward-scattering correction at the water the columns measured
    ctx = _measured_water(processing_context(scene), sim, log=lambda s: None)
    processed = process_detections(sim.returns, ctx, ps.classify)
    grid = grid_seabed(processed.points, ps.grid_resolution_m)
    unc = survey_uncertainty(sim.returns, processed, ctx, grid)
    return unc, processed, ctx.refraction, ctx.surface_fit


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("scene")
    ap.add_argument("--line-length", type=float)
    ap.add_argument("--n-lines", type=int)
    ap.add_argument("--cache", type=Path)
    ap.add_argument("--truth-terms", action="store_true")
    ap.add_argument("--edges", help="depth bin edges, comma-separated (m)")
    a = ap.parse_args(argv)
    edges = EDGES if a.edges is None else tuple(float(e) for e in a.edges.split(","))
    scene = _scene(a.scene, a.line_length, a.n_lines)
    t0 = time.perf_counter()
    sim = _simulate(scene, a.cache)
    print(f"simulation {time.perf_counter() - t0:.1f} s, {len(sim.returns)} pulses")
    t1 = time.perf_counter()
    unc, processed, refr, fit = process(scene, sim)
    print(f"processing and uncertainty {time.perf_counter() - t1:.1f} s")
    p40, tpu = unc.points40, unc.tpu40
    truth = sim.truth
    err = p40.depth_m - truth.depth_m(p40.xyz_m[:, 0], p40.xyz_m[:, 1])
    sig = tpu.sigma_depth_m
    d = p40.depth_m
    print("\n| subset | n | within 1 σ | within 1.96 σ | bias (m) | RMS error (m) | RMS σ (m) |")
    print("|---|---|---|---|---|---|---|")
    print(_row("all, depth sigma", err, sig))
    print(_row("all, elevation sigma (sigma_v_m)", err, tpu.sigma_v_m))
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (d >= lo) & (d < hi)
        if m.sum() >= 50:
            print(_row(f"depth {lo:g}-{hi:g} m", err[m], sig[m]))
    groups = {k: (k,) for k in tpu.terms}
    groups.update(
        surface_tilt=("surface_tilt_x", "surface_tilt_y"),
        water_indices=("temperature", "salinity"),
        attitude=("attitude_x", "attitude_y", "heading"),
        pointing=("pointing_a", "pointing_b"),
        wave_slope=("wave_slope_x", "wave_slope_y"),
    )
    for parts in list(groups.values()):
        if len(parts) > 1:
            for k in parts:
                groups.pop(k, None)

    def rms(names, m):
        return np.sqrt(np.mean(sum(tpu.terms[k][m, 3] ** 2 for k in names)))

    every = np.ones(len(d), dtype=bool)
    names = sorted(groups, key=lambda g: -rms(groups[g], every))[:7]
    print("\nRMS one-sigma depth change per term (m):\n")
    print("| depth | " + " | ".join(names) + " | total |")
    print("|---" * (len(names) + 2) + "|")
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        m = (d >= lo) & (d < hi)
        if m.sum() >= 50:
            cells = [f"{rms(groups[g], m):.4f}" for g in names]
            total = np.sqrt(np.mean(sig[m] ** 2))
            print(f"| {lo:g}-{hi:g} m | " + " | ".join(cells) + f" | {total:.4f} |")
    if a.truth_terms and scene.detector.mode != "photon_counting":
        _truth_terms(scene, sim, refr, p40, err, sig, fit)


def _truth_terms(scene, sim, refr, p40, err, sig, fit):
    """Realised depth error of the navigation: process again with the true navigation."""
    from pipeline.process.surface_fit import fit_water_surface

    ret = sim.returns
    o_true, d_true = _true_pulses(scene, sim, ret.pulse_id)
    truth = sim.truth
    order = np.argsort(ret.pulse_id)
    rows = order[np.searchsorted(ret.pulse_id[order], p40.pulse_id)]
    print("\n| reprocessed with | RMS error (m) | RMS of the change (m) |")
    print("|---|---|---|")
    for name, o, d in (
        ("true position", o_true, ret.direction_meas),
        ("true attitude", ret.origin_meas_m, d_true),
        ("true navigation", o_true, d_true),
    ):
        r2 = dataclasses.replace(ret, origin_meas_m=o, direction_meas=d)
        s2 = fit_water_surface(r2, fit)
        p2 = seabed_points(r2, s2, refr)
        pos = np.searchsorted(np.flatnonzero(ret.has_bottom), rows)
        e2 = p2.depth_m[pos] - truth.depth_m(p2.xyz_m[pos, 0], p2.xyz_m[pos, 1])
        print(
            f"| {name} | {np.sqrt(np.mean(e2**2)):.4f} | {np.sqrt(np.mean((err - e2) ** 2)):.4f} |"
        )


if __name__ == "__main__":
    main()
