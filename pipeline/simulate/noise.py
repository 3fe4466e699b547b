"""Chunk-invariant random processes: navigation errors and slow attitude drift.

Every random number of the survey simulation is a pure function of ``(seed, stream, index)``,
never of the order in which pulses are generated, so a survey split into chunks of any size
gives bit-identical results:

* **White noise per pulse** is drawn in fixed blocks of :data:`PULSE_BLOCK` pulses; block ``b``
  of stream ``s`` comes from ``numpy.random.default_rng([seed, s, 0, b + 2**40])`` and the
  pulses a chunk needs are sliced out of the (at most two) blocks it touches.
* **Time-correlated noise** is a first-order Gauss–Markov (exponentially correlated) process
  built on a fixed time grid of *knots* ``t_k = k * dt`` with ``dt = tau / KNOTS_PER_TAU``.
  Knot innovations are white normals drawn in fixed blocks of :data:`KNOT_BLOCK` knots (seed
  ``[seed, s, 1, b + 2**40]``). The knot value is the moving average
  ``X_k = sum_{m<L} w_m e_{k-m}`` with ``w_m = exp(-m dt / tau)`` truncated at
  ``L = KERNEL_TAUS * KNOTS_PER_TAU`` taps (neglected weight ``exp(-2 * KERNEL_TAUS)``, about
  6e-6 of the variance) and normalised to unit variance. This is the AR(1) recursion unrolled,
  so adjacent knots have correlation ``exp(-dt / tau)`` like the Gauss–Markov process, but each
  knot depends only on ``L`` stored innovations: no state is carried from earlier chunks.
  Between knots the value is linearly interpolated and divided by the exact standard deviation
  of the interpolant, so the marginal standard deviation is exactly 1 at every time.
  The sums run tap by tap in a fixed order, so a knot's value does not depend on which chunk
  asked for it.

A chunk touching ``n`` pulses spanning ``T`` seconds allocates ``O(n + T / dt + L)`` numbers
plus one fixed-size block per stream, independent of the survey length.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pipeline.config import setting

__all__ = [
    "NavigationNoiseSettings",
    "block_normals",
    "gauss_markov",
    "navigation_errors",
    "PULSE_BLOCK",
    "KNOT_BLOCK",
    "KNOTS_PER_TAU",
    "KERNEL_TAUS",
    "MIN_CORRELATION_TIME_S",
]

PULSE_BLOCK = 4096
"""Pulses per white-noise block."""
KNOT_BLOCK = 1024
"""Knots per block of Gauss–Markov innovations."""
KNOTS_PER_TAU = 16
"""Knot spacing of the Gauss–Markov grid: ``dt = tau / KNOTS_PER_TAU``."""
KERNEL_TAUS = 6
"""Length of the truncated exponential kernel, in correlation times."""
MIN_CORRELATION_TIME_S = 1e-3
"""Smallest non-zero correlation time accepted (keeps the knot grid O(pulses))."""

# Stream identifiers: one independent random stream per quantity.
STREAM_GNSS = 1
STREAM_INS = 2
STREAM_ATTITUDE_DRIFT = 3
STREAM_ATTITUDE_PHASE = 4

_KIND_PULSE = 0
_KIND_KNOT = 1
_BLOCK_OFFSET = 1 << 40  # keeps block indices non-negative for SeedSequence


@dataclass(frozen=True)
class NavigationNoiseSettings:
    """Errors of the navigation solution (GNSS position, INS attitude) seen by processing.

    Each error is a zero-mean first-order Gauss–Markov process with the given standard
    deviation and correlation time (exponential autocorrelation ``exp(-|lag| / tau)``), or white
    noise drawn independently for every pulse when the correlation time is 0. The horizontal
    sigma applies to each of east and north separately.
    """

    gnss_horizontal_sigma_m: float = setting(
        0.03,
        ge=0.0,
        le=100.0,
        doc="GNSS position error per horizontal axis, standard deviation (m)",
    )
    gnss_vertical_sigma_m: float = setting(
        0.05, ge=0.0, le=100.0, doc="GNSS vertical position error, standard deviation (m)"
    )
    gnss_correlation_time_s: float = setting(
        60.0,
        ge=0.0,
        le=1e6,
        doc="Gauss-Markov correlation time of GNSS errors; 0 = white per pulse (s)",
    )
    ins_roll_sigma_deg: float = setting(
        0.005, ge=0.0, le=10.0, doc="INS roll error, standard deviation (deg)"
    )
    ins_pitch_sigma_deg: float = setting(
        0.005, ge=0.0, le=10.0, doc="INS pitch error, standard deviation (deg)"
    )
    ins_heading_sigma_deg: float = setting(
        0.008, ge=0.0, le=10.0, doc="INS heading (yaw) error, standard deviation (deg)"
    )
    ins_correlation_time_s: float = setting(
        10.0,
        ge=0.0,
        le=1e6,
        doc="Gauss-Markov correlation time of INS errors; 0 = white per pulse (s)",
    )

    def __post_init__(self) -> None:
        for name in ("gnss_correlation_time_s", "ins_correlation_time_s"):
            tau = getattr(self, name)
            if 0.0 < tau < MIN_CORRELATION_TIME_S:
                raise ValueError(
                    f"{name} must be 0 (white) or >= {MIN_CORRELATION_TIME_S}; got {tau}."
                )


def _check_seed(seed: int) -> int:
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer; got {seed!r}.")
    return int(seed)


def block_normals(
    seed: int, stream: int, kind: int, first: int, stop: int, ncols: int, block: int
) -> np.ndarray:
    """Draw standard normals for the indices ``first <= i < stop`` of a blocked random stream.

    Parameters
    ----------
    seed, stream, kind : int
        Identify the stream; block ``b`` is drawn from
        ``default_rng([seed, stream, kind, b + 2**40])``.
    first, stop : int
        Index range (may be negative).
    ncols : int
        Independent normals per index.
    block : int
        Indices per block.

    Returns
    -------
    numpy.ndarray
        ``(stop - first, ncols)`` float64, identical whatever range it is sliced from.
    """
    seed = _check_seed(seed)
    out = np.empty((max(stop - first, 0), ncols))
    if stop <= first:
        return out
    for b in range(first // block, (stop - 1) // block + 1):
        rng = np.random.default_rng([seed, stream, kind, b + _BLOCK_OFFSET])
        values = rng.standard_normal((block, ncols))
        lo, hi = max(first, b * block), min(stop, (b + 1) * block)
        out[lo - first : hi - first] = values[lo - b * block : hi - b * block]
    return out


def _kernel() -> tuple[np.ndarray, float]:
    """Normalised truncated exponential kernel and the adjacent-knot correlation."""
    n_taps = KERNEL_TAUS * KNOTS_PER_TAU
    w = np.exp(-np.arange(n_taps) / KNOTS_PER_TAU)
    w /= math.sqrt(float(np.sum(w * w)))
    return w, float(np.sum(w[:-1] * w[1:]))


_WEIGHTS, _RHO1 = _kernel()


def gauss_markov(t_s: np.ndarray, tau_s: float, seed: int, stream: int, ncols: int) -> np.ndarray:
    """Unit-variance first-order Gauss–Markov noise evaluated at times ``t_s``.

    Parameters
    ----------
    t_s : numpy.ndarray
        ``(n,)`` times (s); any order.
    tau_s : float
        Correlation time (s), ``>= MIN_CORRELATION_TIME_S``.
    seed, stream : int
        Random stream; independent columns share it.
    ncols : int
        Number of independent processes.

    Returns
    -------
    numpy.ndarray
        ``(n, ncols)``; a pure function of ``(t, tau, seed, stream)`` (see the module notes).
    """
    t = np.asarray(t_s, dtype=np.float64)
    if tau_s < MIN_CORRELATION_TIME_S:
        raise ValueError(f"tau_s must be >= {MIN_CORRELATION_TIME_S}; got {tau_s}.")
    if t.size == 0:
        return np.zeros((0, ncols))
    dt = tau_s / KNOTS_PER_TAU
    u = t / dt
    k = np.floor(u)
    frac = (u - k)[:, None]
    k = k.astype(np.int64)
    kmin, kmax = int(k.min()), int(k.max()) + 1
    n_taps = _WEIGHTS.size
    eps = block_normals(seed, stream, _KIND_KNOT, kmin - n_taps + 1, kmax + 1, ncols, KNOT_BLOCK)
    n_knots = kmax - kmin + 1
    knots = np.zeros((n_knots, ncols))
    for m in range(n_taps):
        start = n_taps - 1 - m
        knots += _WEIGHTS[m] * eps[start : start + n_knots]
    a, b = 1.0 - frac, frac
    norm = np.sqrt(a * a + b * b + 2.0 * _RHO1 * a * b)
    j = k - kmin
    return (a * knots[j] + b * knots[j + 1]) / norm


def _errors(
    pulse_id: np.ndarray,
    t_s: np.ndarray,
    sigmas: tuple[float, float, float],
    tau_s: float,
    seed: int,
    stream: int,
) -> np.ndarray:
    n = pulse_id.size
    sig = np.asarray(sigmas, dtype=np.float64)
    if n == 0 or not np.any(sig > 0.0):
        return np.zeros((n, 3))
    if tau_s == 0.0:
        first = int(pulse_id.min())
        unit = block_normals(
            seed, stream, _KIND_PULSE, first, int(pulse_id.max()) + 1, 3, PULSE_BLOCK
        )
        unit = unit[pulse_id - first]
    else:
        unit = gauss_markov(t_s, tau_s, seed, stream, 3)
    return unit * sig


def navigation_errors(
    pulse_id: np.ndarray, t_s: np.ndarray, nav_noise: NavigationNoiseSettings, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Navigation errors (measured minus true) of the pulses ``pulse_id`` fired at ``t_s``.

    Parameters
    ----------
    pulse_id : numpy.ndarray
        ``(n,)`` int64 global pulse indices (keys of white noise).
    t_s : numpy.ndarray
        ``(n,)`` firing times (s) (keys of Gauss–Markov noise).
    nav_noise : NavigationNoiseSettings
        Error model.
    seed : int
        Survey seed (non-negative).

    Returns
    -------
    position_error_m : numpy.ndarray
        ``(n, 3)`` east, north, up errors (m).
    attitude_error_rad : numpy.ndarray
        ``(n, 3)`` roll, pitch, heading errors (rad).
    """
    pid = np.asarray(pulse_id, dtype=np.int64)
    t = np.asarray(t_s, dtype=np.float64)
    h = nav_noise.gnss_horizontal_sigma_m
    pos = _errors(
        pid,
        t,
        (h, h, nav_noise.gnss_vertical_sigma_m),
        nav_noise.gnss_correlation_time_s,
        seed,
        STREAM_GNSS,
    )
    ins = tuple(
        math.radians(v)
        for v in (
            nav_noise.ins_roll_sigma_deg,
            nav_noise.ins_pitch_sigma_deg,
            nav_noise.ins_heading_sigma_deg,
        )
    )
    att = _errors(pid, t, ins, nav_noise.ins_correlation_time_s, seed, STREAM_INS)
    return pos, att
