"""Settings of the georeferencing (:mod:`pipeline.process.refraction`): indices, a-priori sigmas.

Resolved from the scene by :func:`pipeline.process.context.processing_context`.
"""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.config import setting
from pipeline.process.scatter_bias import ScatterBiasModel

__all__ = ["RefractionSettings"]


@dataclass(frozen=True, kw_only=True)
class RefractionSettings:
    """Water indices and the a-priori uncertainty model of the georeferencing."""

    phase_index: float = setting(1.3415, ge=1.0, le=2.0, doc="water phase index (Snell)")
    group_index: float = setting(1.3638, ge=1.0, le=2.0, doc="water group index (travel time)")
    position_sigma_h_m: float = setting(0.05, ge=0.0, doc="navigation horizontal sigma")
    position_sigma_v_m: float = setting(0.08, ge=0.0, doc="navigation vertical sigma")
    pointing_sigma_deg: float = setting(0.005, ge=0.0, le=10.0, doc="beam pointing sigma")
    timing_sigma_s: float = setting(1e-10, ge=0.0, doc="per-return timing sigma if not given")
    group_index_sigma: float = setting(0.0, ge=0.0, doc="group index sigma")
    # resolved by pipeline.process.context (process.forward_scatter); None: no correction
    forward_scatter: ScatterBiasModel | None = None
    facet_mss: float = setting(
        0.0, ge=0.0, le=1.0, doc="the sea's mean-square slope whose facet excess is taken off"
    )
    facet_mss_sigma: float = setting(
        0.0, ge=0.0, le=1.0, doc="uncertainty of facet_mss (the logged wind's, via Cox-Munk)"
    )
    facet_mss_uncorrected: float = setting(
        0.0,
        ge=0.0,
        le=1.0,
        doc="the sea's mean-square slope whose facet excess is left on (the TPU budgets it)",
    )
    facet_decay_per_m: float = setting(
        0.0, ge=0.0, le=100.0, doc="lidar attenuation weighting the facets' paths (per m)"
    )
