"""Error types of the pipeline, one per kind of failure.

Messages name the key or parameter, echo the value and say what is allowed.
"""

from __future__ import annotations


class BathyError(Exception):
    """Base class of every error the pipeline raises on purpose."""


class SceneError(BathyError, ValueError):
    """A scene file or settings value is invalid (unknown key, wrong type, out of range)."""


class NumericalError(BathyError, ArithmeticError):
    """A computation produced a non-finite or otherwise unusable value."""
