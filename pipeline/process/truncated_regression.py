"""A straight line through points seen only above their own floors (truncated regression).

The bottoms that enter the no-bottom limit's extra decay (:mod:`pipeline.process.
detection_limit`) are those the detector found clearly: a bottom enters only if its peak is at
least twice the threshold. Deep down, where the expected bottom is near that floor, only the
bottoms that happened to come out bright are seen, so their mean log loss stays high and an
ordinary least-squares line through them falls too slowly with depth (at the limit, not at all:
a 50 m survey in clear water measured no extra decay from 36 000 bottoms while its class-45
limits lay up to 16 m under the seabed).

Each point's floor is known (the selection's amplitude in the loss's units), so the line is
fitted by maximum likelihood under the truncated normal law (Hausman & Wise 1977,
*Econometrica* 45(4), 919-938; Greene, *Econometric Analysis*, §19.2): ``y_i = a + b t_i +
e_i``, ``e_i ~ N(0, s^2)``, observed only where ``y_i >= c_i``, each point's density
``phi((y_i - mu_i)/s) / (s (1 - Phi((c_i - mu_i)/s)))``. Where the floors lie far below the
points it is the least-squares line.
"""

from __future__ import annotations

import numpy as np
from scipy import optimize, special

__all__ = ["truncated_line_fit"]

#: The residual sigma is searched within this factor of the least-squares one, either way: a
#: sample whose points all sit on their floors cannot tell a wide law far below them from a
#: narrow one at them (the likelihood runs off to an ever wider, ever lower line).
SIGMA_RANGE = 10.0
#: The fitted law must let through at least this share of the points' kind on average (the
#: truncated fits of the suite's tuning seeds 0, 6, 20 and 24 let through 93-100 %), else
#: least squares.
MIN_SEEN = 0.05


def truncated_line_fit(
    t: np.ndarray, y: np.ndarray, floor: np.ndarray
) -> tuple[float, float, float]:
    """Intercept, slope and residual sigma of ``y`` on ``t``, each ``y_i`` seen only >= ``floor_i``.

    Parameters
    ----------
    t, y, floor : (n,) array_like
        Abscissae, observations and each observation's truncation point (``y >= floor``
        where given; ``-inf``: not truncated). ``n >= 3`` and ``t`` not constant.

    Returns
    -------
    intercept, slope, sigma : float
        Of the line ``y = intercept + slope t`` and the law about it before truncation; the
        least-squares line and scatter where the fitted law would see under :data:`MIN_SEEN`
        of such points (the floors pin no line).
    """
    t = np.asarray(t, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    c = np.minimum(np.asarray(floor, dtype=np.float64), y)
    if t.size < 3 or np.ptp(t) <= 0.0:
        raise ValueError("truncated_line_fit needs >= 3 points at more than one abscissa")
    # centred and scaled abscissa: the three parameters of one order
    t0, ts = float(t.mean()), float(t.std())
    u = (t - t0) / ts
    b_ls, a_ls = np.polyfit(u, y, 1)
    s_ls = max(float(np.std(y - (a_ls + b_ls * u))), 1e-12)

    def terms(p):
        a, b, log_s = p
        s = np.exp(log_s)
        mu = a + b * u
        # a floor 40 sigma below (or -inf): no truncation, to the last bit of log Phi
        return s, (y - mu) / s, np.maximum((c - mu) / s, -40.0)

    def nll(p):
        with np.errstate(over="ignore", invalid="ignore"):
            s, z, w = terms(p)
            # log(1 - Phi(w)) = log Phi(-w), exact far into both tails
            keep = special.log_ndtr(-w)
            # d/dw log Phi(-w) = -phi(w) / Phi(-w): the inverse Mills ratio, in log space
            mills = np.exp(-0.5 * w * w - 0.5 * np.log(2.0 * np.pi) - keep)
            f = float(np.sum(0.5 * z * z + p[2] + keep))
            # gradient in (a, b, log s)
            dmu = -z / s + mills / s  # d f / d mu per point
            g = np.array(
                [
                    float(np.sum(dmu)),
                    float(np.sum(dmu * u)),
                    float(np.sum(-z * z + 1.0 + mills * w)),
                ]
            )
        if not (np.isfinite(f) and np.all(np.isfinite(g))):  # a step far out: backs off
            return np.inf, np.zeros(3)
        return f, g

    lo, hi = np.log(s_ls / SIGMA_RANGE), np.log(s_ls * SIGMA_RANGE)
    res = optimize.minimize(
        nll,
        np.array([a_ls, b_ls, np.log(s_ls)]),
        jac=True,
        method="L-BFGS-B",
        bounds=[(None, None), (None, None), (lo, hi)],
    )
    a, b, log_s = res.x
    with np.errstate(over="ignore", invalid="ignore"):
        seen = float(np.mean(special.ndtr(-terms(res.x)[2])))
    # the share of such points the fitted law would let through: a sample whose points all sit
    # on their floors pins no line (it runs off ever lower, each point a rare survivor), and
    # its least-squares line is the bounded answer
    if not (np.all(np.isfinite(res.x)) and seen >= MIN_SEEN):
        a, b, log_s = a_ls, b_ls, np.log(s_ls)
    return float(a - b * t0 / ts), float(b / ts), float(np.exp(log_s))
