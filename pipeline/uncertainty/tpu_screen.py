"""Pulses the first-order TPU cannot propagate: screened out and counted, never fatal.

:func:`pipeline.uncertainty.tpu.point_tpu` linearises the georeferencing about each bottom return.
That is meaningless for a bottom whose timing uncertainty is as large as its separation from
the surface return (the one-sigma interval of ``t_b - t_s`` reaches the surface: the return
cannot be told from the surface echo, and a perturbation of one sigma would put the bottom
above the water), and impossible where a term is not finite. Such pulses are left out of the
propagation with a reason (:class:`LeftOut`); a survey reports how many, its other points are
unchanged. A few odd pulses (e.g. a false bottom a few ns after the surface, whose neighbours'
scatter gives it an absurd timing sigma) must not stop a survey.

The central differences of the timing terms step at most a quarter of the surface-bottom
separation (:func:`max_timing_step_s`): the depth is linear in ``t_b - t_s``
(:func:`~pipeline.process.refraction.seabed_points`), so the step size does not change the
derivative, and a bounded step never puts the perturbed bottom before the surface.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.process.returns import DetectedReturns

__all__ = ["REASONS", "LeftOut", "max_timing_step_s", "timing_unresolved"]

#: Why a pulse was left out (``LeftOut.reason`` holds the index into this tuple).
REASONS = (
    "timing_sigma_reaches_surface",  # hypot(sigma_s, sigma_b) >= t_b - t_s
    "term_not_finite",  # a propagated term is not finite (e.g. a beam grazing its surface)
)
TIMING_REACHES_SURFACE, TERM_NOT_FINITE = range(len(REASONS))

#: Largest finite-difference step of a timing term, as a fraction of the surface-bottom gap.
_STEP_FRACTION_OF_GAP = 0.25


@dataclass(frozen=True)
class LeftOut:
    """Bottom pulses left out of the propagation.

    Attributes
    ----------
    pulse_id : (m,) int64
    reason : (m,) int64
        Index into :data:`REASONS` (the first that applies).
    """

    pulse_id: np.ndarray
    reason: np.ndarray

    @staticmethod
    def none() -> LeftOut:
        """No pulse left out."""
        return LeftOut(np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64))

    def __len__(self) -> int:
        return int(self.pulse_id.shape[0])

    def counts(self) -> dict[str, int]:
        """Number of pulses per reason (every reason, zeros included)."""
        n = np.bincount(self.reason, minlength=len(REASONS))
        return {name: int(k) for name, k in zip(REASONS, n, strict=True)}

    def concatenate(self, other: LeftOut) -> LeftOut:
        """These pulses followed by ``other``'s."""
        return LeftOut(
            np.concatenate([self.pulse_id, other.pulse_id]).astype(np.int64),
            np.concatenate([self.reason, other.reason]).astype(np.int64),
        )


def _gap_s(returns: DetectedReturns) -> np.ndarray:
    """``t_b - t_s`` where both returns exist, else ``t_b`` (n,)."""
    both = returns.has_surface & returns.has_bottom
    return np.where(both, returns.t_bottom_s - returns.t_surface_s, returns.t_bottom_s)


def max_timing_step_s(returns: DetectedReturns) -> np.ndarray:
    """Largest central-difference step of either return time (n,) s.

    A quarter of the surface-bottom separation (of ``t_b`` without a surface return, and at
    most a quarter of ``t_s``): a step of ``±h`` on one time keeps ``0 < t_s < t_b``.
    """
    gap = _gap_s(returns)
    gap = np.where(returns.has_surface, np.minimum(gap, returns.t_surface_s), gap)
    return _STEP_FRACTION_OF_GAP * gap


def timing_unresolved(
    returns: DetectedReturns, sigma_surface_s: np.ndarray, sigma_bottom_s: np.ndarray
) -> np.ndarray:
    """Reason code of every pulse whose timing the TPU cannot linearise, -1 elsewhere (n,).

    Parameters
    ----------
    returns : DetectedReturns
        Pulses with a bottom return.
    sigma_surface_s, sigma_bottom_s : (n,) float64
        The timing sigmas the TPU uses (0 for an absent surface return), finite.

    Returns
    -------
    (n,) int64
        :data:`TIMING_REACHES_SURFACE` where the one-sigma of ``t_b - t_s``,
        ``hypot(sigma_s, sigma_b)``, is not below ``t_b - t_s`` (both returns present), -1
        where the pulse can be propagated. (``DetectedReturns`` holds finite sigmas only.)
    """
    sigma_dt = np.hypot(sigma_surface_s, sigma_bottom_s)
    both = returns.has_surface & returns.has_bottom
    reaches = both & (sigma_dt >= _gap_s(returns))
    return np.where(reaches, TIMING_REACHES_SURFACE, -1).astype(np.int64)
