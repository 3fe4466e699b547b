"""IHO S-44 Ed. 6.0.0 allowances worked by hand, the 95 % conventions, the order of a cell."""

import math

import numpy as np
import pytest
from scipy import stats

import pipeline.evaluate as evaluate
from pipeline.iho import (
    IHO_ORDERS,
    IHO_THU,
    NO_DATA,
    NO_ORDER,
    THU95_PER_SIGMA,
    TVU95_PER_SIGMA,
    order_summary,
    strictest_order,
    thu95_m,
    thu_allowance_m,
    tvu95_m,
    tvu_allowance_m,
)


@pytest.mark.parametrize(
    ("order", "depth", "expected"),
    [
        ("special", 10.0, 0.2610),  # sqrt(0.25² + (0.0075 x 10)²) = 0.26101
        ("exclusive", 10.0, 0.1677),  # sqrt(0.0225 + 0.005625)
        ("1a", 30.0, 0.6341),  # sqrt(0.25 + 0.39²) = sqrt(0.4021)
        ("1b", 5.0, 0.5042),  # sqrt(0.25 + 0.004225)
        ("2", 100.0, 2.5080),  # sqrt(1 + 5.29)
    ],
)
def test_tvu_by_hand(order, depth, expected):
    # the table values are given to 4 decimals
    assert tvu_allowance_m(depth, order) == pytest.approx(expected, abs=5e-5)


@pytest.mark.parametrize(
    ("order", "depth", "expected"),
    [
        ("exclusive", 30.0, 1.0),
        ("special", 30.0, 2.0),
        ("1a", 40.0, 7.0),  # 5 + 0.05 x 40
        ("1b", 10.0, 5.5),
        ("2", 50.0, 25.0),  # 20 + 0.10 x 50
    ],
)
def test_thu_by_hand(order, depth, expected):
    assert thu_allowance_m(depth, order) == pytest.approx(expected, rel=1e-12)


def test_tables_and_errors():
    assert IHO_ORDERS["special"] == (0.25, 0.0075) and IHO_ORDERS["2"] == (1.0, 0.023)
    assert IHO_THU["1a"] == IHO_THU["1b"] == (5.0, 0.05)
    with pytest.raises(ValueError, match="order"):
        thu_allowance_m(1.0, "3")
    # the evaluation re-exports the same table (one source)
    assert evaluate.IHO_ORDERS is IHO_ORDERS and evaluate.tvu_allowance_m is tvu_allowance_m


def test_95_percent_conventions():
    # 1-D normal: two-sided 95 %
    assert TVU95_PER_SIGMA == pytest.approx(stats.norm.ppf(0.975), rel=1e-12)
    # circular 2-D normal, per-axis sigma: the radius is Rayleigh, P(r <= k) = 1 - exp(-k²/2)
    assert 1.0 - math.exp(-(THU95_PER_SIGMA**2) / 2.0) == pytest.approx(0.95, rel=1e-12)
    assert THU95_PER_SIGMA == pytest.approx(2.4477, abs=1e-4)
    rng = np.random.default_rng(0)
    xy = rng.normal(0.0, 0.3, (200_000, 2))
    # 200 000 draws: the fraction is within 0.2 % (4 sigma)
    assert np.mean(np.hypot(*xy.T) <= thu95_m(0.3)) == pytest.approx(0.95, abs=0.002)
    assert tvu95_m(0.1) == pytest.approx(0.196, abs=1e-4)


def test_strictest_order_by_hand():
    d = np.array([10.0, 10.0, 10.0, 10.0, 10.0, 10.0, 40.0, np.nan])
    tvu = np.array([0.10, 0.20, 0.20, 0.40, 1.00, 1.10, 0.60, 0.1])
    thu = np.array([0.50, 0.50, 1.50, 3.00, 15.0, 1.00, 6.90, 0.1])
    # 10 m: exclusive 0.1677 / 1 m, special 0.2610 / 2 m, 1a 0.5166 / 5.5 m, 2 1.0261 / 21 m
    # 40 m: 1a TVU sqrt(0.25 + 0.2704) = 0.7214, THU 7 m
    expected = [0, 1, 1, 2, 3, NO_ORDER, 2, NO_DATA]
    np.testing.assert_array_equal(strictest_order(d, tvu, thu), expected)


def test_summary_counts_and_fractions():
    codes = np.array([[0, 0, 1], [2, 3, NO_ORDER], [NO_DATA, 1, 1]])
    s = order_summary(codes)
    assert s.n_cells == 8
    assert s.labels == ("exclusive", "special", "1a/1b", "2", "none")
    assert s.counts == (2, 3, 1, 1, 1)
    np.testing.assert_allclose(s.fractions, [0.25, 0.375, 0.125, 0.125, 0.125])
    np.testing.assert_allclose(s.at_least, [0.25, 0.625, 0.75, 0.875, 1.0])
    assert "| special | 3 | 0.375 | 0.625 |" in s.table()
    assert s.to_dict()["orders"]["2"]["count"] == 1
    empty = order_summary(np.full(3, NO_DATA))
    assert empty.n_cells == 0 and empty.to_dict()["orders"]["none"]["fraction"] is None
