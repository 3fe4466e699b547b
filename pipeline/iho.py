"""IHO S-44 (6th edition, 2020) survey orders: allowed uncertainties and the order a cell meets.

Neutral module: used by processing (cell uncertainty) and by the evaluation against truth.

Table 1 of S-44 Ed. 6.0.0, maximum allowable uncertainties at the 95 % confidence level
(``d`` the depth in metres):

=========  ==================  =============  ======================
order      TVU a (m)           TVU b          THU
=========  ==================  =============  ======================
Exclusive  0.15                0.0075         1 m
Special    0.25                0.0075         2 m
1a         0.50                0.013          5 m + 5 % of depth
1b         0.50                0.013          5 m + 5 % of depth
2          1.00                0.023          20 m + 10 % of depth
=========  ==================  =============  ======================

``TVU(d) = sqrt(a² + (b d)²)``, ``THU(d) = c + p d``.

Orders 1a and 1b share their uncertainty limits (they differ in feature search and
bathymetric coverage, not assessed from uncertainties): a cell meeting them is reported as
``"1a"`` (= 1a and 1b) by :func:`strictest_order`.

95 % from one sigma (our convention)
------------------------------------
* vertical, a one-dimensional normal error: ``TVU95 = 1.96 sigma_v``
  (:data:`TVU95_PER_SIGMA`, the 97.5 % normal quantile);
* horizontal, a circular two-dimensional normal error of per-axis sigma ``sigma_h``: the
  radius holding 95 % is ``sqrt(-2 ln 0.05) sigma_h = 2.45 sigma_h``
  (:data:`THU95_PER_SIGMA`, the Rayleigh quantile).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = [
    "IHO_ORDERS",
    "IHO_THU",
    "IHO_CONFIDENCE",
    "ORDER_NAMES",
    "CLASSIFIED_ORDERS",
    "TVU95_PER_SIGMA",
    "THU95_PER_SIGMA",
    "NO_ORDER",
    "NO_DATA",
    "tvu_allowance_m",
    "thu_allowance_m",
    "tvu95_m",
    "thu95_m",
    "strictest_order",
    "OrderSummary",
    "order_summary",
]

#: IHO S-44 Ed. 6.0.0 (2020) TVU coefficients per order: (a in m, b dimensionless).
IHO_ORDERS: dict[str, tuple[float, float]] = {
    "exclusive": (0.15, 0.0075),
    "special": (0.25, 0.0075),
    "1a": (0.5, 0.013),
    "1b": (0.5, 0.013),
    "2": (1.0, 0.023),
}
#: IHO S-44 Ed. 6.0.0 (2020) THU per order: (constant in m, fraction of depth).
IHO_THU: dict[str, tuple[float, float]] = {
    "exclusive": (1.0, 0.0),
    "special": (2.0, 0.0),
    "1a": (5.0, 0.05),
    "1b": (5.0, 0.05),
    "2": (20.0, 0.10),
}
#: S-44 allowances are at 95 % confidence.
IHO_CONFIDENCE = 0.95
ORDER_NAMES = tuple(IHO_ORDERS)
#: Orders told apart by uncertainty, strictest first (1b has 1a's limits).
CLASSIFIED_ORDERS = ("exclusive", "special", "1a", "2")
#: ``strictest_order`` code of a cell that meets no order, and of a cell without data.
NO_ORDER = len(CLASSIFIED_ORDERS)
NO_DATA = -1
#: 97.5 % quantile of the standard normal: two-sided 95 % of a 1-D normal error.
TVU95_PER_SIGMA = 1.959963984540054
#: ``sqrt(-2 ln 0.05)``: 95 % radius of a circular 2-D normal, per-axis sigma.
THU95_PER_SIGMA = math.sqrt(-2.0 * math.log(1.0 - IHO_CONFIDENCE))


def _order(order: str) -> str:
    if order not in IHO_ORDERS:
        raise ValueError(f"`order` must be one of {', '.join(IHO_ORDERS)}; got {order!r}")
    return order


def tvu_allowance_m(depth_m: Any, order: str) -> np.ndarray:
    """Maximum allowable TVU ``sqrt(a^2 + (b d)^2)`` of an IHO order at depth(s) ``depth_m``."""
    a, b = IHO_ORDERS[_order(order)]
    d = np.asarray(depth_m, dtype=np.float64)
    return np.sqrt(a * a + (b * d) ** 2)[()]


def thu_allowance_m(depth_m: Any, order: str) -> np.ndarray:
    """Maximum allowable THU ``c + p d`` of an IHO order at depth(s) ``depth_m``."""
    c, p = IHO_THU[_order(order)]
    d = np.asarray(depth_m, dtype=np.float64)
    return (c + p * d)[()]


def tvu95_m(sigma_v_m: Any) -> np.ndarray:
    """95 % vertical uncertainty ``1.96 sigma_v`` of a normal error."""
    return (TVU95_PER_SIGMA * np.asarray(sigma_v_m, dtype=np.float64))[()]


def thu95_m(sigma_h_m: Any) -> np.ndarray:
    """95 % horizontal uncertainty ``2.45 sigma_h`` of a circular normal (per-axis sigma)."""
    return (THU95_PER_SIGMA * np.asarray(sigma_h_m, dtype=np.float64))[()]


def strictest_order(depth_m: Any, tvu95: Any, thu95: Any) -> np.ndarray:
    """The strictest order whose TVU and THU allowances both hold, per cell.

    Parameters
    ----------
    depth_m, tvu95, thu95 : array_like, broadcast together
        Depth (clipped at 0) and the 95 % vertical and horizontal uncertainties, metres.

    Returns
    -------
    ndarray of int8
        Index into :data:`CLASSIFIED_ORDERS`; :data:`NO_ORDER` if even order 2 fails,
        :data:`NO_DATA` where an input is NaN.
    """
    d, v, h = np.broadcast_arrays(
        *(np.asarray(a, dtype=np.float64) for a in (depth_m, tvu95, thu95))
    )
    nodata = ~(np.isfinite(d) & np.isfinite(v) & np.isfinite(h))
    d = np.where(nodata, 0.0, np.maximum(d, 0.0))
    out = np.full(d.shape, NO_ORDER, dtype=np.int8)
    # loosest first, so that the strictest order met is written last
    for i in range(len(CLASSIFIED_ORDERS) - 1, -1, -1):
        name = CLASSIFIED_ORDERS[i]
        ok = (v <= tvu_allowance_m(d, name)) & (h <= thu_allowance_m(d, name))
        out[ok] = i
    out[nodata] = NO_DATA
    return out


@dataclass(frozen=True)
class OrderSummary:
    """Cells per strictest order met.

    Attributes
    ----------
    labels : tuple of str
        ``exclusive``, ``special``, ``1a/1b``, ``2``, ``none``.
    counts : tuple of int
        Cells whose strictest order met is each label.
    fractions : tuple of float
        ``counts`` over the cells with data (NaN if none).
    at_least : tuple of float
        Fraction of cells with data meeting that order or a stricter one.
    n_cells : int
        Cells with data.
    """

    labels: tuple[str, ...]
    counts: tuple[int, ...]
    fractions: tuple[float, ...]
    at_least: tuple[float, ...]
    n_cells: int

    def to_dict(self) -> dict[str, Any]:
        """Plain data (NaN as None)."""

        def num(x):
            return None if not np.isfinite(x) else float(x)

        return {
            "n_cells": self.n_cells,
            "orders": {
                lab: {"count": c, "fraction": num(f), "at_least": num(a)}
                for lab, c, f, a in zip(
                    self.labels, self.counts, self.fractions, self.at_least, strict=True
                )
            },
        }

    def table(self) -> str:
        """A Markdown table of the summary."""
        lines = ["| order | cells | fraction | this order or stricter |", "|---|---|---|---|"]
        for lab, c, f, a in zip(
            self.labels, self.counts, self.fractions, self.at_least, strict=True
        ):
            lines.append(f"| {lab} | {c} | {f:.3f} | {a:.3f} |")
        return "\n".join(lines)


def order_summary(order_codes: Any) -> OrderSummary:
    """Counts and fractions of cells per strictest order (codes of :func:`strictest_order`)."""
    codes = np.asarray(order_codes).ravel()
    codes = codes[codes != NO_DATA]
    n = int(codes.size)
    counts = tuple(int(np.sum(codes == i)) for i in range(NO_ORDER + 1))
    fr = tuple((c / n) if n else float("nan") for c in counts)
    cum = tuple(float(np.sum(fr[: i + 1])) if n else float("nan") for i in range(NO_ORDER + 1))
    labels = (*(("1a/1b" if o == "1a" else o) for o in CLASSIFIED_ORDERS), "none")
    return OrderSummary(labels, counts, fr, cum, n)
