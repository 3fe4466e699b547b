"""How many coverage floors a TPU exactly right would miss, its shared terms drawn once per scene.

:mod:`pipeline.suite.chance` reads the floors against independent draws, the most favourable
case. The TPU's own terms say which of its errors are shared
(:mod:`pipeline.uncertainty.tpu`): the navigation (GNSS, Gauss-Markov over 60 s), the attitude
and heading (INS, 10 s), the forward-scattering correction and the water's temperature and
salinity (one water per survey) move every sounding of a scene's 2-3 s line together. A
stratum of thousands of points from a few scenes is then a few draws of those, not thousands.

This module takes the TPU's terms as the truth's model and simulates the suite's coverage:
for each replicate, every scene draws one standard normal per shared term
(:data:`SHARED_TERMS`) and every point one per other term; a point's simulated error is
``sum_k t_k xi_k`` over its signed one-sigma depth terms ``t_k`` (``tpu_term_*`` of
``evaluation_points.npz``), judged against its own ``sqrt(sum_k t_k^2)``. The strata and floor
bands are the report's (:func:`pipeline.suite.strata.stratum_windows`,
:data:`pipeline.suite.chance.COVERAGE_FLOORS`); the count of failing strata over the
replicates is what an exactly right TPU would show on these scenes. Per stratum, the
replicates' coverages give the range (2.5-97.5 %) an exactly right TPU's coverage falls in 95 %
of the time on these scenes: an observed coverage outside it (:func:`beyond_chance`) is a
miscalibration the shared draws do not explain, an observed one inside it is not evidence of one
(a predictive check, as in Gelman et al., *Bayesian Data Analysis*, ch. 6).

Model choices: terms not named shared are independent per point (the surface-fit terms are
shared over a fit's neighbourhood, so this still leans favourable); the lines are short against
the navigation's correlation times, so one draw per scene.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from pipeline.suite.chance import COVERAGE_FLOORS
from pipeline.suite.strata import Pool, stratum_windows, tpu_window_mask

__all__ = ["SHARED_TERMS", "beyond_chance", "simulated_tpu_failures"]

#: TPU terms shared by every sounding of a suite scene (one draw per scene)
SHARED_TERMS = (
    "navigation",
    "attitude_x",
    "attitude_y",
    "heading",
    "forward_scatter",
    "temperature",
    "salinity",
)
_PREFIX = "tpu_term_"


def _scene_terms(arrays: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """``(shared, own)``: the scene's signed depth terms, ``(n, n_shared)`` and ``(n, n_own)``."""
    names = sorted(k[len(_PREFIX) :] for k in arrays if k.startswith(_PREFIX))
    n = arrays["tpu_true_depth_m"].size
    shared = [arrays[_PREFIX + k] for k in names if k in SHARED_TERMS]
    own = [arrays[_PREFIX + k] for k in names if k not in SHARED_TERMS]
    as_cols = lambda cols: np.column_stack(cols) if cols else np.zeros((n, 0))  # noqa: E731
    return as_cols(shared), as_cols(own)


def simulated_tpu_failures(
    pool: Pool, rows: list[dict[str, Any]], half: str, n_rep: int = 200, seed: int = 0
) -> dict[str, dict[str, Any]]:
    """Failing strata of an exactly right TPU, per TPU floor, over ``n_rep`` simulated suites.

    Parameters
    ----------
    pool : Pool
        :func:`pipeline.suite.strata.pool_rows` of ``rows``.
    rows : list of dict
        :func:`pipeline.suite.run.collect` rows (their ``arrays`` hold the terms).
    half : {"tuning", "heldout"}
    n_rep : int
        Simulated suites.
    seed : int

    Returns
    -------
    dict
        Per floor (``tpu68``, ``tpu95``): ``mean``, ``p10``, ``p90`` of the number of failing
        strata, ``strata`` (how many were judged) and ``ranges``: per judged stratum
        ``(dimension, label)``, the ``(2.5 %, 97.5 %)`` quantiles of its simulated coverage
        (the coverage an exactly right TPU gives that stratum 95 % of the time: an observed
        coverage outside it is beyond chance, :func:`beyond_chance`).
    """
    rng = np.random.default_rng(seed)
    windows = [w for w in stratum_windows(pool) if w["in_floor_window"] and w["half"] == half]
    # per scene: its points' window masks (one per distinct depth window) and terms
    depths = sorted({w["depth"] for w in windows})
    scenes = []
    for i, row in enumerate(rows):
        shared, own = _scene_terms(row["arrays"])
        sigma = np.sqrt(np.sum(shared**2, axis=1) + np.sum(own**2, axis=1))
        masks = {d: tpu_window_mask(pool, i, d) & (sigma > 0) for d in depths}
        scenes.append((shared, own, sigma, masks))
    floors = {k: v for k, v in COVERAGE_FLOORS.items() if v[0] == "tpu"}
    # simulated coverage per floor, replicate and window (NaN: too few points to judge)
    cov = {k: np.full((n_rep, len(windows)), np.nan) for k in floors}
    for r in range(n_rep):
        # within counts per scene and window: (n, k68, k95)
        tally = {}
        for i, (shared, own, sigma, masks) in enumerate(scenes):
            e = shared @ rng.standard_normal(shared.shape[1])
            e = e + np.sum(own * rng.standard_normal(own.shape), axis=1)
            z = np.abs(e) / np.where(sigma > 0, sigma, 1.0)
            for d, m in masks.items():
                tally[i, d] = (int(m.sum()), int(np.sum(z[m] <= 1.0)), int(np.sum(z[m] <= 1.96)))
        for j, w in enumerate(windows):
            tot = np.zeros(3, dtype=np.int64)
            for i in np.flatnonzero(w["runs"]):
                tot += tally[i, w["depth"]]
            for name, (_, key, _, _, _, min_n) in floors.items():
                if tot[0] >= min_n:
                    cov[name][r, j] = tot[1 if key == "cov68" else 2] / tot[0]
    out: dict[str, dict[str, Any]] = {}
    for name, (_, _, _, lo, hi, _) in floors.items():
        c = cov[name]
        judged = ~np.isnan(c[0])  # a window's points are the same in every replicate
        fails = np.sum(((c < lo) | (c > hi)) & judged, axis=1)
        out[name] = {
            "mean": float(fails.mean()),
            "p10": float(np.percentile(fails, 10)),
            "p90": float(np.percentile(fails, 90)),
            "strata": int(judged.sum()),
            "ranges": {
                (w["dimension"], w["label"]): tuple(
                    float(q) for q in np.percentile(c[:, j], [2.5, 97.5])
                )
                for j, w in enumerate(windows)
                if judged[j]
            },
        }
    return out


def beyond_chance(coverage: float | None, rng: tuple[float, float] | None) -> str:
    """``"low"`` / ``"high"`` where ``coverage`` lies below / above the range ``rng``, else ``""``.

    ``rng``: a stratum's :func:`simulated_tpu_failures` ``ranges`` entry (None: not judged).
    """
    if coverage is None or rng is None:
        return ""
    return "low" if coverage < rng[0] else "high" if coverage > rng[1] else ""
