"""Pool the suite's points into strata and compute each stratum's figures, per half.

A stratum is a scene condition (wind band, surface kind, attenuation band, slope band,
roughness, scanner, receiver) or a depth band of the points. Its figures pool every point of
every scene of one half that falls in it, so a stratum's RMSE is over its points, not a mean of
the scenes' RMSEs.

**The depth window of the floors**: points whose *true* depth lies in
``[1 m, 0.8 D_ext]``. ``D_ext``, the scene's extinction depth, comes from the run's own
outputs where it can: the median depth of its class-45 (no-bottom-found-at) points, each placed
by processing at its pulse's own detection limit (:mod:`pipeline.process.detection_limit`),
those at least as deep as 95 % of its soundings (:mod:`pipeline.process.extinction`: a
shore's merged bottoms are not the light giving out), when a full-waveform run has at least
:data:`MIN_NO_BOTTOM` of them. Other runs (photon
counting places class 45 at the end of its range gate, not at a detection limit; a shallow
full-waveform scene finds the bottom everywhere) fall back to a
planning value from the scene's beam attenuation ``c``: ``4.5 / c`` (the generator's guess,
:mod:`pipeline.suite.generate`), which is a truth-side value and flagged as such
(``d_ext_source``). Depth bands report points shallower than ``0.8 D_ext`` only; the points
deeper than that are the ``past 0.8 D_ext`` stratum.

**Cube detection** (IHO S-44 features): the run's own ``evaluation.json`` ``features``
(:mod:`pipeline.evaluate_features`): a cube of side ``s`` is *detected* when a seabed sounding
(class 40 or 43) inside its footprint has a depth error below ``s / 2`` (nearer its top than
the seabed around it) or the grid cell at its centre stands above its neighbours by ``s / 2``;
its *density* is the soundings per m² in its footprint grown by 1 m on each side (a 5 m disc,
used before, counted a profiler's line passing metres beside the cube as density on it); its
depth is the true depth of the seabed at its base. Runs from before that entry: the same
point rule and density from ``evaluation_points.npz`` (no grid, no class 43).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from pipeline.process.extinction import MIN_CLASS45, extinction_depth

__all__ = [
    "MIN_NO_BOTTOM",
    "DEPTH_BANDS_M",
    "stratum_windows",
    "tpu_window_mask",
    "extinction_depth_m",
    "cube_detections",
    "Pool",
    "pool_rows",
    "stratum_figures",
    "STRATA",
    "all_strata",
    "shallowest_unbiased_m",
]

#: class-45 points a run needs for its own D_ext (:data:`pipeline.process.extinction.MIN_CLASS45`)
MIN_NO_BOTTOM = MIN_CLASS45
#: depth bands of the points (m, lower edge inclusive)
DEPTH_BANDS_M = (0.1, 1.0, 3.0, 6.0, 12.0, 25.0, math.inf)
#: finer bands of the shallowest-unbiased-depth search (m)
SHALLOW_BANDS_M = (0.1, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0, 3.0, 5.0)
_FLOOR_MIN_DEPTH_M = 1.0
_FLOOR_EXT_FRACTION = 0.8
#: a cube's density counts the soundings in its footprint grown by this on each side
_CUBE_MARGIN_M = 1.0
#: runs without ``features``: the base depth from the soundings within this of the centre
_CUBE_DEPTH_RADIUS_M = 5.0
_GROUPS = ("pt", "tpu", "post", "cell", "rej")
#: the rejected soundings' arrays, empty for runs from before processing rejected any
_REJ_EMPTY = {
    "rej_true_depth_m": np.float64,
    "rej_error_m": np.float64,
    "rej_tvu": np.bool_,
    "rej_surface": np.bool_,
}


def extinction_depth_m(
    nb_depth_m: np.ndarray,
    attenuation_per_m: float,
    receiver: str = "full_waveform",
    class40_depth_m: np.ndarray | None = None,
) -> tuple[float, str]:
    """The scene's extinction depth and where it comes from (see the module docstring).

    A full-waveform run's own (:func:`pipeline.process.extinction.extinction_depth` of its
    class-45 and class-40 depths) where it reached one. A photon-counting run takes the
    planning value: its class-45 points sit at its windows' detection limits
    (:mod:`pipeline.process.photon_limit`) only since that limit was added, and the suite keeps
    the planning value its baseline used, so figures stay comparable.
    """
    if receiver == "full_waveform":
        d40 = np.zeros(0) if class40_depth_m is None else class40_depth_m
        ext, src, _ = extinction_depth(nb_depth_m, d40)
        if ext is not None:
            return ext, src
    return 4.5 / attenuation_per_m, "planning_4.5_over_c"


def cube_detections(
    arrays: dict[str, np.ndarray], cubes, evaluation: dict | None = None
) -> list[dict[str, Any]]:
    """Per cube ``(x_m, y_m, size_m)``: density, points on it, how detected, base depth.

    Parameters
    ----------
    arrays : dict
        A run's ``evaluation_points.npz`` arrays.
    cubes : sequence of (x_m, y_m, size_m)
    evaluation : dict, optional
        The run's ``evaluation.json``; its ``features`` entry is used when present.

    Returns
    -------
    list of dict
        ``size_m``, ``density_per_m2``, ``n_on_top``, ``detected``, ``by_points``,
        ``by_grid``, ``by_class43`` (bools), ``depth_m`` (true depth at the cube's base; NaN
        when unknown).
    """
    feats = ((evaluation or {}).get("features") or {}).get("cubes")
    if feats is not None:
        return [
            {
                "size_m": float(c["size_m"]),
                "density_per_m2": float(c["density_per_m2"]),
                "n_on_top": int(c["points_on_top"]),
                "detected": bool(c["detected"]),
                "by_points": c["points_on_top"] > 0,
                "by_grid": bool(c["grid_shows"]),
                "by_class43": c["object_points"] > 0,
                "depth_m": float(c["base_depth_m"]),
            }
            for c in feats
        ]
    x, y, err = arrays["pt_x_m"], arrays["pt_y_m"], arrays["pt_error_m"]
    out = []
    for cx, cy, s in cubes:
        g = 0.5 * s + _CUBE_MARGIN_M
        box = (np.abs(x - cx) <= g) & (np.abs(y - cy) <= g)
        on = (np.abs(x - cx) <= 0.5 * s) & (np.abs(y - cy) <= 0.5 * s)
        # the base: the true depth of the soundings within 5 m, not on its top
        near = np.hypot(x - cx, y - cy) <= _CUBE_DEPTH_RADIUS_M
        around = arrays["pt_true_depth_m"][near & ~on]
        hit = bool(np.any(np.abs(err[on]) < 0.5 * s))
        out.append(
            {
                "size_m": float(s),
                "density_per_m2": float(box.sum() / (2.0 * g) ** 2),
                "n_on_top": int(on.sum()),
                "detected": hit,
                "by_points": hit,
                "by_grid": False,
                "by_class43": False,
                "depth_m": float(np.median(around)) if around.size else float("nan"),
            }
        )
    return out


@dataclass(frozen=True)
class Pool:
    """Every run's arrays concatenated, with the scene row of each element.

    ``arrays[name]`` is the concatenation; ``scene[group]`` the run index of each element of
    the group (``pt``, ``tpu``, ``post``, ``cell``); ``meta`` one dict per run (the draw, half,
    ``d_ext_m`` and ``d_ext_source``); ``cubes`` one dict per cube with its run index.
    """

    arrays: dict[str, np.ndarray]
    scene: dict[str, np.ndarray]
    meta: list[dict[str, Any]]
    cubes: list[dict[str, Any]]


def pool_rows(rows: list[dict[str, Any]]) -> Pool:
    """Pool :func:`pipeline.suite.run.collect` rows (see :class:`Pool`)."""
    meta, cubes = [], []
    parts: dict[str, list[np.ndarray]] = {}
    scene: dict[str, list[np.ndarray]] = {g: [] for g in _GROUPS}
    for i, row in enumerate(rows):
        d = row["draw"]
        a = {**{k: np.zeros(0, t) for k, t in _REJ_EMPTY.items()}, **row["arrays"]}
        # runs from before the THU search (pipeline.evaluate_thu): the strict error
        a.setdefault("pt_error_thu_m", a["pt_error_m"])
        d_ext, src = extinction_depth_m(
            a["nb_depth_m"], d.attenuation_per_m, d.receiver, a["pt_depth_m"]
        )
        # class-45 claims past the true seabed (runs from before nb_true_depth_m: None)
        past = None
        if "nb_true_depth_m" in a:
            past = int(np.count_nonzero(a["nb_depth_m"] > np.asarray(a["nb_true_depth_m"])))
        meta.append(
            {
                **d.to_dict(),
                "d_ext_m": d_ext,
                "d_ext_source": src,
                "class45_n": int(np.asarray(a["nb_depth_m"]).size),
                "class45_past_seabed": past,
            }
        )
        for name, v in a.items():
            if name not in ("nb_depth_m", "nb_true_depth_m"):
                parts.setdefault(name, []).append(np.asarray(v))
        for g in _GROUPS:
            n = a[f"{g}_true_depth_m"].size
            scene[g].append(np.full(n, i, dtype=np.int64))
        cubes += [{**c, "run": i} for c in cube_detections(a, d.cubes, row.get("evaluation"))]
    arrays = {k: np.concatenate(v) for k, v in parts.items()}
    return Pool(arrays, {g: np.concatenate(v) for g, v in scene.items()}, meta, cubes)


def _stats(e: np.ndarray) -> dict[str, float | int | None]:
    e = e[np.isfinite(e)]
    if not e.size:
        return {"n": 0, "bias_m": None, "rmse_m": None, "p95_m": None, "max_m": None}
    a = np.abs(e)
    return {
        "n": int(e.size),
        "bias_m": float(e.mean()),
        "rmse_m": float(np.sqrt(np.mean(e * e))),
        "p95_m": float(np.percentile(a, 95.0)),
        "max_m": float(a.max()),
    }


def _depth_ok(pool: Pool, group: str, lo_m: float, hi_frac: float, hi_m: float) -> np.ndarray:
    """Elements of ``group`` with true depth in ``[lo_m, min(hi_frac D_ext, hi_m))``."""
    d = pool.arrays[f"{group}_true_depth_m"]
    d_ext = np.array([m["d_ext_m"] for m in pool.meta])[pool.scene[group]]
    return (d >= lo_m) & (d < np.minimum(hi_frac * d_ext, hi_m))


def stratum_figures(pool: Pool, runs: np.ndarray, depth: tuple[float, float, float]) -> dict:
    """Figures of the points of ``runs`` (bool per run) in a depth window.

    Parameters
    ----------
    pool : Pool
    runs : (n_runs,) bool
        The stratum's scenes.
    depth : (lo_m, hi_fraction_of_D_ext, hi_m)
        True depth in ``[lo_m, min(hi_fraction D_ext, hi_m))``.

    Returns
    -------
    dict
        ``points`` and ``cells`` (:func:`_stats`: ``n``, ``bias_m``, ``rmse_m``, ``p95_m``,
        ``max_m``), ``n_over_1m`` (at the points' positions) and ``n_over_1m_thu`` (no seabed
        at their depth within their THU95: :mod:`pipeline.evaluate_thu`), ``tpu`` (``n``,
        ``cov68``, ``cov95``), ``posterior``
        (``n``, ``cov68``, ``cov95``, ``converged``), ``cubes`` (per size: ``n``,
        ``detected``, ``n_dense``, ``detected_dense``: cubes at density >= 1 per m²),
        ``rejected`` (``n``, ``over_1m``, ``good``: soundings processing rejected, by their
        true depth), ``scenes``.
    """
    a = pool.arrays
    sel = {g: runs[pool.scene[g]] & _depth_ok(pool, g, *depth) for g in _GROUPS}
    pts = a["pt_error_m"][sel["pt"]]
    out: dict[str, Any] = {"scenes": int(runs.sum()), "points": _stats(pts)}
    out["n_over_1m"] = int(np.sum(np.abs(pts) > 1.0))
    out["n_over_1m_thu"] = int(np.sum(np.abs(a["pt_error_thu_m"][sel["pt"]]) > 1.0))
    out["cells"] = _stats(a["cell_error_m"][sel["cell"]])
    z = np.abs(a["tpu_error_m"][sel["tpu"]]) / a["tpu_sigma_depth_m"][sel["tpu"]]
    z = z[np.isfinite(z)]
    out["tpu"] = {
        "n": int(z.size),
        "cov68": float(np.mean(z <= 1.0)) if z.size else None,
        "cov95": float(np.mean(z <= 1.96)) if z.size else None,
    }
    p = sel["post"]
    t = a["post_true_depth_m"][p]
    within = {q: (a[f"post_lo{q}_m"][p] <= t) & (t <= a[f"post_hi{q}_m"][p]) for q in ("68", "95")}
    out["posterior"] = {
        "n": int(p.sum()),
        "cov68": float(within["68"].mean()) if p.any() else None,
        "cov95": float(within["95"].mean()) if p.any() else None,
        "converged": float(a["post_converged"][p].mean()) if p.any() else None,
    }
    out["cubes"] = _cube_figures(pool, runs, depth)
    e = np.abs(a["rej_error_m"][sel["rej"]])
    # the soundings processing rejected (class 7, withheld): how many were gross errors and
    # how many good (|error| <= 0.5 m, the rejection's cost)
    out["rejected"] = {
        "n": int(e.size),
        "over_1m": int(np.sum(e > 1.0)),
        "good": int(np.sum(e <= 0.5)),
    }
    return out


def _cube_figures(pool: Pool, runs: np.ndarray, depth) -> dict[str, dict[str, int]]:
    lo, frac, hi = depth
    figs: dict[str, dict[str, int]] = {}
    for c in pool.cubes:
        d_ext = pool.meta[c["run"]]["d_ext_m"]
        if not runs[c["run"]] or not (lo <= c["depth_m"] < min(frac * d_ext, hi)):
            continue
        f = figs.setdefault(
            f"{c['size_m']:g}", dict.fromkeys(("n", "detected", "n_dense", "detected_dense"), 0)
        )
        dense = c["density_per_m2"] >= 1.0
        f["n"] += 1
        f["detected"] += int(c["detected"])
        f["n_dense"] += int(dense)
        f["detected_dense"] += int(dense and c["detected"])
    return figs


def _band(edges, v) -> str:
    """``"lo-hi"`` of the band holding ``v`` (lower edge inclusive; the last band also its top)."""
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        if lo <= v < hi or (hi == edges[-1] and v == hi):
            return f"{lo:g}-{hi:g}"
    return f"outside {edges[0]:g}-{edges[-1]:g}"


#: scene-level strata: (dimension, label of a run's meta)
STRATA: tuple[tuple[str, Callable[[dict], str]], ...] = (
    ("all", lambda m: "all"),
    ("wind m/s", lambda m: _band((0.0, 2.0, 5.0, 8.0, 12.0), m["wind_m_s"])),
    ("surface", lambda m: m["surface"]),
    ("c 1/m", lambda m: _band((0.05, 0.1, 0.2, 0.4, 0.8), m["attenuation_per_m"])),
    ("slope deg", lambda m: _band((0.0, 2.0, 8.0, 14.0, 20.0), m["slope_deg"])),
    ("roughness", lambda m: "rough" if m["roughness_rms_m"] > 0 else "smooth"),
    ("scanner", lambda m: m["scanner"]),
    ("receiver", lambda m: m["receiver"]),
)


def _windows(pool: Pool):
    """``(dimension, label, runs, depth, in_floor_window)`` of every stratum (halves pooled)."""
    window = (_FLOOR_MIN_DEPTH_M, _FLOOR_EXT_FRACTION, math.inf)
    for dim, fn in STRATA:
        labels = np.array([fn(m) for m in pool.meta])
        for lab in sorted(set(labels)):
            yield dim, lab, labels == lab, window, True
    every = np.ones(len(pool.meta), dtype=bool)
    for lo, hi in zip(DEPTH_BANDS_M[:-1], DEPTH_BANDS_M[1:], strict=True):
        yield "depth m", f"{lo:g}-{hi:g}", every, (lo, _FLOOR_EXT_FRACTION, hi), lo >= 1.0


def stratum_windows(pool: Pool) -> list[dict[str, Any]]:
    """Every stratum of :func:`all_strata` but ``past 0.8 D_ext``, one entry per half.

    Returns
    -------
    list of dict
        ``dimension``, ``label``, ``half``, ``runs`` ((n_runs,) bool: the stratum's scenes of
        that half), ``depth`` (the window of :func:`stratum_figures`), ``in_floor_window``.
    """
    halves = np.array([m["half"] for m in pool.meta])
    return [
        {"dimension": dim, "label": lab, "half": h, "runs": runs & (halves == h)}
        | {"depth": depth, "in_floor_window": in_window}
        for dim, lab, runs, depth, in_window in _windows(pool)
        for h in ("tuning", "heldout")
    ]


def tpu_window_mask(pool: Pool, run: int, depth: tuple[float, float, float]) -> np.ndarray:
    """Run ``run``'s TPU points (in its own order) whose true depth lies in the window ``depth``."""
    return _depth_ok(pool, "tpu", *depth)[pool.scene["tpu"] == run]


def all_strata(pool: Pool) -> list[dict[str, Any]]:
    """Every stratum's figures for both halves, in the floors' depth window.

    Scene strata (:data:`STRATA`) take the window ``[1 m, 0.8 D_ext)``; depth bands
    (:data:`DEPTH_BANDS_M`) take their band below ``0.8 D_ext``; ``past 0.8 D_ext`` takes the
    points deeper than that (no upper bound).

    Returns
    -------
    list of dict
        ``dimension``, ``label``, ``in_floor_window`` (bool), ``wind_max_m_s`` (largest wind
        of its scenes), and per half (``tuning``, ``heldout``) :func:`stratum_figures`.
    """
    halves = np.array([m["half"] for m in pool.meta])
    wind = np.array([m["wind_m_s"] for m in pool.meta])
    out = []

    def add(dim, label, runs, depth, in_window):
        row = {"dimension": dim, "label": label, "in_floor_window": in_window}
        row["wind_max_m_s"] = float(wind[runs].max()) if runs.any() else None
        for h in ("tuning", "heldout"):
            row[h] = stratum_figures(pool, runs & (halves == h), depth)
        out.append(row)

    for dim, lab, runs, depth, in_window in _windows(pool):
        add(dim, lab, runs, depth, in_window)
    every = np.ones(len(pool.meta), dtype=bool)
    add("depth m", "past 0.8 D_ext", every, (0.0, math.inf, math.inf), False)
    _past_only(pool, out[-1])
    return out


def _past_only(pool: Pool, row: dict) -> None:
    """Recompute the ``past 0.8 D_ext`` row on the points deeper than 0.8 D_ext alone."""
    halves = np.array([m["half"] for m in pool.meta])
    d_ext = np.array([m["d_ext_m"] for m in pool.meta])
    for h in ("tuning", "heldout"):
        runs = halves == h
        sel = runs[pool.scene["pt"]] & (
            pool.arrays["pt_true_depth_m"] >= _FLOOR_EXT_FRACTION * d_ext[pool.scene["pt"]]
        )
        e = pool.arrays["pt_error_m"][sel]
        row[h] = {
            "scenes": int(runs.sum()),
            "points": _stats(e),
            "n_over_1m": int(np.sum(np.abs(e) > 1.0)),
            "n_over_1m_thu": int(np.sum(np.abs(pool.arrays["pt_error_thu_m"][sel]) > 1.0)),
        }


def shallowest_unbiased_m(
    pool: Pool, receiver: str, wind_range: tuple[float, float], half: str, max_bias_m: float = 0.10
) -> dict[str, Any]:
    """The shallowest depth from which every shallow band down to 2 m has ``|bias| <= max``.

    Bands (:data:`SHALLOW_BANDS_M`) of at least 30 points, of one receiver, wind in
    ``wind_range`` (inclusive) and one half, below 0.8 D_ext; searched from the 1.5-2 m band
    upward. ``depth_m`` is the lower edge of the shallowest passing band (None when the
    1.5-2 m band fails or has too few points); ``bands`` lists every band's ``n`` and bias.
    """
    runs = np.array(
        [
            m["receiver"] == receiver
            and m["half"] == half
            and wind_range[0] <= m["wind_m_s"] <= wind_range[1]
            for m in pool.meta
        ]
    )
    bands = []
    edges = SHALLOW_BANDS_M
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = runs[pool.scene["pt"]] & _depth_ok(pool, "pt", lo, _FLOOR_EXT_FRACTION, hi)
        st = _stats(pool.arrays["pt_error_m"][sel])
        bands.append({"band": f"{lo:g}-{hi:g}", "lo_m": lo, "n": st["n"], "bias_m": st["bias_m"]})
    best = None
    for b in reversed([b for b in bands if b["lo_m"] < 2.0]):
        if b["n"] < 30:
            continue
        if abs(b["bias_m"]) > max_bias_m:
            break
        best = b["lo_m"]
    return {"depth_m": best, "bands": bands, "scenes": int(runs.sum())}
