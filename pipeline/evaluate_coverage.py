"""Coverage of the uncertainty against the truth: TPU intervals and posterior intervals.

Split from :mod:`pipeline.evaluate` (the only other module that meets the truth), whose error
conventions it keeps: ``error = depth_measured - depth_true``, positive when too deep.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from pipeline.evaluate import TruthFn, _json_number, point_errors_m, truth_at
from pipeline.process.returns import Points

__all__ = ["tpu_coverage", "posterior_coverage"]


def tpu_coverage(
    points: Points,
    sigma_m: Any,
    *,
    truth_depth_m: TruthFn,
    k: float = 1.96,
    ks: tuple[float, ...] = (1.0, 1.96),
    group: Any = None,
) -> dict[str, Any]:
    """How often the true depth lies within ``± k σ`` of the measured depth.

    Parameters
    ----------
    points : Points
        The points whose depth uncertainty is ``sigma_m`` (same order).
    sigma_m : (n,) array_like
        Propagated 1σ uncertainty of the *depth* (``PointTpu.sigma_depth_m``: the depth below
        the measured water surface at the measured position, which is what is compared),
        metres. An elevation sigma (``sigma_v_m``) also holds the navigation's vertical error,
        which cancels in the depth: its coverage is too high.
    truth_depth_m : callable
        True depth at local ``(x, y)``.
    k : float
        Coverage factor of the headline ``fraction_within`` (1.96: the 95 % interval of a
        normal error).
    ks : tuple of float
        Coverage factors of ``intervals`` (default the 68 % and 95 % intervals, k = 1, 1.96).
    group : (n,) array_like, optional
        Points sharing one measurement (a photon-counting window's shots) carry the same label;
        the standard errors then count groups, not points (cluster-robust). Default: every
        point is its own draw.

    Returns
    -------
    dict
        ``n``, ``n_groups``, ``k``, ``fraction_within`` and its ``standard_error``, the
        median ``|error| / sigma``, and ``intervals``: per coverage factor ``k``, the
        ``nominal`` normal coverage ``erf(k / sqrt 2)``, ``fraction_within`` and its binomial
        ``standard_error`` ``sqrt(p (1 - p) / n)`` (cluster-robust with ``group``).
    """
    sig = np.asarray(sigma_m, dtype=np.float64)
    err, _ = point_errors_m(points, truth_depth_m=truth_depth_m)
    ok = np.isfinite(err) & np.isfinite(sig) & (sig > 0)
    z = np.abs(err[ok]) / sig[ok]
    labels = np.arange(ok.sum()) if group is None else np.asarray(group).ravel()[ok]
    _, inv = np.unique(labels, return_inverse=True)
    n_groups = int(inv.max()) + 1 if z.size else 0

    def fraction(kk: float) -> tuple[float | None, float | None]:
        if not z.size:
            return None, None
        hit = (z <= kk).astype(np.float64)
        p = float(hit.mean())
        if group is None:
            se = math.sqrt(p * (1.0 - p) / z.size)
        else:  # ratio estimator over clusters
            resid = np.bincount(inv, weights=hit - p)
            se = math.sqrt(float(np.sum(resid**2)) * n_groups / max(n_groups - 1, 1)) / z.size
        return p, se

    head, head_se = fraction(k)
    intervals = []
    for kk in ks:
        p, se = fraction(kk)
        intervals.append(
            {
                "k": float(kk),
                "nominal": math.erf(kk / math.sqrt(2.0)),
                "fraction_within": p,
                "standard_error": se,
            }
        )
    return {
        "n": int(ok.sum()),
        "n_groups": n_groups,
        "k": k,
        "fraction_within": head,
        "standard_error": head_se,
        "median_abs_error_over_sigma": _json_number(float(np.median(z))) if z.size else None,
        "intervals": intervals,
    }


def posterior_coverage(posteriors, *, truth_depth_m: TruthFn) -> dict[str, Any]:
    """How often each sampled pulse's posterior intervals hold the true depth.

    Parameters
    ----------
    posteriors : SeabedPosteriors
        :func:`pipeline.uncertainty.seabed_posterior.seabed_posteriors` output (depth below the
        fitted surface; the truth is taken at the posterior median position).
    truth_depth_m : callable
        True depth at local ``(x, y)``.

    Returns
    -------
    dict
        ``n`` (pulses with a start), ``converged``, ``coverage_68`` / ``coverage_95`` with
        binomial standard errors (also for the converged pulses alone), the normalised
        errors' mean and spread, the median posterior sd and the median |error|, metres.
    """
    from pipeline.uncertainty.posterior import PosteriorFlag

    d = posteriors.depth_m
    started = (posteriors.flags & np.uint16(PosteriorFlag.NO_START)) == 0
    xy = posteriors.xyz_median_m[started]
    pid = getattr(posteriors, "pulse_id", None)
    truth = truth_at(truth_depth_m, xy[:, 0], xy[:, 1], None if pid is None else pid[started])
    sub = {k: v[started] for k, v in d.items()}
    conv = posteriors.converged[started]

    def cov(mask):
        n = int(mask.sum())
        if n == 0:
            return {"n": 0}
        out = {"n": n}
        for name, lo, hi in (("coverage_68", "lo68", "hi68"), ("coverage_95", "lo95", "hi95")):
            p = float(np.mean((sub[lo][mask] <= truth[mask]) & (truth[mask] <= sub[hi][mask])))
            out[name] = p
            out[name + "_standard_error"] = math.sqrt(p * (1.0 - p) / n)
        return out

    z = (sub["median"] - truth) / np.where(sub["std"] > 0, sub["std"], np.nan)
    return {
        **cov(np.ones(truth.size, dtype=bool)),
        "converged_fraction": float(np.mean(conv)) if conv.size else None,
        "converged_only": cov(conv),
        "normalised_error_mean": _json_number(float(np.nanmean(z))) if z.size else None,
        "normalised_error_sd": _json_number(float(np.nanstd(z))) if z.size else None,
        "median_posterior_sd_m": _json_number(float(np.median(sub["std"]))) if z.size else None,
        "median_abs_error_m": (
            _json_number(float(np.median(np.abs(sub["median"] - truth)))) if z.size else None
        ),
    }
