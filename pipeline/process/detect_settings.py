"""What the full-waveform detector assumes and chooses (:mod:`pipeline.process.detect`).

The settings alone, so the scene's keys (``process.detect.*``) are declared apart from the
detector's code; :mod:`pipeline.process.detect` re-exports :class:`DetectSettings`.
"""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.config import setting

__all__ = ["DetectSettings"]


@dataclass(frozen=True, kw_only=True)
class DetectSettings:
    """Detection thresholds."""

    threshold_sigma: float = setting(5.0, gt=0.0, le=100.0, doc="detection threshold, noise σ")
    noise_fraction: float = setting(
        0.1, gt=0.0, lt=0.9, doc="leading part of the window used for the noise floor"
    )
    min_separation_fwhm: float = setting(
        2.5, ge=0.5, le=20.0, doc="surface-bottom separation below which returns merge"
    )
    fit_merged: bool = setting(True, doc="separate merged returns by a two-Gaussian fit")
    surface_step: bool = setting(
        True,
        doc="time the surface with a Gaussian + column-onset step fit (unbiased by the "
        "water-column return that starts with it)",
    )
    surface_onset_decay: bool = setting(
        True,
        doc="the column onset under the surface echo decays at the pulse's measured column rate "
        "(an exponentially modified Gaussian); False: a plain smoothed step",
    )
    surface_echo_sigma: float = setting(
        10.0,
        gt=0.0,
        doc="a surface echo is clear (the step fit's echo-kept time taken as it is) where its "
        "fitted amplitude stands this many (residual-based, so optimistic) standard errors "
        "above 0 and above the column onset's peak; a weaker one's time is mixed from the "
        "onset alone and the echo-kept fit by the survey's share of clear echoes "
        "(surface_echo_prevalence_half). The 10 was set, as a yes/no switch, on the suite's "
        "tuning scenes 20, 43, 60 (calm) and 24 (7 m/s): 5 left the calm ones 2-5 cm shallow, "
        "50 made scene 24 0.19 m deep, 20 dropped clear echoes "
        "(SNR ~20) of the posterior tests' waveforms",
    )
    surface_echo_prevalence_half: float = setting(
        0.02,
        gt=0.0,
        lt=1.0,
        doc="share of clear surface echoes (significant and above the column onset's peak) "
        "among the survey's pulses at which an ambiguous echo's time is half the echo-kept "
        "fit's and half the onset alone's (weight p / (p + this)). Set on the tuning scenes "
        "of benchmarks/wave_refraction (seeds 7, 8: 5 m/s waves, flat 5 and 1.5 m/s) as the "
        "smallest sum of squared surface-time biases among 0.005, 0.01, 0.02, 0.05",
    )
    surface_echo_angle_bin_deg: float = setting(
        2.0,
        gt=0.0,
        le=90.0,
        doc="the survey's share of clear surface echoes is counted per band of this many "
        "degrees of the beam's off-nadir angle: a glint needs a facet tilted by the angle, so "
        "a scanner sweeping 0-20 degrees over a light sea sees clear echoes near nadir and "
        "none at its swath's edges, where the survey-wide share timed the onset's noise as "
        "echoes (late: the surface 3-6 cm low at 15-18 degrees, an oscillating scan's edges); "
        "a band's share leans on the survey's by surface_echo_angle_prior_pulses; 90: one "
        "share for the survey",
    )
    surface_echo_angle_prior_pulses: float = setting(
        1.0,
        ge=0.0,
        doc="pulses' worth of the survey's share of clear echoes added to each angle band's "
        "counts: a band of a few judged pulses leans on the survey's share, one of thousands "
        "reads its own (the weight p / (p + surface_echo_prevalence_half) is steep: 200 gave "
        "a band of 2600 ambiguous echoes and none clear the weight 0.55 on a survey 34 % clear)",
    )
    surface_echo_null_every: int = setting(
        16,
        ge=0,
        le=1_000_000,
        doc="one ambiguous surface echo in this many (by pulse number) is fitted again on noise "
        "alone (a parametric bootstrap of its onset-alone fit and the receiver's noise): the "
        "survey's echo-kept shifts against those tell a sea of weak echoes (light wind off "
        "nadir) from noise (pipeline/process/surface_echo_null.py); 0: no such test",
    )
    surface_echo_null_z: float = setting(
        3.0,
        gt=0.0,
        doc="the survey's ambiguous echoes are echoes (their times take the echo-kept fit) "
        "where their shifts exceed (1 + surface_echo_null_excess) times the null's by this "
        "many standard errors (one-sided) ...",
    )
    surface_echo_null_excess: float = setting(
        0.20,
        ge=0.0,
        doc="... the margin, a share of the null's mean shift: the null is a model of the "
        "noise, a little off where the signal is weakest. Set on the light-wind tuning scene "
        "7102's geometry at six altitudes, waters and angles (benchmarks/surface_glint.py, "
        "every pulse resampled): calm flat water read -8 to +16 % (the most at 761 m), the "
        "weak glints at 2.7 m/s +27 to +42 %",
    )
    surface_echo_null_max_clear: float = setting(
        0.01,
        ge=0.0,
        le=1.0,
        doc="... and the survey's clear echoes are rarer than this share of those judged: flat "
        "water in a light wind glints weakly in every footprint, a wave sea's facets glint "
        "clearly in some and not in others, where the clear share's weight stands (set on the "
        "suite's tuning scenes: 7102, light wind on flat water, 0-0.3 % clear, the depths "
        "+0.045 -> -0.003 m; the wave scenes 6 and 25, 5.5 and 2.8 % clear, whose biases the "
        "echo-kept fit made worse: +0.004 -> -0.004 and -0.025 -> -0.053 m)",
    )
    trend_fwhm: float = setting(
        8.0, ge=2.0, le=100.0, doc="running-median width (system FWHMs) of the column trend"
    )
    column_returns: bool = setting(
        True, doc="report the strongest significant in-column return between surface and bottom"
    )
    bottom_pick: str = setting(
        "strongest",
        choices=("strongest", "last"),
        doc="bottom among the candidates: the strongest, or the last (a scattering layer "
        "stronger than the seabed then stays an in-column return)",
    )
    max_plateau_fwhm: float = setting(
        6.0,
        ge=1.0,
        le=100.0,
        doc="longest clipped plateau (system FWHMs) taken for one echo; longer, it runs on "
        "into the column and the bottom: the surface is not timed, no bottom is reported",
    )
