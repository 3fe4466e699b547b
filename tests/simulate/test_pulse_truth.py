"""The per-pulse truth remembers the sea it met, and answers exactly as the direct formula."""

import numpy as np

from pipeline.simulate.pulse_truth import PulseDepth
from pipeline.simulate.world import Truth


class _Sea:
    """A travelling wave written here; counts the points it is asked for."""

    evolving = True

    def __init__(self):
        self.asked = 0

    def height_m(self, x, y, t):
        self.asked += np.size(x)
        return 0.3 * np.sin(0.5 * np.asarray(x) + 0.2 * np.asarray(y) - 1.7 * np.asarray(t))


class _Plane:
    def height_m(self, x, y):
        return -5.0 - 0.1 * np.asarray(x)


def _direct(x, y, pid):
    t = 0.01 * pid
    return 0.3 * np.sin(0.5 * x + 0.2 * y - 1.7 * t) + 5.0 + 0.1 * x


def test_remembered_sea_gives_the_direct_depth_and_is_not_asked_twice():
    sea = _Sea()
    truth = Truth(seabed=_Plane(), water=sea, frame=None, pulse_time_s=lambda p: 0.01 * p)
    depth = truth.depth_at_pulses_m
    assert truth.depth_at_pulses_m is depth  # one instance per truth
    rng = np.random.default_rng(4)
    pid = rng.permutation(500)
    x, y = rng.uniform(0, 50, 500), rng.uniform(0, 50, 500)
    np.testing.assert_allclose(depth(x, y, pid), _direct(x, y, pid), rtol=0, atol=1e-12)
    assert sea.asked == 500
    # a subset in another order: all remembered
    sub = rng.choice(500, 120, replace=False)
    np.testing.assert_allclose(depth(x[sub], y[sub], pid[sub]), _direct(x[sub], y[sub], pid[sub]))
    assert sea.asked == 500
    # the same pulses at other points (uncorrected soundings) are new; repeats inside a call too
    x2 = x[:50] + 0.25
    x3 = np.concatenate([x2, x2])
    y3, p3 = np.concatenate([y[:50], y[:50]]), np.concatenate([pid[:50], pid[:50]])
    np.testing.assert_allclose(depth(x3, y3, p3), _direct(x3, y3, p3), atol=1e-12)
    assert sea.asked == 600
    np.testing.assert_allclose(depth(x2, y[:50], pid[:50]), _direct(x2, y[:50], pid[:50]))
    assert sea.asked == 600


def test_without_pulses_the_depth_is_below_the_sea_at_t0():
    truth = Truth(seabed=_Plane(), water=_Sea(), frame=None, pulse_time_s=None)
    x = np.array([[1.0, 2.0], [3.0, 4.0]])
    out = truth.depth_at_pulses_m(x, x, np.zeros((2, 2), dtype=int))
    assert out.shape == (2, 2)
    np.testing.assert_allclose(out, _direct(x, x, 0))
    assert isinstance(truth.depth_at_pulses_m, PulseDepth)


class _CountingSea(_Sea):
    """Also counts the calls: each call of a real moving sea walks its time slabs."""

    def __init__(self):
        super().__init__()
        self.calls = 0

    def height_m(self, x, y, t):
        self.calls += 1
        return super().height_m(x, y, t)


def test_the_survey_evaluation_meets_the_sea_in_one_call():
    from types import SimpleNamespace

    from pipeline.evaluate import truth_at
    from pipeline.survey_report import _meet_the_sea_once

    sea = _CountingSea()
    truth = Truth(seabed=_Plane(), water=sea, frame=None, pulse_time_s=lambda p: 0.01 * p)
    rng = np.random.default_rng(9)

    def pts(n):
        return SimpleNamespace(xyz_m=rng.uniform(0, 50, (n, 3)), pulse_id=rng.permutation(n))

    points, uncorrected, medians = pts(300), pts(300), pts(12)
    processed = SimpleNamespace(points=points, uncorrected=uncorrected)
    post = SimpleNamespace(
        posteriors=SimpleNamespace(xyz_median_m=medians.xyz_m, pulse_id=medians.pulse_id)
    )
    _meet_the_sea_once(truth.depth_at_pulses_m, processed, post)
    assert sea.calls == 1 and sea.asked == 612
    for s in (points, uncorrected, medians):  # what the evaluation then asks: remembered
        x, y = s.xyz_m[:, 0], s.xyz_m[:, 1]
        got = truth_at(truth.depth_at_pulses_m, x, y, s.pulse_id)
        np.testing.assert_allclose(got, _direct(x, y, s.pulse_id), rtol=0, atol=1e-12)
    assert sea.calls == 1


class _OrderedSea(_Sea):
    """Records each call's times: a real moving sea re-makes a slab it left for another."""

    def __init__(self):
        super().__init__()
        self.spans = []

    def height_m(self, x, y, t):
        self.spans.append((float(np.min(t)), float(np.max(t))))
        return super().height_m(x, y, t)


def test_truth_in_blocks_is_the_one_call_truth_and_meets_the_sea_in_time_order(monkeypatch):
    import pipeline.evaluate as ev

    rng = np.random.default_rng(21)
    n = 1000
    pid = rng.permutation(n)
    x, y = rng.uniform(0, 50, n), rng.uniform(0, 50, n)
    monkeypatch.setattr(ev, "TRUTH_BLOCK", 64)
    sea = _OrderedSea()
    truth = Truth(seabed=_Plane(), water=sea, frame=None, pulse_time_s=lambda p: 0.01 * p)
    got = ev.truth_at(truth.depth_at_pulses_m, x, y, pid)
    np.testing.assert_allclose(got, _direct(x, y, pid), rtol=0, atol=1e-12)
    assert len(sea.spans) == -(-n // 64) and sea.asked == n  # blocks, each pulse asked once
    # blocks in pulse (time) order: each ends before the next starts
    assert all(a[1] < b[0] for a, b in zip(sea.spans[:-1], sea.spans[1:], strict=True))

    # a static truth (no pulse ids) in blocks: the same values as one call, in the input order
    class _Still:
        def height_m(self, x, y):
            return 0.2 * np.cos(0.3 * np.asarray(x) * np.asarray(y))

    flat = Truth(seabed=_Plane(), water=_Still(), frame=None)
    want = 0.2 * np.cos(0.3 * x * y) + 5.0 + 0.1 * x
    np.testing.assert_allclose(ev.truth_at(flat.depth_m, x, y), want, rtol=0, atol=1e-12)
    monkeypatch.setattr(ev, "TRUTH_BLOCK", 10**9)
    np.testing.assert_allclose(ev.truth_at(flat.depth_m, x, y), want, rtol=0, atol=1e-12)
    assert ev.truth_at(flat.depth_m, x[:0], y[:0]).shape == (0,)
