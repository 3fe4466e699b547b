"""Figures 14-17 and the JSON photon budget of the profiling bathymeter."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")  # files only: no screen on survey servers or CI
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from pipeline import lidar_equation as le  # noqa: E402
from pipeline import profiler  # noqa: E402
from pipeline.outputs.atomic import atomic_path, write_json  # noqa: E402

__all__ = ["ProfilerResults", "compute", "write_report"]

#: Floor detection criterion reported in the budget: S / sqrt(S + B) over a ±FWHM window.
DETECTION_SNR = 5.0


class ProfilerResults(dict):
    """Everything the profiler figures and budget are made of (a plain dict of arrays)."""


def compute(scene) -> ProfilerResults:
    """Run the profiler stages: transmittance, budget, ideal times, simulated histograms."""
    return ProfilerResults(**compute_budget(scene), **compute_histograms(scene))


def compute_budget(scene) -> dict[str, Any]:
    """The photon-budget stage: transmittance, budget against depth, ideal times."""
    prof = scene.profiler
    depths = np.geomspace(*prof.depth_sweep_m, 200)
    return {
        "transmittance": profiler.transmittance_profile(scene),
        "sweep": profiler.budget_vs_depth(scene, depths),
        "ideal": profiler.ideal_times(scene, depths),
        "budget": le.nadir_budget(scene, prof.altitude_m, scene.seabed.depth_m),
    }


def compute_histograms(scene) -> dict[str, Any]:
    """The histogram stage: the expected and the simulated accumulated histograms."""
    gate = profiler.range_gate(scene)
    hists = {}
    for i, n_shots in enumerate(scene.profiler.shot_counts):
        rng = np.random.default_rng([scene.scene.seed, 17, i])
        hists[n_shots] = profiler.simulate_histogram(scene, gate, n_shots, rng)
    return {"gate": gate, "expected": profiler.expected_histogram(scene, gate), "histograms": hists}


def _floor_detection(res: ProfilerResults, fwhm_s: float) -> dict[str, Any]:
    gate = res["gate"]
    centres = 0.5 * (gate.edges_s[1:] + gate.edges_s[:-1])
    win = np.abs(centres - gate.t_floor_s) <= fwhm_s
    exp = res["expected"]
    s = float(exp["floor"][win].sum())
    b = float((exp["total"] - exp["floor"])[win].sum())
    # S N / sqrt((S + B) N) >= k  <=>  N >= k² (S + B) / S²
    n_needed = math.ceil(DETECTION_SNR**2 * (s + b) / s**2) if s > 0 else None
    return {
        "window_s": [float(gate.t_floor_s - fwhm_s), float(gate.t_floor_s + fwhm_s)],
        "floor_photons_in_window_per_shot": s,
        "other_photons_in_window_per_shot": b,
        "snr_criterion": DETECTION_SNR,
        "shots_needed": n_needed,
    }


def budget_json(scene, res: ProfilerResults) -> dict[str, Any]:
    """The photon budget as plain JSON-able data, every factor with its log."""
    b = res["budget"]
    gate = res["gate"]

    def terms(log_terms: dict[str, float]) -> dict[str, Any]:
        return {
            k: {"ln": v, "log10": v / math.log(10.0), "value": math.exp(v) if v > -745 else 0.0}
            for k, v in log_terms.items()
        }

    ideal = profiler.ideal_times(scene, [scene.seabed.depth_m])
    hist = {}
    centres = 0.5 * (gate.edges_s[1:] + gate.edges_s[:-1])
    fwhm = scene.system.pulse_fwhm_s
    floor_win = np.abs(centres - gate.t_floor_s) <= fwhm
    for n_shots, counts in res["histograms"].items():
        hist[str(n_shots)] = {
            "total_counts": int(counts.sum()),
            "expected_total": float(n_shots * res["expected"]["total"].sum()),
            "floor_window_counts": int(counts[floor_win].sum()),
            "expected_floor_window": float(n_shots * res["expected"]["total"][floor_win].sum()),
        }
    return {
        "scene": scene.scene.name,
        "altitude_m": scene.profiler.altitude_m,
        "depth_m": scene.seabed.depth_m,
        "units": "expected photoelectrons per shot at the detector output",
        "surface": {
            "photons_per_shot": b.surface_photons,
            "ln_photons": b.surface_log_photons,
            "terms": terms(b.surface_log_terms),
        },
        "floor": {
            "photons_per_shot": b.floor_photons,
            "ln_photons": b.floor_log_photons,
            "terms": terms(b.floor_log_terms),
        },
        "water_column": {"photons_per_shot": gate.column_photons},
        "background": {
            "solar_rate_hz": le.solar_background_rate_hz(scene, scene.profiler.altitude_m),
            "dark_rate_hz": scene.system.dark_count_rate_hz,
            "counts_per_gate": gate.background_rate_hz * gate.duration_s,
            "gate_s": [float(gate.edges_s[0]), float(gate.edges_s[-1])],
        },
        "ideal_measurement": {
            "t_surface_s": float(ideal["t_surface_s"][0]),
            "t_floor_s": float(ideal["t_floor_s"][0]),
            "surface_range_m": float(ideal["surface_range_m"][0]),
            "depth_from_tof_m": float(ideal["depth_from_tof_m"][0]),
            "depth_if_phase_index_m": float(ideal["depth_if_phase_index_m"][0]),
        },
        "floor_detection": _floor_detection(res, fwhm),
        "flags": {
            "surface_pileup": bool(b.surface_photons > 1.0),
            "note": "surface_pileup: more than one photoelectron per shot from the surface; a "
            "single-photon detector with dead time would under-count it (not modelled here).",
        },
        "histograms": hist,
    }


def _save(fig, path: Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def _fig14(res: ProfilerResults, path: Path) -> None:
    tp = res["transmittance"]
    fig, ax = plt.subplots(figsize=(7, 4.2))
    ax.semilogy(tp.path_m, np.exp(tp.log_transmittance), "b", label="one way")
    ax.semilogy(
        tp.path_m, np.exp(2 * tp.log_transmittance), "r--", label="two way (no target reflectance)"
    )
    ax.axvline(tp.altitude_m, color="0.5", lw=0.8)
    ax.text(tp.altitude_m, ax.get_ylim()[1], " water surface", va="top", fontsize=8)
    ax.set_xlabel("distance along the beam from the instrument (m)")
    ax.set_ylabel("transmittance")
    ax.set_title("Fig. 14: transmittance of the profiling bathymeter")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    _save(fig, path)


def _fig15(res: ProfilerResults, path: Path) -> None:
    sw = res["sweep"]
    fig, ax = plt.subplots(figsize=(7, 4.2))
    ax.loglog(sw["depth_m"], sw["surface"], "b", label="water surface (facets + whitecaps)")
    ax.loglog(sw["depth_m"], sw["floor"], "r", label="floor (Lambertian)")
    if np.any(sw["column"] > 0):
        ax.loglog(sw["depth_m"], sw["column"], "g", label="water column above the floor")
    ax.set_xlabel("water depth (m)")
    ax.set_ylabel("expected photoelectrons per shot")
    ax.set_title("Fig. 15: photons from the water surface and the floor")
    ax.legend()
    ax.grid(True, which="both", alpha=0.3)
    _save(fig, path)


def _fig16(scene, res: ProfilerResults, path: Path) -> None:
    ideal = res["ideal"]
    gate = res["gate"]
    exp = res["expected"]
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    centres_ns = 1e9 * 0.5 * (gate.edges_s[1:] + gate.edges_s[:-1])
    a1.semilogy(centres_ns, np.maximum(exp["total"], 1e-12), "k", label="expected, per shot")
    a1.axvline(1e9 * gate.t_surface_s, color="b", ls=":", label="surface time of flight")
    a1.axvline(1e9 * gate.t_floor_s, color="r", ls=":", label="floor time of flight")
    a1.set_xlabel("time after the shot (ns)")
    a1.set_ylabel(f"photoelectrons per {1e9 * scene.profiler.bin_width_s:g} ns bin")
    a1.set_title(f"Ideal return at {scene.seabed.depth_m:g} m depth")
    a1.legend(fontsize=8)
    d = ideal["depth_m"]
    a2.plot(
        d,
        1e9 * (ideal["t_floor_s"] - ideal["t_surface_s"]),
        "r",
        label="floor − surface time of flight",
    )
    a2.set_xlabel("true depth (m)")
    a2.set_ylabel("time of flight difference (ns)")
    a2.set_title(
        f"surface range {ideal['surface_range_m'][0]:.3f} m "
        f"(ToF {1e9 * ideal['t_surface_s'][0]:.2f} ns)"
    )
    b2 = a2.twinx()
    b2.plot(
        d,
        100 * (ideal["depth_if_phase_index_m"] / d - 1),
        "m--",
        label="depth error if the phase index sets travel time",
    )
    b2.plot(d, 100 * (ideal["depth_from_tof_m"] / d - 1), "k:", label="depth error, group index")
    b2.set_ylabel("retrieved depth error (%)")
    # float round-off (1e-13 %) would otherwise fill the axis when both indices are equal
    err_max = float(np.max(np.abs(100 * (ideal["depth_if_phase_index_m"] / d - 1))))
    b2.set_ylim(-max(0.5, 1.2 * err_max), max(2.0, 1.2 * err_max))
    lines = a2.get_legend_handles_labels()
    lines2 = b2.get_legend_handles_labels()
    a2.legend(lines[0] + lines2[0], lines[1] + lines2[1], fontsize=8, loc="upper left")
    fig.suptitle("Fig. 16: ideal measurements of the bathymeter")
    fig.tight_layout()
    _save(fig, path)


def _fig17(scene, res: ProfilerResults, path: Path) -> None:
    gate = res["gate"]
    hists = res["histograms"]
    n = len(hists)
    fig, axes = plt.subplots(n, 1, figsize=(8, 1.9 * n + 0.6), sharex=True, squeeze=False)
    centres_ns = 1e9 * 0.5 * (gate.edges_s[1:] + gate.edges_s[:-1])
    for ax, (n_shots, counts) in zip(axes[:, 0], hists.items(), strict=True):
        ax.step(centres_ns, counts, where="mid", color="k", lw=0.8)
        ax.plot(centres_ns, n_shots * res["expected"]["total"], "c", lw=0.8, alpha=0.8)
        ax.axvline(1e9 * gate.t_floor_s, color="r", ls=":", lw=0.8)
        ax.set_yscale("symlog", linthresh=1.0)
        ax.set_ylim(bottom=0.0)
        ax.set_ylabel("counts")
        ax.text(
            0.99,
            0.85,
            f"{n_shots} shot{'s' if n_shots > 1 else ''}",
            transform=ax.transAxes,
            ha="right",
            fontsize=9,
        )
    axes[-1, 0].set_xlabel("time after the shot (ns); red: floor time of flight")
    fig.suptitle(
        f"Fig. 17: photon histograms, {scene.seabed.depth_m:g} m depth, "
        "solar background and dark counts"
    )
    fig.tight_layout()
    _save(fig, path)


def write_report(scene, res: ProfilerResults, out_dir: str | Path) -> dict[str, Path]:
    """Write the four figures (PNG) and ``photon_budget.json`` into ``out_dir``.

    Returns
    -------
    dict of str to Path
        The files written.
    """
    out = Path(out_dir)  # made by the first atomic write
    files = {
        "fig14": out / "fig14_transmittance.png",
        "fig15": out / "fig15_photons_vs_depth.png",
        "fig16": out / "fig16_ideal_measurements.png",
        "fig17": out / "fig17_photon_histograms.png",
        "budget": out / "photon_budget.json",
    }
    _fig14(res, files["fig14"])
    _fig15(res, files["fig15"])
    _fig16(scene, res, files["fig16"])
    _fig17(scene, res, files["fig17"])
    write_json(files["budget"], budget_json(scene, res))
    return files
