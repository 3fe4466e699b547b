"""Calibration and cost of the depth posterior, the point TPU and the cell uncertainty.

Run: .venv/bin/python benchmarks/bench_posterior.py [--pulses 500] [--pc-pulses 200]
[--seed S] [--posterior-only] [--dump FILE.npz] [--set KEY=JSON] [--threads N]
Writes nothing but stdout (and ``--dump``'s per-pulse summaries); results are recorded by hand
in benchmarks/RESULTS_posterior.md. ``--seed`` draws another set of truths and noise (the
held-out check of a change tuned on the default set).

1. Simulation-based calibration of the sampler: pulses drawn from the process-side model and
   its noise law with known parameters (depth 1-10 m, a range of SNR), sampled with the
   production settings; coverage of the 68 % and 95 % intervals, overall and per bin.
2. Cramér–Rao: posterior sigma of the depth over 16 realisations of a flat-bottom pulse vs
   the CRB of the same model.
3. TPU vs Monte Carlo through refraction.py (sigma ratio and interval coverage).
4. Cost: seconds per pulse; TPU and cells per point; per km² for the cell strategy.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "uncertainty"))

from pipeline.process.grid import grid_points  # noqa: E402
from pipeline.process.refraction import RefractionSettings  # noqa: E402
from pipeline.uncertainty.cell_uncertainty import cell_uncertainty, select_posterior_pulses  # noqa: E402
from pipeline.uncertainty.posterior import (  # noqa: E402
    PosteriorFlag,
    PosteriorSettings,
    interval_summary,
    sample_batch,
)
from pipeline.uncertainty.survey_uncertainty import take_tpu  # noqa: E402
from pipeline.uncertainty.tpu import TpuSettings, monte_carlo_points, point_tpu  # noqa: E402
from pipeline.uncertainty.waveform_information import (  # noqa: E402
    depth_crb_m,
)
from pipeline.uncertainty.waveform_model import (  # noqa: E402
    WaveformSystem,
    draw_waveform,
    in_water_delay_s,
)

FW = WaveformSystem(
    sample_interval_s=1e-9,
    pulse_fwhm_s=3e-9,
    counts_per_photoelectron=5.0,
    excess_noise_factor=1.3,
    electronic_noise_counts=2.0,
    offset_counts=100.0,
)
PC = WaveformSystem(sample_interval_s=1e-9, pulse_fwhm_s=3e-9, receiver="photon_counting")
N_G = 1.3638


def window(th):
    """Samples covering the surface, the column and the bottom plus 12 ns."""
    return int(math.ceil((th[1] * 1e-9 + in_water_delay_s(th[0], 1.0, N_G)) / 1e-9 + 12.0))


def draw_truths(n, rng, pc=False, depth=(1.0, 10.0)):
    d = rng.uniform(*depth, n)
    # the detector takes its noise floor from the first 10 % of the window: start 15 ns in
    t_ns = 15.0 + rng.uniform(0.0, 1.0, n)
    if pc:
        areas = np.exp(rng.uniform(np.log([150, 60, 40]), np.log([800, 300, 300]), (n, 3)))
        bg = rng.uniform(0.02, 0.3, n)
    else:
        areas = np.exp(rng.uniform(np.log([500, 100, 150]), np.log([5000, 2000, 3000]), (n, 3)))
        bg = rng.uniform(0.5, 10.0, n)
    k = np.exp(rng.uniform(np.log(0.08), np.log(0.5), n))
    lw = np.log(rng.uniform(1.0, 2.0, n))  # bottom echo up to twice the response (stretching)
    lws = np.log(rng.uniform(1.0, 1.3, n))  # surface echo widened by the footprint
    th = np.column_stack([d, t_ns, np.log(areas), np.log(k), bg, lw, lws])
    system = PC if pc else FW
    return th, [draw_waveform(t, window(t), system, rng) for t in th]


def coverage(lo, hi, x):
    return float(np.mean((lo <= x) & (x <= hi)))


def calibrate(name, n, system, rng, st, pc=False, dump=None):
    th, waves = draw_truths(n, rng, pc=pc)
    order = np.argsort([w.size for w in waves])  # batches of similar length: less padding
    # compile (or load) the numba kernels before the clock starts: the figure is the sampling
    sample_batch(waves[:2], system, dataclasses.replace(st, max_steps=20, min_steps=0), seed=0)
    t0, c0 = time.perf_counter(), time.process_time()
    chains = [None] * n
    started = np.ones(n, bool)
    for b in range(0, n, st.batch_size):
        idx = order[b : b + st.batch_size]
        out = sample_batch([waves[i] for i in idx], system, st, seed=b)
        for k, i in enumerate(idx):
            q = interval_summary(out.draws[k, :, 0])
            stats = (out.converged[k], out.acceptance[k], out.tau_steps[k].max(), out.n_steps[k])
            chains[i] = (q, *stats)
            started[i] = not out.flags[k] & PosteriorFlag.NO_START
    el, cpu = time.perf_counter() - t0, time.process_time() - c0
    s = {key: np.array([c[0][key] for c in chains]) for key in chains[0][0]}
    conv = np.array([c[1] for c in chains])
    acc = np.array([c[2] for c in chains])
    tau = np.array([c[3] for c in chains])
    steps = np.array([c[4] for c in chains])
    if dump is not None:  # per-pulse summaries: two code versions compared pulse by pulse
        dump.update({f"{name[:2]}_{k}": v for k, v in s.items()})
        dump.update({f"{name[:2]}_conv": conv, f"{name[:2]}_acc": acc, f"{name[:2]}_steps": steps})
    d = th[:, 0]
    snr_area = th[:, 4]  # log bottom area
    print(
        f"\n## {name}: {n} pulses, {el:.1f} s, {el / n * 1e3:.0f} ms/pulse wall, "
        f"{cpu / n * 1e3:.0f} ms/pulse CPU; "
        f"{n - started.sum()} without a start (no surface detected), left out"
    )
    print("| subset | pulses | 68 % coverage | 95 % coverage |")
    print("|---|---|---|---|")

    def row(label, sel):
        print(
            f"| {label} | {sel.sum()} | {coverage(s['lo68'][sel], s['hi68'][sel], d[sel]):.3f}"
            f" | {coverage(s['lo95'][sel], s['hi95'][sel], d[sel]):.3f} |"
        )

    row("all", started)
    row("converged", conv & started)
    row("not converged", ~conv & started)
    for lo, hi in ((1, 4), (4, 7), (7, 10)):
        row(f"depth {lo}-{hi} m", started & (d >= lo) & (d < hi))
    q = np.quantile(snr_area, [1 / 3, 2 / 3])
    row("weakest third of bottoms", started & (snr_area < q[0]))
    row("strongest third of bottoms", started & (snr_area >= q[1]))
    z = ((s["median"] - d) / np.where(started, s["std"], 1.0))[started]
    print(f"z = (median - truth) / sd: mean {z.mean():.3f}, sd {z.std():.3f}")
    print(
        f"converged {conv.mean():.3f}; acceptance median {np.median(acc):.2f}"
        f" [{acc.min():.2f}, {acc.max():.2f}]; tau median {np.median(tau):.1f} steps"
        f" (90 % {np.quantile(tau, 0.9):.1f}); steps mean {steps.mean():.0f}"
    )
    return cpu / n  # CPU, not wall: the machine is shared


def crb(name, th, system, st, n=16):
    m = window(th)
    rng = np.random.default_rng(21)
    waves = [draw_waveform(th, m, system, rng) for _ in range(n)]
    out = sample_batch(waves, system, st, seed=2)
    sd = np.std(out.draws[:, :, 0], axis=1)
    bound = depth_crb_m(th, m, system)
    print(
        f"{name}: CRB {bound * 100:.2f} cm, posterior sd {sd.mean() * 100:.2f} cm "
        f"(range {sd.min() * 100:.2f}-{sd.max() * 100:.2f}), ratio {sd.mean() / bound:.3f}"
    )


def tpu_check(n_draws):
    from test_tpu import RST, survey

    ret, surf = survey(wave_m=0.05)
    st = TpuSettings(wave_slope_sigma_rad=0.02, seabed_slope_deg=5.0)
    t0 = time.perf_counter()
    tpu = point_tpu(ret, surf, RST, st)
    t_tpu = time.perf_counter() - t0
    mc = monte_carlo_points(ret, surf, RST, st, n_draws=n_draws, seed=7)
    sd = mc.std(axis=0)
    print(f"\n## TPU vs Monte Carlo ({len(tpu)} points, {n_draws} draws)")
    print("| coordinate | MC sd / TPU sigma: mean | min | max | 68 % coverage | 95 % coverage |")
    print("|---|---|---|---|---|---|")
    for a, (lab, sig) in enumerate(
        zip("xyz", (tpu.sigma_x_m, tpu.sigma_y_m, tpu.sigma_v_m), strict=True)
    ):
        r = sd[:, a] / sig
        dev = np.abs(mc[:, :, a] - tpu.xyz_m[:, a])
        print(
            f"| {lab} | {r.mean():.3f} | {r.min():.3f} | {r.max():.3f} | "
            f"{np.mean(dev <= sig):.3f} | {np.mean(dev <= 1.96 * sig):.3f} |"
        )
    print(
        f"median sigma_v {np.median(tpu.sigma_v_m):.3f} m, sigma_h "
        f"{np.median(tpu.sigma_h_m):.3f} m; TPU {t_tpu / len(tpu) * 1e6:.0f} us/point "
        f"at {len(tpu)} points"
    )


def cost_per_km2(s_per_pulse):
    """TPU and cells on a synthetic 200 m x 200 m patch at 2 points/m²; posterior budget."""
    from test_tpu import RST, survey

    # TPU throughput on a bigger survey (the 144-point one is overhead-bound)
    ret, surf = survey(n_side=100, wave_m=0.05)
    t0 = time.perf_counter()
    tpu = point_tpu(
        ret, surf, RefractionSettings(phase_index=RST.phase_index, group_index=RST.group_index)
    )
    t_tpu = (time.perf_counter() - t0) / len(tpu)
    rng = np.random.default_rng(9)
    n = 80_000  # 2 points / m² on 200 m x 200 m
    x, y = rng.uniform(0, 200, n), rng.uniform(0, 200, n)
    depth = 8.0 + 0.02 * x + rng.normal(0, 0.05, n)
    grid = grid_points(x, y, depth, resolution_m=2.0, bounds_m=(0, 200, 0, 200))
    # the points take the TPU of random points of the survey above
    j = rng.integers(0, len(tpu), n)
    pick_tpu = dataclasses.replace(take_tpu(tpu, j), xyz_m=np.column_stack([x, y, -depth]))
    t0 = time.perf_counter()
    cells = cell_uncertainty(grid, pick_tpu)
    t_cells = time.perf_counter() - t0
    sel = select_posterior_pulses(grid, cells, pick_tpu, k_per_cell=2, max_pulses=10**9)
    frac = len(sel) / n
    area_km2 = 0.04
    print(f"\n## Cost (2 points/m², 2 m cells: {grid.count.size / area_km2:.0f} cells/km²)")
    print(
        f"TPU {t_tpu * 1e6:.0f} us/point -> {t_tpu * 2e6:.0f} s/km²; cells "
        f"{t_cells / area_km2:.2f} s/km²"
    )
    print(
        f"posterior {s_per_pulse:.3f} CPU s/pulse: every pulse "
        f"{s_per_pulse * 2e6 / 3600:.0f} h/km²;"
        f" k = 2 per marginal cell here ({frac:.1%} of points) "
        f"{s_per_pulse * len(sel) / area_km2 / 3600:.1f} h/km²; with a cap of 2000 pulses/km² "
        f"{s_per_pulse * 2000 / 60:.1f} min/km²"
    )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--pulses", type=int, default=500)
    ap.add_argument("--pc-pulses", type=int, default=200)
    ap.add_argument("--mc-draws", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=None, help="truths' seed (default 101 / 202)")
    ap.add_argument("--posterior-only", action="store_true", help="sections 1 only")
    ap.add_argument("--dump", default=None, help="npz of the per-pulse summaries")
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a PosteriorSettings field for this run (VALUE in JSON), repeatable",
    )
    ap.add_argument(
        "--threads",
        type=int,
        default=None,
        help="threads of the sampler's log-densities (default: every core, as `bathy run`)",
    )
    args = ap.parse_args()
    import numba

    if args.threads is not None:
        numba.set_num_threads(args.threads)
    print(f"sampler threads: {numba.get_num_threads()}")
    st = PosteriorSettings()
    for kv in args.set:
        key, value = kv.split("=", 1)
        st = dataclasses.replace(st, **{key: json.loads(value)})
    print(f"settings changed: {args.set or 'none'}")
    # the full-waveform law as `bathy run` samples it: the surface echo's misfit drawn and
    # modelled (process.posterior.surface_misfit; 0 gives the runs before session 14)
    fw = dataclasses.replace(FW, surface_misfit=st.surface_misfit)
    print(f"full-waveform surface misfit: {fw.surface_misfit}")
    seeds = (101, 202) if args.seed is None else (args.seed, args.seed + 1)
    dump = None if args.dump is None else {}
    s_fw = calibrate(
        "Full waveform (Gaussian noise law)",
        args.pulses,
        fw,
        np.random.default_rng(seeds[0]),
        st,
        dump=dump,
    )
    calibrate(
        "Photon counting (Poisson)",
        args.pc_pulses,
        PC,
        np.random.default_rng(seeds[1]),
        st,
        pc=True,
        dump=dump,
    )
    if dump is not None:
        np.savez(args.dump, **dump)
    if args.posterior_only:
        return
    print("\n## Cramér–Rao (16 realisations, flat bottom at 4 m)")
    crb(
        "full waveform",
        np.array(
            [4.0, 15.0, math.log(2000), math.log(500), math.log(1200), math.log(0.2), 4.0, 0.0, 0.0]
        ),
        fw,
        st,
    )
    crb(
        "photon counting",
        np.array(
            [4.0, 15.0, math.log(1000), math.log(1000), math.log(400), math.log(0.2), 0.5, 0.0, 0.0]
        ),
        PC,
        st,
    )
    tpu_check(args.mc_draws)
    cost_per_km2(s_fw)


if __name__ == "__main__":
    main()
