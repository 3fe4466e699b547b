"""Support of ``bathy stress`` (:mod:`pipeline.stress`).

The base scenes, the outputs read back and checked finite, the expectation checks, and a TOML
writer for the bad-input cases.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["BASES", "CHECKS", "Outputs", "read_outputs", "with_overrides", "to_toml"]

#: The full-waveform base: palmer_survey.toml (data_synthetic/scenes) on one 40 m line at
#: 2 kHz: ~1300 pulses over water 2-6 m deep and land west of x = -21 m, ~2 s.
PALMER_BASE: dict[str, Any] = {
    "scene": {"name": "stress", "seed": 7, "preset": "topobathy_full_waveform"},
    "scanner": {"prf_hz": 2000.0, "scan_rate_hz": 20.0},
    "flight": {
        "altitude_m": 400.0,
        "speed_m_s": 60.0,
        "heading_deg": 0.0,
        "area_m": [0.0, 40.0, 0.0, 40.0],
        "n_lines": 1,
        "run_in_m": 0.0,
    },
    "atmosphere": {"extinction_per_m": 1.5e-4},
    "water": {"extinction_per_m": 0.15, "backscatter_180_per_m_sr": 2.0e-3, "wind_speed_m_s": 5.0},
    "water_surface": {"kind": "flat"},
    "seabed": {
        "kind": "plane",
        "depth_m": 2.0,
        "slope_deg": 5.33,
        "aspect_deg": 90.0,
        "reflectance": 0.2,
        "roughness_rms_m": 0.2,
        "roughness_correlation_m": 8.0,
    },
    "background": {"solar_irradiance_w_m2_nm": 1.5},
    "detector": {"window_s": 3.5e-7},
    "process": {
        "grid_resolution_m": 5.0,
        "posterior_pulses_per_km2": 0.0,
        "posterior_min_pulses": 0,
    },
}

#: The photon-counting base: photon_profiler.toml (one nadir beamlet of the photon_counting
#: preset) on a 12 m line over a 2 m seabed, 8 kHz, 100-shot windows: 1600 shots.
PHOTON_BASE: dict[str, Any] = {
    "scene": {"name": "stress_photon", "seed": 11, "preset": "photon_counting"},
    "scanner": {"kind": "profiler", "prf_hz": 8000.0},
    "flight": {
        "altitude_m": 500.0,
        "speed_m_s": 60.0,
        "heading_deg": 0.0,
        "area_m": [-1.0, 1.0, 0.0, 12.0],
        "n_lines": 1,
    },
    "atmosphere": {"extinction_per_m": 1.5e-4},
    "water": {"extinction_per_m": 0.12, "backscatter_180_per_m_sr": 1.5e-3, "wind_speed_m_s": 4.0},
    "seabed": {"kind": "plane", "depth_m": 2.0, "reflectance": 0.25},
    "background": {"solar_irradiance_w_m2_nm": 1.5},
    "process": {
        "grid_resolution_m": 2.0,
        "photon_detect": {"shots_per_window": 100, "bin_m": 0.1},
        "posterior_pulses_per_km2": 0.0,
        "posterior_min_pulses": 0,
    },
}

BASES = {"palmer": PALMER_BASE, "photon": PHOTON_BASE}


def with_overrides(base: str, name: str, overrides) -> dict[str, Any]:
    """A copy of base scene ``base`` named ``name``, with the dotted keys ``overrides`` set."""
    data = copy.deepcopy(BASES[base])
    data["scene"]["name"] = name
    for key, value in overrides:
        node = data
        *parents, leaf = key.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = copy.deepcopy(value)
    return data


def to_toml(data: dict[str, Any]) -> str:
    """``data`` (nested tables of numbers, strings, booleans and flat lists) as TOML text."""

    def value(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, str):
            return json.dumps(v)
        if isinstance(v, list | tuple):
            return "[" + ", ".join(value(x) for x in v) + "]"
        if isinstance(v, float) and not math.isfinite(v):
            return {True: "nan"}.get(math.isnan(v), "inf" if v > 0 else "-inf")
        return repr(v)

    lines: list[str] = []

    def table(node: dict[str, Any], prefix: str) -> None:
        leaves = {k: v for k, v in node.items() if not isinstance(v, dict)}
        if prefix and leaves:
            lines.append(f"[{prefix}]")
        lines.extend(f"{k} = {value(v)}" for k, v in leaves.items())
        for k, v in node.items():
            if isinstance(v, dict):
                table(v, f"{prefix}.{k}" if prefix else k)

    table(data, "")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------
# outputs read back, and checked finite


@dataclass(frozen=True)
class Outputs:
    """A run's outputs read back: ``evaluation.json``, ``points.laz``, ``grid.tif`` bands."""

    evaluation: dict[str, Any]
    las: Any  # laspy.LasData
    grid: dict[str, np.ndarray]  # band name -> values, NaN where nodata


def _reject_constant(name: str):
    raise ValueError(f"non-finite JSON number {name}")


def _json_nonfinite(node: Any, where: str = "") -> list[str]:
    """Paths of the numbers in a parsed JSON tree that are not finite (null is allowed)."""
    if isinstance(node, dict):
        return [p for k, v in node.items() for p in _json_nonfinite(v, f"{where}.{k}")]
    if isinstance(node, list):
        return [p for i, v in enumerate(node) for p in _json_nonfinite(v, f"{where}[{i}]")]
    if isinstance(node, float) and not math.isfinite(node):
        return [where]
    return []


def read_outputs(out: Path) -> tuple[Outputs, list[str]]:
    """Read ``evaluation.json``, ``points.laz`` and ``grid.tif``; list what is not finite."""
    import laspy
    import rasterio

    bad: list[str] = []
    docs = {}
    for name in ("evaluation.json", "manifest.json"):
        text = (out / name).read_text()
        docs[name] = json.loads(text, parse_constant=_reject_constant)
        bad += [f"{name}{p}" for p in _json_nonfinite(docs[name])[:3]]
    las = laspy.read(str(out / "points.laz"))
    fields = {"x": las.x, "y": las.y, "z": las.z}
    for name in ("depth_m", "uncertainty_v_m", "uncertainty_h_m", "confidence"):
        fields[name] = las[name]
    for name, values in fields.items():
        n_bad = int(np.count_nonzero(~np.isfinite(np.asarray(values, dtype=np.float64))))
        if n_bad:
            bad.append(f"points.laz {name}: {n_bad} not finite")
    grid = {}
    with rasterio.open(out / "grid.tif") as src:
        for i in range(1, src.count + 1):
            a = src.read(i).astype(np.float64)
            valid = a != src.nodata
            if not np.all(np.isfinite(a[valid])):
                bad.append(f"grid.tif {src.descriptions[i - 1]}: valid cell not finite")
            grid[src.descriptions[i - 1]] = np.where(valid, a, np.nan)
    return Outputs(docs["evaluation.json"], las, grid), bad


# ---------------------------------------------------------------------------------------------
# expectations: each returns a failure message, or "" when it holds


def _classes(o: Outputs) -> np.ndarray:
    return np.asarray(o.las.classification, dtype=np.int64)


def _has_class(o: Outputs, arg: str) -> str:
    n = int(np.count_nonzero(_classes(o) == int(arg)))
    return "" if n else f"no class-{arg} point"


def _no_class(o: Outputs, arg: str) -> str:
    n = int(np.count_nonzero(_classes(o) == int(arg)))
    return f"{n} class-{arg} points" if n else ""


def _subray_flag(o: Outputs, arg: str) -> str:
    n = (o.evaluation.get("subray_flags") or {}).get(arg, 0)
    return "" if n > 0 else f"subray flag {arg} not counted"


def _receiver_flag(o: Outputs, arg: str) -> str:
    n = (o.evaluation.get("receiver_pulse_flags") or {}).get(arg, 0)
    return "" if n > 0 else f"receiver pulse flag {arg} not counted"


def _detector_flag(o: Outputs, arg: str) -> str:
    from pipeline.process.returns import DetectorFlag

    bit = int(DetectorFlag[arg])
    flags = np.asarray(o.las["detector_flags"], dtype=np.int64)
    return "" if np.any(flags & bit) else f"no point carries detector flag {arg}"


def _point_flag(o: Outputs, arg: str) -> str:
    from pipeline.process.returns import PointFlag

    bit = int(PointFlag[arg])
    flags = np.asarray(o.las["process_flags"], dtype=np.int64)
    return "" if np.any(flags & bit) else f"no point carries process flag {arg}"


def _no_detections(o: Outputs, arg: str) -> str:
    n = len(o.las.points)
    frac = o.evaluation.get("bottom_detected_fraction")
    if n or frac:
        return f"{n} points, bottom detected fraction {frac}"
    return ""


def _depths(o: Outputs, arg: str) -> tuple[np.ndarray, str, float]:
    cls, _, limit = arg.partition(":")
    return (
        np.asarray(o.las["depth_m"], dtype=np.float64)[_classes(o) == int(cls)],
        cls,
        float(limit),
    )


def _min_depth(o: Outputs, arg: str) -> str:
    d, cls, limit = _depths(o, arg)
    n = int(np.count_nonzero(d < limit))
    return f"{n} class-{cls} points shallower than {limit:g} m (min {d.min():.3f} m)" if n else ""


def _max_depth(o: Outputs, arg: str) -> str:
    d, cls, limit = _depths(o, arg)
    n = int(np.count_nonzero(d > limit))
    return f"{n} class-{cls} points deeper than {limit:g} m (max {d.max():.3f} m)" if n else ""


def _min_points(o: Outputs, arg: str) -> str:
    n = len(o.las.points)
    return "" if n >= int(arg) else f"{n} points, expected at least {arg}"


def _world_offset(o: Outputs, arg: str) -> str:
    # the LAS stores world coordinates: local (tens of metres) plus the frame origin
    e = np.asarray(o.las.x, dtype=np.float64) - float(arg)
    n = np.asarray(o.las.y, dtype=np.float64) - float(arg)
    far = int(np.count_nonzero((np.abs(e) > 1e4) | (np.abs(n) > 1e4)))
    return f"{far} points more than 10 km from the origin {arg}" if far else ""


def _grid_cells(o: Outputs, arg: str) -> str:
    n = int(np.count_nonzero(np.isfinite(o.grid["depth_m"])))
    return "" if n >= int(arg) else f"{n} valid grid cells, expected at least {arg}"


def _datum_error(o: Outputs, arg: str) -> str:
    d = o.evaluation["datum"]
    err = d["water_level_m"] - d["true_mean_water_level_m"]
    return f"grid datum {err:+.3f} m off the true mean water level" if abs(err) > float(arg) else ""


def _datum_source(o: Outputs, arg: str) -> str:
    src = o.evaluation["datum"].get("source")
    return "" if src == arg else f"grid datum source {src!r}, expected {arg!r}"


def _rmse(o: Outputs, arg: str) -> str:
    st = (o.evaluation.get("error") or {}).get("points") or {}
    rmse = st.get("rmse_m")
    if rmse is None:
        return "no point compared with the truth"
    return f"points' RMSE against the truth {rmse:.3f} m > {arg} m" if rmse > float(arg) else ""


def _max_error(o: Outputs, arg: str) -> str:
    # the trust issue's "no class-40 point more than 1 m off": a survey may abstain (no class-40
    # point at all) where its data cannot measure a depth, but never claim a wrong one
    st = (o.evaluation.get("error") or {}).get("points") or {}
    worst = st.get("max_abs_m")
    if worst is None or worst <= float(arg):
        return ""
    return f"a class-40 point {worst:.3f} m off the truth (> {arg} m)"


def _only_noise(o: Outputs, arg: str) -> str:
    # noise alone may cross a per-sample threshold now and then (a constant false-alarm rate),
    # but what it gives must be classed noise (7 low, 18 high), never a surface, bottom or land
    c = _classes(o)
    bad = c[(c != 7) & (c != 18)]
    return f"{bad.size} non-noise points (classes {sorted(set(bad.tolist()))})" if bad.size else ""


def _posteriors(o: Outputs, arg: str) -> str:
    post = o.evaluation.get("posterior_against_truth") or {}
    return "" if (post.get("n") or 0) >= int(arg) else f"posteriors: {post.get('n')}"


#: Expectation name -> check of the outputs (the argument after ":" as a string).
CHECKS: dict[str, Callable[[Outputs, str], str]] = {
    "class": _has_class,
    "no_class": _no_class,
    "subray_flag": _subray_flag,
    "receiver_flag": _receiver_flag,
    "detector_flag": _detector_flag,
    "point_flag": _point_flag,
    "no_detections": _no_detections,
    "min_depth": _min_depth,
    "max_depth": _max_depth,
    "min_points": _min_points,
    "world_offset": _world_offset,
    "grid_cells": _grid_cells,
    "datum_error": _datum_error,
    "datum_source": _datum_source,
    "rmse": _rmse,
    "max_error": _max_error,
    "only_noise": _only_noise,
    "posteriors": _posteriors,
}
