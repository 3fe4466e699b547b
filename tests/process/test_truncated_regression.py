"""The truncated-normal line recovers a known line from points seen only above their floors."""

import numpy as np
import pytest

from pipeline.process.no_bottom import excess_decay_per_s
from pipeline.process.truncated_regression import truncated_line_fit


def _truncated(seed, n=20_000, a=2.0, b=-0.5, s=0.8):
    """Draws about a known line, each kept only at or above its own (noisy, rising) floor."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(0.0, 10.0, n)
    y = a + b * t + rng.normal(0.0, s, n)
    floor = -1.5 + 0.05 * t + rng.normal(0.0, 0.2, n)
    keep = y >= floor
    return t[keep], y[keep], floor[keep], keep.mean()


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_known_line_is_recovered_where_least_squares_is_not(seed):
    t, y, floor, kept = _truncated(seed)
    assert 0.5 < kept < 0.8  # deep points really are cut
    a, b, s = truncated_line_fit(t, y, floor)
    # n ~ 13 000: the slope's standard error is ~0.005
    assert b == pytest.approx(-0.5, abs=0.02)
    assert a == pytest.approx(2.0, abs=0.08)
    assert s == pytest.approx(0.8, abs=0.03)
    # the selection flattens an ordinary least-squares line by a quarter
    b_ls = np.polyfit(t, y, 1)[0]
    assert b_ls > -0.4


def test_without_truncation_it_is_least_squares():
    rng = np.random.default_rng(7)
    t = rng.uniform(-3.0, 5.0, 500)
    y = 0.3 + 1.7 * t + rng.normal(0.0, 0.2, t.size)
    b_ls, a_ls = np.polyfit(t, y, 1)
    a, b, s = truncated_line_fit(t, y, np.full(t.size, -np.inf))
    assert a == pytest.approx(a_ls, abs=1e-5) and b == pytest.approx(b_ls, abs=1e-5)
    assert s == pytest.approx(np.std(y - (a_ls + b_ls * t)), rel=1e-4)
    with pytest.raises(ValueError):
        truncated_line_fit(np.ones(5), y[:5], y[:5] - 1.0)


def test_points_all_on_their_floors_pin_no_line_and_give_least_squares(recwarn):
    # each point its own floor: the likelihood grows without end as the line runs off below
    # (every point a rarer survivor); the fit must not follow it, nor warn on the way
    rng = np.random.default_rng(0)
    t = rng.uniform(0.0, 10.0, 500)
    y = 1.0 - 0.1 * t + rng.normal(0.0, 0.3, t.size)
    b_ls, a_ls = np.polyfit(t, y, 1)
    a, b, s = truncated_line_fit(t, y, y)
    assert a == pytest.approx(a_ls, rel=1e-9) and b == pytest.approx(b_ls, rel=1e-9)
    assert np.isfinite(s) and not [w for w in recwarn if issubclass(w.category, RuntimeWarning)]


def test_extra_decay_of_selected_bottoms():
    # losses falling at 0.02 per ns, selected above floors that deep bottoms sit near: the
    # truncated fit gives the decay, a least-squares line about two thirds of it
    rng = np.random.default_rng(5)
    t_s = rng.uniform(20e-9, 150e-9, 30_000)
    loss = -0.2 - 0.02e9 * t_s + rng.normal(0.0, 0.6, t_s.size)
    floor = -2.8 + rng.normal(0.0, 0.3, t_s.size)
    keep = loss >= floor
    delta = excess_decay_per_s(t_s[keep], loss[keep], floor[keep])
    assert delta == pytest.approx(0.02e9, rel=0.05)
    assert excess_decay_per_s(t_s[keep], loss[keep]) < 0.8 * 0.02e9
