"""The survey's reading of its ambiguous surface echoes: one share of clear echoes for all.

:func:`~pipeline.process.surface_step.surface_step_fit` gives each pulse two surface times, the
echo-kept fit's and the onset alone's (:class:`StepParts`). Where a pulse's echo is ambiguous (a
weak echo and an earlier onset are nearly the same waveform), its time is the onset's moved
toward the echo's by :func:`echo_weight` of the survey's share of clear echoes on a column onset
(empirical Bayes: the population sets the prior); :func:`mix_stored_echoes` sets it once every
chunk is detected, from integer counts, so the times do not depend on the chunking.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["StepParts", "echo_weight", "mixed_time", "mix_stored_echoes", "ECHO_FIELDS"]

#: The step fit's parts the survey mixes once its share of clear echoes is known
#: (:func:`echo_weight`, :func:`mix_stored_echoes`; the detector stores them per pulse, the
#: survey drops them after)
ECHO_FIELDS = ("surface_echo_state", "t_surface_onset_s", "surface_echo_shift_s")


class StepParts(NamedTuple):
    """A batch's two surface times and which of them the survey's echo prevalence mixes.

    Attributes
    ----------
    t_echo : (n,) ndarray
        Time of the fit with the echo term kept, fractional sample.
    t_onset : (n,) ndarray
        Time of the onset alone (``t_echo`` where not ``mixable``).
    clear : (n,) bool ndarray
        The echo is unambiguous: significant (``echo_sigma``) and above the onset's own peak.
    mixable : (n,) bool ndarray
        Neither clear nor timed by the echo term of necessity (window cut, no onset minimum):
        its time is ``t_onset + w (t_mix_echo − t_onset)``, ``w`` from :func:`echo_weight`.
    on_column : (n,) bool ndarray
        A clear echo on a significant column onset (``echo_sigma``): a water surface's. Only
        these count as clear in the share :func:`echo_weight` reads: a land or roof echo is as
        clear but has no column under it, and counted as a sea's it pushed every ambiguous
        echo of a calm sea beside a shore to the echo-kept time (late; issue 13, suite seed 0:
        half the swath on land, +0.46 ns, the depths 6 cm short).
    t_mix_echo : (n,) ndarray
        The echo-kept time an ambiguous echo is mixed with: ``t_echo``, but where the onset
        alone was fitted with the candidates moved back (the look-back of
        :func:`~pipeline.process.surface_step.surface_step_fit`), the
        echo-kept fit there (a weak echo on that onset, not the peak's).
    """

    t_echo: np.ndarray
    t_onset: np.ndarray
    clear: np.ndarray
    mixable: np.ndarray
    on_column: np.ndarray
    t_mix_echo: np.ndarray


def echo_weight(n_clear: int, n_mixable: int, half: float) -> float:
    """Weight of the echo-kept time of an ambiguous echo: ``p / (p + half)``.

    ``p`` is the share of the pulses judged (clear + mixable) whose echo is clear (0 without
    any judged). A weak echo and an earlier onset are nearly the same waveform (``g ∝
    ∂h/∂t_s``), so a pulse alone cannot tell them apart: where clear echoes are common (a
    wind sea) the weak ones are echoes too, where they are absent (calm water off nadir) an
    "echo" is the onset's noise. The survey's share of clear echoes is the prior (empirical
    Bayes, Efron 2010, *Large-Scale Inference*, ch. 1), ``half``
    (``detect.surface_echo_prevalence_half``) the share that weighs both times equally.
    """
    n = n_clear + n_mixable
    if n <= 0:
        return 0.0
    p = n_clear / n
    return p / (p + half)


def mixed_time(parts: StepParts, weight: float) -> np.ndarray:
    """Each pulse's surface time (fractional sample), an ambiguous echo's weighted by ``weight``."""
    mix = parts.t_onset + weight * (parts.t_mix_echo - parts.t_onset)
    return np.where(parts.mixable, mix, parts.t_echo)


def mix_stored_echoes(store, half: float, log=print) -> float:
    """Set each stored ambiguous surface echo's time from the survey's share of clear echoes.

    Each chunk's detection weighed its ambiguous echoes by its own blocks' share; the survey's
    share, from integer counts, makes every pulse's time independent of the chunking. The
    parts (:data:`ECHO_FIELDS`) are dropped from the store.

    Parameters
    ----------
    store : DetectionStore
        The survey's stored chunks (:class:`~pipeline.detection_store.DetectionStore`).
    half : float
        ``half`` of :func:`echo_weight`.
    log : callable

    Returns
    -------
    float
        The weight of the echo-kept time.
    """
    n_clear = n_mix = 0
    for c in range(len(store.chunks)):
        state = store.load_chunk(c, ["surface_echo_state"])["surface_echo_state"]
        n_clear += int(np.count_nonzero(state == 1))  # a clear echo on a column onset
        n_mix += int(np.count_nonzero(state < 0))
    w = echo_weight(n_clear, n_mix, half)
    for c in range(len(store.chunks)):
        d = store.load_chunk(c, ["t_surface_s", *ECHO_FIELDS])
        mix = d["surface_echo_state"] < 0
        t = np.where(mix, d["t_surface_onset_s"] + w * d["surface_echo_shift_s"], d["t_surface_s"])
        store.replace_field(c, "t_surface_s", t)
    for k in ECHO_FIELDS:
        store.drop_field(k)
    log(
        f"  surface echoes: {n_clear} clear of {n_clear + n_mix} judged; an ambiguous one's "
        f"time weighs the echo-kept fit {w:.3f}"
    )
    return w
