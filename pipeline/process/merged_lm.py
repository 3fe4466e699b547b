"""The Levenberg-Marquardt loop of :func:`pipeline.process.detect_merged.fit_merged`, compiled.

Per pulse, over its slice of samples: the model (surface and bottom Gaussians and the column
onset, see :func:`~pipeline.process.detect_merged.fit_merged`) and its Jacobian in one pass, the
damped normal equations solved by Gaussian elimination with partial pivoting, the step accepted
when the cost falls. The same iterations, damping and bounds as the array form; the sums run in
a fixed order per pulse (so a pulse's fit does not depend on the batch) and differ from
numpy's pairwise sums and LAPACK's solve only by rounding.
"""

from __future__ import annotations

import math

import numba
import numpy as np

__all__ = ["lm_fit"]

_SQRT_2PI = math.sqrt(2.0 * math.pi)


@numba.njit(cache=True, nogil=True)
def _model(x, y, win, p, kk, sg, npar, jac, r, want_jac):  # pragma: no cover - compiled
    """Cost over the window.

    With ``want_jac`` also fills ``jac`` (w, npar) and the residuals ``r`` (w,), both zero
    outside the window.
    """
    cost = 0.0
    s1 = p[5]
    for j in range(x.size):
        tau = x[j] - p[0]
        u1 = tau / s1
        g1 = math.exp(-0.5 * u1 * u1)
        u2 = (x[j] - p[1]) / sg
        g2 = math.exp(-0.5 * u2 * u2)
        decay = math.exp(-kk * max(tau, 0.0))
        zt = tau / sg
        col = 0.5 * math.erfc(-zt / math.sqrt(2.0)) * decay
        f = p[2] * g1 + p[3] * g2 + p[4] * col
        if win[j]:
            cost += (f - y[j]) ** 2
        if want_jac:
            if not win[j]:
                r[j] = 0.0
                for i in range(npar):
                    jac[j, i] = 0.0
                continue
            r[j] = f - y[j]
            dcol = -math.exp(-0.5 * zt * zt) / (sg * _SQRT_2PI) * decay
            if tau > 0.0:
                dcol += kk * col
            jac[j, 0] = p[2] * g1 * tau / s1**2 + p[4] * dcol
            jac[j, 1] = p[3] * g2 * (x[j] - p[1]) / sg**2
            jac[j, 2] = g1
            jac[j, 3] = g2
            if npar > 4:
                jac[j, 4] = col
                jac[j, 5] = p[2] * g1 * tau**2 / s1**3
    return cost


@numba.njit(cache=True, nogil=True)
def _solve(a, b, npar):  # pragma: no cover - compiled
    """``a x = b`` in place for a small dense system (partial pivoting); returns ok."""
    for c in range(npar):
        piv = c
        for r in range(c + 1, npar):
            if abs(a[r, c]) > abs(a[piv, c]):
                piv = r
        if a[piv, c] == 0.0:
            return False
        if piv != c:
            for k in range(npar):
                a[c, k], a[piv, k] = a[piv, k], a[c, k]
            b[c], b[piv] = b[piv], b[c]
        for r in range(c + 1, npar):
            fac = a[r, c] / a[c, c]
            for k in range(c, npar):
                a[r, k] -= fac * a[c, k]
            b[r] -= fac * b[c]
    for c in range(npar - 1, -1, -1):
        s = b[c]
        for k in range(c + 1, npar):
            s -= a[c, k] * b[k]
        b[c] = s / a[c, c]
    return True


@numba.njit(cache=True, nogil=True)
def lm_fit(x, y, win, p0, kk, sg, npar, iterations):  # pragma: no cover - compiled
    """Fit every pulse; returns the parameters ``(n, 6)`` and the final cost ``(n,)``.

    Parameters
    ----------
    x, y : (n, w) float64
        Sample positions and filtered samples of each pulse's slice.
    win : (n, w) bool
        Samples that count.
    p0 : (n, 6) float64
        Start: t_s, t_b, a_s, a_b, column b, surface σ.
    kk : (n,) float64
        Column decay rate per sample.
    sg : float
        σ of the filtered system response, samples.
    npar : int
        6 (with the column and the free width) or 4 (two Gaussians).
    iterations : int
    """
    n, w = x.shape
    p_out = p0.copy()
    c_out = np.empty(n)
    jac, jac_t = np.empty((w, 6)), np.empty((w, 6))
    r, r_t = np.empty(w), np.empty(w)
    jtj = np.empty((6, 6))
    step = np.empty(6)
    trial = np.empty(6)
    gram = np.empty((6, 6))  # JᵀJ and -Jᵀr at the current point, undamped
    grad = np.empty(6)
    for q in range(n):
        p = p_out[q]
        lam = 1e-2
        # the model and its Jacobian at the trial point serve the next step when it is taken
        c = _model(x[q], y[q], win[q], p, kk[q], sg, npar, jac, r, True)
        moved = True
        for _ in range(iterations):
            if moved:
                # (JᵀJ is symmetric: its lower half is the upper's, the same products summed
                # in the same order; a rejected step leaves the point, and these, as they were)
                for i in range(npar):
                    for k in range(i, npar):
                        s = 0.0
                        for j in range(w):
                            s += jac[j, i] * jac[j, k]
                        gram[i, k] = s
                        gram[k, i] = s
                    s = 0.0
                    for j in range(w):
                        s += jac[j, i] * r[j]
                    grad[i] = -s  # -Jᵀr
            for i in range(npar):
                step[i] = grad[i]
                for k in range(npar):
                    jtj[i, k] = gram[i, k]
            for i in range(npar):
                jtj[i, i] += lam * (jtj[i, i] + 1e-12)
            ok = _solve(jtj, step, npar)
            for i in range(6):
                trial[i] = p[i] + (step[i] if (ok and i < npar) else 0.0)
            # a negative column is not physical, nor a surface echo narrower than the system's
            trial[4] = max(trial[4], 0.0)
            trial[5] = min(max(trial[5], sg), 3.0 * sg)
            c_new = _model(x[q], y[q], win[q], trial, kk[q], sg, npar, jac_t, r_t, True)
            moved = ok and c_new < c
            if moved:
                for i in range(6):
                    p[i] = trial[i]
                c = c_new
                jac, jac_t = jac_t, jac
                r, r_t = r_t, r
                lam *= 0.3
            else:
                lam *= 10.0
        c_out[q] = c
    return p_out, c_out
