"""The compiled row helpers give numpy's own figures, to the bit (pipeline.process.row_kernels)."""

import numpy as np

from pipeline.process.row_kernels import COUNT_HALF, counted_median, median_of, pairwise_sum


def test_pairwise_sum_is_numpys_sum_of_a_row_bit_for_bit():
    # lengths across numpy's branches (< 8, the 8-lane block up to 128, halved runs above),
    # magnitudes mixed so that another order of additions would show in the last bits
    rng = np.random.default_rng(3)
    lengths = [*range(0, 300), 511, 512, 513, 1000, 1023, 4097, 20_000]
    for m in lengths:
        x = rng.normal(size=m) * 10.0 ** rng.uniform(-8, 8, m)
        x[rng.random(m) < 0.3] = 0.0
        want = x.reshape(1, -1).sum(axis=1)[0]
        assert pairwise_sum(x, 0, m) == want, m
        if m > 5:  # from an offset: a row of a flattened (pulses, samples) buffer
            assert pairwise_sum(x, 5, m - 5) == x[5:].reshape(1, -1).sum(axis=1)[0], m


def test_a_plain_running_sum_would_differ():
    # the comparison above can fail: a left-to-right sum of the same rows differs
    rng = np.random.default_rng(4)
    x = rng.normal(size=(200, 500)) * 10.0 ** rng.uniform(-8, 8, (200, 500))
    running = np.array([sum(row.tolist()) for row in x])
    assert np.count_nonzero(running != x.sum(axis=1)) > 100


def test_median_of_is_numpys_median():
    rng = np.random.default_rng(5)
    for trial in range(3000):
        m = int(rng.integers(1, 700))
        v = rng.normal(size=m) * 10.0 ** rng.uniform(-3, 3)
        if trial % 3 == 0:
            v = np.round(v)  # integer codes: many ties, -0.0 beside +0.0
        assert median_of(v.copy(), m) == np.median(v), trial


def test_counted_median_is_numpys_median_of_integers_or_nan():
    rng = np.random.default_rng(7)
    counts = np.zeros(2 * COUNT_HALF + 1, np.int64)
    outside = 0
    for trial in range(3000):
        m = int(rng.integers(1, 700))
        v = np.round(rng.normal(size=m) * 10.0 ** rng.uniform(-1, 3) + rng.uniform(-1500, 1500))
        if trial % 4 == 0:  # echoes far outside the band: counted above or below it
            v[rng.integers(0, m, 1 + m // 20)] = rng.choice([-1, 1]) * 50_000.0
        got = counted_median(v.copy(), m, counts)
        want = np.median(v)
        assert not counts.any(), trial  # given back zeroed
        if np.isnan(got):  # a middle value outside [-h, h]: the caller selects instead
            outside += 1
            srt = np.sort(v)
            assert max(abs(srt[m // 2]), abs(srt[(m - 1) // 2])) > COUNT_HALF, trial
        else:
            assert got == want, trial
    assert 50 < outside < 1500  # both paths taken
    # not integers (one is enough): not counted
    v = np.array([1.0, 2.0, 2.5])
    assert np.isnan(counted_median(v, 3, counts))
    assert np.isnan(counted_median(np.array([1.0, np.nan, 2.0]), 3, counts))


def _noise_sigma_numpy(y):
    """The clipped second moment of detect_noise's docstring, in whole-array numpy."""
    from pipeline.constants import MAD_TO_SIGMA
    from pipeline.process.detect_noise import CLIP_SIGMA, N_ITER, _inside_variance_share

    d = np.diff(np.asarray(y, dtype=np.float64), axis=1)
    d -= np.median(d, axis=1)[:, None]
    a = np.abs(d)
    quantum = np.min(np.where(a > 0, a, np.inf), axis=1)
    quantum = np.where(np.isfinite(quantum), quantum, 0.0)
    s = np.maximum(MAD_TO_SIGMA * np.median(a, axis=1), quantum)
    for _ in range(N_ITER):
        lim = np.maximum(CLIP_SIGMA * s, 1.5 * quantum)
        inside = a <= lim[:, None]
        ms = np.where(inside, d * d, 0.0).sum(axis=1) / np.maximum(inside.sum(axis=1), 1)
        s = np.sqrt(ms / _inside_variance_share(lim / np.maximum(s, 1e-300)))
    return s / np.sqrt(2.0)


def test_the_noise_kernel_gives_the_whole_array_figures_bit_for_bit():
    from pipeline.process.detect_noise import difference_noise_sigma

    rng = np.random.default_rng(6)
    for trial in range(60):
        n, m = int(rng.integers(1, 200)), int(rng.integers(3, 600))
        # up to ~3000 counts of noise: medians past the counted band (selected instead)
        y = np.round(100.0 + rng.normal(0.0, 1.0, (n, m)) * 10.0 ** rng.uniform(-1.5, 3.5, (n, 1)))
        if trial % 2:
            y[:, m // 3 : m // 3 + 5] += 500.0  # echoes, clipped out
        if trial % 5 == 0:
            y = y + rng.normal(0.0, 0.3, (n, m))  # float samples
        y[0] = 7.0  # a flat row: sigma 0
        y = y.astype(np.float32 if trial % 3 == 0 else np.float64)
        got, want = difference_noise_sigma(y), _noise_sigma_numpy(y)
        assert got.tobytes() == want.tobytes(), trial
        assert got[0] == 0.0


def test_gaussian_rows_is_scipys_filter_bit_for_bit():
    from scipy.ndimage import gaussian_filter1d

    from pipeline.process.row_kernels import gaussian_rows, gaussian_weights

    rng = np.random.default_rng(8)
    for sigma in (0.3, 0.7655, 1.08, 2.3, 6.0):
        for m in (1, 2, 5, 40, 350):  # rows shorter than the kernel: "nearest" runs off both ends
            for dtype in (np.float32, np.float64):
                y = (rng.normal(100.0, 20.0, (60, m)) * 10.0 ** rng.uniform(-3, 3)).astype(dtype)
                base = rng.normal(100.0, 3.0, 60)
                want = gaussian_filter1d(
                    np.asarray(y, np.float64) - base[:, None], sigma, axis=1, mode="nearest"
                )
                got = gaussian_rows(y, base, gaussian_weights(sigma))
                assert got.tobytes() == want.tobytes(), (sigma, m, dtype)
