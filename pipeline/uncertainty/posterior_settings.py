"""Settings and per-pulse flags of the depth posterior (:mod:`pipeline.uncertainty.posterior`).

:class:`PosteriorSettings` holds the sampler's settings and the bounds of the priors (which
:mod:`pipeline.uncertainty.posterior_target` describes); :class:`PosteriorFlag` the per-pulse bits
the sampling sets.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

from pipeline.config import setting

__all__ = ["PosteriorFlag", "PosteriorSettings"]


class PosteriorFlag(enum.IntFlag):
    """Per-pulse bits of the posterior sampling."""

    #: The chain is shorter than ``tau_factor`` autocorrelation times after ``max_steps``.
    NOT_CONVERGED = 1 << 0
    #: Mean acceptance fraction outside ``acceptance_range``.
    ACCEPTANCE = 1 << 1
    #: No surface detected to start from: not sampled.
    NO_START = 1 << 2
    #: The 95 % depth interval reaches a prior bound (prior-dominated).
    AT_PRIOR_BOUND = 1 << 3
    #: The detector found no bottom: the start came from a depth scan (a weak bottom).
    START_SCANNED = 1 << 4


@dataclass(frozen=True, kw_only=True)
class PosteriorSettings:
    """Sampler settings and prior bounds."""

    n_walkers: int = setting(16, ge=16, le=1024, doc="emcee walkers (>= 2 x 9 parameters - 2)")
    burn_steps: int = setting(150, ge=0, doc="steps discarded after the start")
    restart_steps: int | None = setting(
        1500,
        ge=10,
        doc="production steps after which unconverged chains refit the proposal and restart",
    )
    chunk_steps: int = setting(100, ge=10, doc="production steps between convergence checks")
    max_steps: int = setting(4000, ge=10, doc="production steps at most")
    # 35, not emcee's conservative 50: the same coverage on the bench's tuning set and on its
    # held-out seeds at ~3/4 of the steps (benchmarks/RESULTS_posterior.md, session 35)
    tau_factor: float = setting(35.0, gt=0.0, doc="converged: chain >= this x autocorr. time")
    acceptance_range: tuple[float, float] = setting(
        (0.15, 0.8), ge=0.0, le=1.0, length=2, doc="converged: mean acceptance inside"
    )
    thin: int = setting(5, ge=1, le=100, doc="steps between stored chain samples")
    min_steps: int = setting(300, ge=0, doc="no convergence check before this many steps")
    independence_weight: float = setting(
        0.8, ge=0.0, le=1.0, doc="share of independence (Student-t) moves; the rest DE"
    )
    # chosen on tuning scenes (suite seeds 48, 47, 40), judged on the held-out half:
    # benchmarks/RESULTS_posterior.md, "Speed 7, continued"
    restart_independence_weight: float = setting(
        0.2,
        ge=0.0,
        le=1.0,
        doc="share of independence moves in the chains restarted after restart_steps",
    )
    proposal_dof: float = setting(5.0, gt=2.0, doc="Student-t degrees of freedom")
    proposal_scale: float = setting(1.2, gt=0.0, doc="proposal scale / posterior sigma")
    batch_size: int = setting(32, ge=1, le=4096, doc="pulses sampled side by side")
    init_scale: float = setting(0.5, gt=0.0, le=10.0, doc="start ball / Laplace sigma")
    max_draws: int = setting(2000, ge=50, doc="thinned draws kept per pulse")
    depth_bounds_m: tuple[float, float] = setting(
        (0.01, 100.0), gt=0.0, length=2, doc="flat prior on the depth"
    )
    area_bounds: tuple[float, float] = setting(
        (1.0, 1e9), gt=0.0, length=2, doc="log-uniform prior on the return areas, counts"
    )
    attenuation_bounds_per_m: tuple[float, float] = setting(
        (0.01, 2.0), gt=0.0, length=2, doc="log-uniform prior on the attenuation"
    )
    background_max: float = setting(1e7, gt=0.0, doc="flat prior on the background up to this")
    bottom_width_ratio_bounds: tuple[float, float] = setting(
        (0.7, 20.0), gt=0.0, length=2, doc="log-uniform prior on bottom echo / response width"
    )
    surface_width_ratio_bounds: tuple[float, float] = setting(
        (0.7, 3.0), gt=0.0, length=2, doc="log-uniform prior on surface echo / response width"
    )
    # chosen on tuning scenes only (0, 6, 19, 20, 24, 32, 231; 0.05-0.2 alike there):
    # benchmarks/RESULTS_posterior.md, "The surface echo's shape misfit"
    surface_misfit: float = setting(
        0.1,
        ge=0.0,
        le=1.0,
        doc="full waveform: sd of the surface echo's shape misfit, as a share of the echo",
    )
    marginalise_tpu: bool = setting(
        True,
        doc="seabed posterior: add the TPU's non-waveform depth terms as Gaussian nuisances",
    )
    attenuation_prior: tuple[float, float] | None = setting(
        None,
        gt=0.0,
        length=2,
        doc="(median k 1/m, sigma of ln k): log-normal prior on k; None: log-uniform",
    )

    def __post_init__(self) -> None:
        for name in (
            "depth_bounds_m",
            "area_bounds",
            "attenuation_bounds_per_m",
            "bottom_width_ratio_bounds",
            "surface_width_ratio_bounds",
        ):
            lo, hi = getattr(self, name)
            if not lo < hi:
                raise ValueError(f"`{name}` must be increasing; got {getattr(self, name)}")
        lo, hi = self.acceptance_range
        if not lo < hi:
            raise ValueError(f"`acceptance_range` must be increasing; got {(lo, hi)}")
