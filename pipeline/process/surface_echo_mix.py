"""The survey's reading of its ambiguous surface echoes: its share of clear echoes, by angle.

:func:`~pipeline.process.surface_step.surface_step_fit` gives each pulse two surface times, the
echo-kept fit's and the onset alone's (:class:`StepParts`). Where a pulse's echo is ambiguous (a
weak echo and an earlier onset are nearly the same waveform), its time is the onset's moved
toward the echo's by :func:`echo_weight` of the survey's share of clear echoes on a column onset
(empirical Bayes: the population sets the prior), counted per band of the beams' off-nadir angle
(:func:`band_weights`: a glint needs a facet tilted by the angle, so a scan has clear echoes near
nadir and none at its edges over a light sea); :func:`mix_stored_echoes` sets it once every
chunk is detected, from integer counts, so the times do not depend on the chunking.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

__all__ = [
    "StepParts",
    "angle_band",
    "echo_weight",
    "band_weights",
    "mixed_time",
    "mix_stored_echoes",
    "weak_echo_test",
    "ECHO_FIELDS",
    "NULL_FIELD",
]

#: The step fit's parts the survey mixes once its share of clear echoes is known
#: (:func:`echo_weight`, :func:`mix_stored_echoes`; the detector stores them per pulse, the
#: survey drops them after)
ECHO_FIELDS = ("surface_echo_state", "t_surface_onset_s", "surface_echo_shift_s")
#: The echo-kept shift on noise alone of the pulses the detector resampled (seconds; NaN
#: elsewhere: :func:`~pipeline.process.surface_echo_null.null_shifts`)
NULL_FIELD = "surface_echo_null_shift_s"


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


def angle_band(direction: np.ndarray, band_deg: float) -> np.ndarray:
    """Band of each beam's off-nadir angle, ``floor(angle / band_deg)``, ``(n,)`` int.

    Parameters
    ----------
    direction : (n, 3) ndarray
        Measured unit beam directions.
    band_deg : float
        Width of a band (degrees).
    """
    cos = np.clip(np.abs(np.asarray(direction, dtype=np.float64)[:, 2]), 0.0, 1.0)
    return np.floor(np.degrees(np.arccos(cos)) / band_deg).astype(np.int64)


def band_weights(
    n_clear: np.ndarray, n_mixable: np.ndarray, half: float, prior_pulses: float
) -> np.ndarray:
    """:func:`echo_weight` of each off-nadir band's share of clear echoes, ``(n_bands,)``.

    A band's share is its own counts with ``prior_pulses`` pulses' worth of the survey's
    share added (``p_b = (c_b + m p) / (n_b + m)``): the survey's share is the prior of the
    bands' (empirical Bayes again), which a band of many judged pulses outweighs.

    Parameters
    ----------
    n_clear, n_mixable : (n_bands,) int
        Clear echoes on a column onset and ambiguous echoes in each band.
    half : float
        ``half`` of :func:`echo_weight`.
    prior_pulses : float
        ``m``.
    """
    c = np.asarray(n_clear, dtype=np.float64)
    n = c + np.asarray(n_mixable, dtype=np.float64)
    total = float(n.sum())
    if total <= 0.0:
        return np.zeros(n.shape)
    share = float(c.sum()) / total
    m = float(prior_pulses)
    p = np.where(n + m > 0.0, (c + m * share) / np.maximum(n + m, 1e-300), share)
    return p / (p + half)


def mixed_time(parts: StepParts, weight: float) -> np.ndarray:
    """Each pulse's surface time (fractional sample), an ambiguous echo's weighted by ``weight``."""
    mix = parts.t_onset + weight * (parts.t_mix_echo - parts.t_onset)
    return np.where(parts.mixable, mix, parts.t_echo)


def mix_stored_echoes(
    store,
    half: float,
    log=print,
    null_z: float = 3.0,
    null_excess: float = 0.20,
    null_max_clear: float = 0.01,
    band_deg: float = 90.0,
    prior_pulses: float = 0.0,
) -> float:
    """Set each stored ambiguous surface echo's time from the survey's share of clear echoes.

    Each chunk's detection weighed its ambiguous echoes by its own blocks' share; the survey's
    share, from integer counts, makes every pulse's time independent of the chunking. The
    share is counted per band of the beams' off-nadir angle (:func:`angle_band`,
    :func:`band_weights`): glints need facets tilted by the angle, so a scan over a light sea
    has clear echoes near nadir and none off it. Where the detector resampled some of them on
    noise alone (:data:`NULL_FIELD`), the survey's shifts against those may show its ambiguous
    echoes to be echoes (:func:`weak_echo_test`): where its clear echoes are also rarer than
    ``null_max_clear`` (a sea whose glints are weak in every footprint, not one whose facets
    glint in some), they take the echo-kept fit (weight 1). The parts (:data:`ECHO_FIELDS`,
    :data:`NULL_FIELD`) are dropped from the store.

    Parameters
    ----------
    store : DetectionStore
        The survey's stored chunks (:class:`~pipeline.detection_store.DetectionStore`).
    half : float
        ``half`` of :func:`echo_weight`.
    log : callable
    null_z, null_excess : float
        ``z_min`` and ``excess_min`` of the weak-echo test.
    null_max_clear : float
        Largest share of clear echoes among the judged at which the test's verdict counts.
    band_deg : float
        Width of the off-nadir bands (degrees; 90: one share for the survey).
    prior_pulses : float
        ``prior_pulses`` of :func:`band_weights`.

    Returns
    -------
    (float, dict)
        The survey-wide weight of the echo-kept time (one band), and the figures behind the
        times (JSON-ready: the evaluation records them): ``clear``, ``ambiguous``,
        ``weight``, ``bands`` (per off-nadir band with judged pulses: its lower angle, counts
        and weight), ``weak_echoes`` (the test's figures and ``taken``; None without
        resampled pulses).
    """
    n_clear = n_mix = 0
    band_clear: dict[int, int] = {}
    band_mix: dict[int, int] = {}
    shifts, nulls = [], []
    weak_figures = None
    for c in range(len(store.chunks)):
        has_null = NULL_FIELD in store.fields(c)
        names = ["surface_echo_state", "direction_meas"]
        names += [*(("surface_echo_shift_s", NULL_FIELD) if has_null else ())]
        d = store.load_chunk(c, names)
        state = d["surface_echo_state"]
        band = angle_band(d["direction_meas"], band_deg)
        for counts, judged in ((band_clear, state == 1), (band_mix, state < 0)):
            # a clear echo on a column onset; an ambiguous one
            for b, k in zip(*np.unique(band[judged], return_counts=True), strict=True):
                counts[int(b)] = counts.get(int(b), 0) + int(k)
        n_clear += int(np.count_nonzero(state == 1))
        n_mix += int(np.count_nonzero(state < 0))
        if has_null:
            pair = (state < 0) & np.isfinite(d[NULL_FIELD])
            shifts.append(d["surface_echo_shift_s"][pair])
            nulls.append(d[NULL_FIELD][pair])
    w = echo_weight(n_clear, n_mix, half)
    bands = np.array(sorted(set(band_clear) | set(band_mix)), dtype=np.int64)
    bc = np.array([band_clear.get(int(b), 0) for b in bands], dtype=np.int64)
    bm = np.array([band_mix.get(int(b), 0) for b in bands], dtype=np.int64)
    wb = band_weights(bc, bm, half, prior_pulses)
    if shifts:
        shift, null = np.concatenate(shifts), np.concatenate(nulls)
        weak, fig = weak_echo_test(shift, null, null_z, null_excess)
        clear_share = n_clear / max(n_clear + n_mix, 1)
        taken = weak and clear_share < null_max_clear
        if fig["z"] is not None:
            verdict = "no echoes told from the noise"
            if taken:
                verdict = "echoes: the ambiguous ones take the echo-kept fit"
            elif weak:
                verdict = f"echoes, but {100.0 * clear_share:.1f} % are clear: their share weighs"
            log(
                f"  weak surface echoes: the echo-kept shift exceeds noise's by "
                f"{100.0 * fig['excess']:.0f} % (z = {fig['z']:.1f}; beyond the margin "
                f"{fig['z_excess']:.1f}, "
                f"{fig['pairs']} pulses resampled): {verdict}"
            )
        if taken:
            w = 1.0
            wb = np.ones_like(wb)
        weak_figures = {
            "pairs": fig["pairs"],
            "z": fig["z"],
            "excess": fig["excess"],
            "z_excess": fig["z_excess"],
            "null_mean_shift_s": fig["null_mean"],  # the shifts are stored in seconds
            "echoes": bool(weak),
            "clear_share": clear_share,
            "taken": taken,
        }
    for c in range(len(store.chunks)):
        d = store.load_chunk(c, ["t_surface_s", "direction_meas", *ECHO_FIELDS])
        mix = d["surface_echo_state"] < 0
        # every judged pulse's band is one of `bands`; the others are not mixed (their index
        # is only kept in range)
        at = np.searchsorted(bands, angle_band(d["direction_meas"], band_deg))
        wp = wb[np.minimum(at, bands.size - 1)] if bands.size else np.zeros(mix.size)
        t = np.where(mix, d["t_surface_onset_s"] + wp * d["surface_echo_shift_s"], d["t_surface_s"])
        store.replace_field(c, "t_surface_s", t)
    for k in (*ECHO_FIELDS, NULL_FIELD):
        store.drop_field(k)
    spread = f"{wb.min():.3f}-{wb.max():.3f} by off-nadir angle" if bands.size > 1 else f"{w:.3f}"
    log(
        f"  surface echoes: {n_clear} clear of {n_clear + n_mix} judged; an ambiguous one's "
        f"time weighs the echo-kept fit {spread}"
    )
    summary = {
        "clear": n_clear,
        "ambiguous": n_mix,
        "weight": w,
        "bands": [
            {
                "from_deg": float(b * band_deg),
                "clear": int(k),
                "ambiguous": int(m),
                "weight": float(x),
            }
            for b, k, m, x in zip(bands, bc, bm, wb, strict=True)
        ],
        "weak_echoes": weak_figures,
    }
    return w, summary


def weak_echo_test(
    shift_s: np.ndarray, null_s: np.ndarray, z_min: float, excess_min: float
) -> tuple[bool, dict]:
    """Whether a survey's ambiguous surface echoes are echoes, from its pulses' shifts.

    The observed shifts must exceed the null's by more than ``excess_min`` of them, with
    significance: ``mean(e) / se(e) >= z_min`` for ``e = shift - (1 + excess_min) null``
    (one-sided). The margin is there because the null is a model of the noise, a little off
    where the signal is weakest (calm water from 761 m read +10 % over 3300 pulses); testing
    the margin itself, not a point estimate of the excess against it, keeps a small survey's
    scatter from reading as echoes (the same calm water, 840 pulses, read +25 % once).

    Parameters
    ----------
    shift_s, null_s : (k,) ndarray
        The observed and the null echo-kept shifts of the resampled pulses (any unit; finite).
    z_min : float
        Smallest significance of the excess beyond the margin.
    excess_min : float
        The margin, a share of the null's mean shift.

    Returns
    -------
    (bool, dict)
        The verdict and its figures, JSON-ready: ``pairs``, ``z`` (of ``shift - null``),
        ``excess`` (``mean(shift - null) / mean(null)``), ``z_excess`` (the verdict's) and
        ``null_mean``. Sums are exact (:func:`math.fsum`): the same figures in any order of
        the pulses.
    """
    shift = np.asarray(shift_s, dtype=np.float64)
    null = np.asarray(null_s, dtype=np.float64)
    k = shift.size
    fig = {"pairs": int(k), "z": None, "excess": None, "z_excess": None, "null_mean": None}
    if k < 30:
        return False, fig

    def mean_z(d):
        mean = math.fsum(d.tolist()) / k
        var = math.fsum(((d - mean) ** 2).tolist()) / (k - 1)
        return mean, (mean / math.sqrt(var / k) if var > 0.0 else 0.0)

    mean_d, z = mean_z(shift - null)
    _, z_excess = mean_z(shift - (1.0 + excess_min) * null)
    null_mean = math.fsum(null.tolist()) / k
    excess = mean_d / null_mean if null_mean > 0.0 else 0.0
    fig.update(
        z=float(z), excess=float(excess), z_excess=float(z_excess), null_mean=float(null_mean)
    )
    return bool(z_excess >= z_min), fig
