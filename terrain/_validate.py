"""Argument checks shared by the terrain modules.

Every check raises :class:`ValueError` whose message names the parameter and echoes the value,
e.g. "`rms_height_m` must be >= 0; got -1".
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = [
    "as_rng",
    "check_bounds",
    "check_choice",
    "check_finite",
    "check_number",
    "check_points",
]


def check_number(
    name: str,
    value: Any,
    *,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    allow_inf: bool = False,
) -> float:
    """Return ``value`` as a float after checking it is a real number within the bounds.

    Parameters
    ----------
    name : str
        Parameter name used in the error message.
    value : object
        The value to check; ``bool`` is rejected.
    ge, gt, le, lt : float, optional
        Inclusive (``ge``, ``le``) and exclusive (``gt``, ``lt``) bounds.
    allow_inf : bool
        Accept +-inf (NaN is always rejected).

    Returns
    -------
    float
        The value converted to float.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"`{name}` must be a real number; got {value!r}")
    v = float(value)
    if math.isnan(v) or (math.isinf(v) and not allow_inf):
        raise ValueError(f"`{name}` must be finite; got {value!r}")
    if ge is not None and not v >= ge:
        raise ValueError(f"`{name}` must be >= {ge:g}; got {value!r}")
    if gt is not None and not v > gt:
        raise ValueError(f"`{name}` must be > {gt:g}; got {value!r}")
    if le is not None and not v <= le:
        raise ValueError(f"`{name}` must be <= {le:g}; got {value!r}")
    if lt is not None and not v < lt:
        raise ValueError(f"`{name}` must be < {lt:g}; got {value!r}")
    return v


def check_choice(name: str, value: Any, choices: tuple[str, ...]) -> str:
    """Return ``value`` if it is one of ``choices``, else raise :class:`ValueError`."""
    if value not in choices:
        raise ValueError(f"`{name}` must be one of {choices}; got {value!r}")
    return value


def check_finite(name: str, array: Any) -> np.ndarray:
    """Return ``array`` as a float64 ndarray after checking every element is finite."""
    a = np.asarray(array, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        bad = a[~np.isfinite(a)].ravel()[0]
        raise ValueError(f"`{name}` must be finite everywhere; got {bad!r}")
    return a


def check_points(x_m: Any, y_m: Any) -> tuple[np.ndarray, np.ndarray]:
    """Broadcast query coordinates to a common shape as finite float64 arrays.

    Parameters
    ----------
    x_m, y_m : array_like
        Local coordinates in metres; any broadcastable shapes.

    Returns
    -------
    x, y : numpy.ndarray
        float64 arrays of the broadcast shape.
    """
    x = check_finite("x_m", x_m)
    y = check_finite("y_m", y_m)
    try:
        x, y = np.broadcast_arrays(x, y)
    except ValueError:
        raise ValueError(
            f"`x_m` and `y_m` must broadcast together; got shapes {x.shape} and {y.shape}"
        ) from None
    return x, y


def check_bounds(name: str, bounds: Any, *, allow_inf: bool = False) -> tuple[float, ...]:
    """Check a ``(xmin, xmax, ymin, ymax)`` tuple with ``xmin < xmax`` and ``ymin < ymax``."""
    try:
        values = tuple(bounds)
    except TypeError:
        raise ValueError(f"`{name}` must be (xmin, xmax, ymin, ymax); got {bounds!r}") from None
    if len(values) != 4:
        raise ValueError(f"`{name}` must be (xmin, xmax, ymin, ymax); got {bounds!r}")
    out = tuple(check_number(name, v, allow_inf=allow_inf) for v in values)
    if not (out[0] < out[1] and out[2] < out[3]):
        raise ValueError(f"`{name}` must have xmin < xmax and ymin < ymax; got {bounds!r}")
    return out


def as_rng(rng: Any) -> np.random.Generator:
    """Return a :class:`numpy.random.Generator` from a Generator or an integer seed.

    ``None`` is rejected so that every generated world is reproducible.
    """
    if isinstance(rng, np.random.Generator):
        return rng
    if isinstance(rng, (int, np.integer)) and not isinstance(rng, bool) and rng >= 0:
        return np.random.default_rng(int(rng))
    raise ValueError(
        f"`rng` must be a numpy.random.Generator or a non-negative int seed; got {rng!r}"
    )
