"""Settings of the trace stage (kept apart so scene validation does not import open3d)."""

from __future__ import annotations

from dataclasses import dataclass

from pipeline.config import setting

__all__ = ["TraceSettings"]


@dataclass(frozen=True, kw_only=True)
class TraceSettings:
    """How finely each beam footprint is sampled."""

    subrays: int = setting(1, ge=1, le=1000, doc="sub-rays per pulse across the divergence cone")
    cone_extent: float = setting(
        1.5, gt=0.0, le=3.0, doc="sub-rays reach this many 1/e² half-angles off the beam axis"
    )
    nthreads: int = setting(0, ge=0, le=256, doc="open3d ray-casting threads (0 = all cores)")
