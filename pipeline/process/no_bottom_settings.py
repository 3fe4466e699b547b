"""What a class-45 "no-bottom-found-at" point assumes (``[process.no_bottom]``).

The named assumptions of :mod:`pipeline.process.detection_limit` (the bottom a class-45 point
states the absence of, the water it assumes, the probability of its claim) and what enters the
bottoms' extra-decay fit.
"""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.config import setting

__all__ = ["DEFAULT_EXCESS_DECAY_PER_M", "NoBottomSettings"]

#: Default of :attr:`NoBottomSettings.default_excess_decay_per_m` (1/m).
DEFAULT_EXCESS_DECAY_PER_M = 0.06


@dataclass(frozen=True, kw_only=True)
class NoBottomSettings:
    """Assumptions of the no-bottom-found-at depth (``[process.no_bottom]``)."""

    # 0.15: a mid value of sand/mud seabed reflectances at 532 nm used in bathymetric lidar
    # depth-performance statements (e.g. 10-20 %)
    bottom_reflectance: float = setting(
        0.15,
        ge=1e-3,
        le=1.0,
        doc="Lambertian reflectance of the bottom whose absence a class-45 point states",
    )
    # 2e-3: coastal water, Petzold (1972) coastal/harbour β(180°) ~ 1e-3 to 1e-2 m⁻¹ sr⁻¹
    backscatter_180_per_m_sr: float = setting(
        2.0e-3,
        ge=1e-5,  # pure sea water is ~1e-4 at 532 nm
        le=10.0,
        doc="water volume backscatter β(180°) processing assumes: sets the ratio of a "
        "bottom echo to the column return at the same depth",
    )
    min_column_snr: float = setting(
        3.0, ge=0.5, le=100.0, doc="column samples above this many noise σ enter the decay fit"
    )
    # the bottoms' losses are fitted as seen only above their selection floors; each floor
    # holds the pulse's own column fit, which the truncated law takes as exact: a bottom whose
    # column is a few noisy samples carries a floor as unsure as its loss (suite tuning seed 19,
    # a profiler whose columns start late behind clipped surface echoes: median sigma 14
    # nepers, and a truncated line falling at 105 /m). 0.5, set on the tuning half: tuning
    # seeds 0, 20 and 24 keep 76-88 % of their bottoms, and the truncated and least-squares
    # lines of those agree to 3-26 % (without the cut: 40-220 % apart)
    max_column_sigma: float = setting(
        0.5,
        gt=0.0,
        le=10.0,
        doc="a bottom enters the extra-decay fit only where its column's fitted log level at "
        "the bottom has at most this sigma (nepers)",
    )
    # the extra decay a survey whose own bottoms are too few to fit it (fewer than 20 enter)
    # is given. 0 claimed the weakest fading there is: suite tuning seed 25 (clear water at
    # c 0.05 /m over a 60 m seabed, no bottom entered the fit) put 579 class-45 limits more
    # than 0.5 m under the seabed, the deepest 30 m. 0.06: the median of the six tuning-half
    # surveys that fit their own (0.021-0.124 /m, seeds 0, 6, 20, 24, 32, 33), a typical
    # fading; seed 25 then has none under the seabed (at 0.02: 44), its median limit 34 -> 24 m
    # (benchmarks/RESULTS_suite.md, held-out seeds judged there)
    default_excess_decay_per_m: float = setting(
        DEFAULT_EXCESS_DECAY_PER_M,
        ge=0.0,
        le=10.0,
        doc="bottoms' extra decay (1/m of in-water path) the class-45 limits take where the "
        "survey's own bottoms are too few to fit it (fewer than 20)",
    )
    # 0.95: "no bottom down to here" is a claim; at the old one half, a bottom just above the
    # limit was missed as often as found (palmer_survey at c 0.5: 7.2 % of the limits lay below
    # the seabed, 5.3 % by more than 0.5 m; at 0.95, with the decay at its bound too, 0.8 % and
    # 0.4 %; with the extra decay fitted as a truncated line too, 0.1 % and 0.1 %, the deepest
    # 2.9 m under the seabed)
    detection_probability: float = setting(
        0.95,
        ge=0.5,
        lt=1.0,
        doc="probability with which the assumed bottom would have been detected at the "
        "class-45 limit (0.5: the threshold itself)",
    )
