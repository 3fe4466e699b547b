"""Numerical constants used across stages, each defined once.

Physical models with their own constants live with the model (Cox & Munk's slope law in
:mod:`pipeline.lidar_equation`, the sea-water index in :mod:`pipeline.optics`).
"""

from __future__ import annotations

import math

__all__ = ["FWHM_TO_SIGMA", "MAD_TO_SIGMA"]

#: A Gaussian's standard deviation per unit of its full width at half maximum, 1 / 2.3548.
FWHM_TO_SIGMA = 1.0 / (2.0 * math.sqrt(2.0 * math.log(2.0)))
#: 1.4826 × the median absolute deviation estimates the standard deviation of normal data.
MAD_TO_SIGMA = 1.4826
