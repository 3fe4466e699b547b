"""How often a perfectly calibrated uncertainty would miss the coverage floors by chance alone.

The coverage floors ask for 64-72 % at 68 % and 93-97 % at 95 % in every stratum
(:mod:`pipeline.suite.report`). A stratum's coverage is a fraction of ``n`` draws: even an
uncertainty that is exactly right scatters about its nominal coverage by
``sqrt(p (1 - p) / n)``, which at the posteriors' ``n`` (60 to a few hundred per stratum) is
as wide as the band itself (``n = 60`` at 95 %: 2.8 %, the band +-2 %). This module gives the
chance that such an uncertainty falls outside the band (:func:`band_miss_probability`) and
the number of strata it would be expected to fail (:func:`expected_failures`), so the count
of failing strata is read against it.

The draws are taken as independent (binomial): the most favourable case. Errors shared by
many points (a survey's attitude, its water's forward scattering, the waves under a photon
window) make a stratum's points fewer independent draws than points, so the real chance of a
miss is larger than this; the figure is a lower bound, not an excuse.
"""

from __future__ import annotations

import math
from typing import Any

from scipy.stats import binom

__all__ = ["COVERAGE_FLOORS", "band_miss_probability", "expected_failures"]

#: coverage floor -> (figure group, key, nominal, band low, band high, minimum n)
COVERAGE_FLOORS = {
    "tpu68": ("tpu", "cov68", 0.6827, 0.64, 0.72, 200),
    "tpu95": ("tpu", "cov95", 0.95, 0.93, 0.97, 200),
    "post68": ("posterior", "cov68", 0.68, 0.64, 0.72, 60),
    "post95": ("posterior", "cov95", 0.95, 0.93, 0.97, 60),
}


def band_miss_probability(n: int, nominal: float, lo: float, hi: float) -> float:
    """Chance that ``k / n``, ``k ~ Binomial(n, nominal)``, falls outside ``[lo, hi]``.

    Parameters
    ----------
    n : int
        Draws (> 0).
    nominal : float
        True coverage of a calibrated uncertainty (0.6827 at one sigma, 0.95 at 1.96).
    lo, hi : float
        The floor's band, as fractions (``lo <= k / n <= hi`` passes).
    """
    if n <= 0:
        raise ValueError(f"`n` must be > 0; got {n}")
    k_lo = math.ceil(lo * n - 1e-9)  # the band's edges as counts, as the floors compare
    k_hi = math.floor(hi * n + 1e-9)
    p_in = binom.cdf(k_hi, n, nominal) - binom.cdf(k_lo - 1, n, nominal)
    return float(max(0.0, 1.0 - p_in))


def expected_failures(strata: list[dict[str, Any]], half: str) -> dict[str, float]:
    """Strata a calibrated uncertainty would be expected to fail, per coverage floor.

    ``strata``: :func:`pipeline.suite.strata.all_strata` rows; only those in the floors'
    window and with the floor's minimum ``n`` count, as :func:`pipeline.suite.report.floors`
    judges them.
    """
    out = dict.fromkeys(COVERAGE_FLOORS, 0.0)
    for s in strata:
        if not s["in_floor_window"]:
            continue
        for name, (group, _, nominal, lo, hi, min_n) in COVERAGE_FLOORS.items():
            n = (s[half].get(group) or {}).get("n", 0)
            if n >= min_n:
                out[name] += band_miss_probability(n, nominal, lo, hi)
    return out
