"""cell_inverse against numpy's own np.unique(axis=0) numbering (brute force), fuzzed."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from pipeline.cell_keys import cell_inverse


def _numpy(ij):
    return np.unique(np.asarray(ij, dtype=np.int64), axis=0, return_inverse=True)[1].ravel()


@settings(max_examples=300, deadline=None)
@given(
    arrays(
        np.int64,
        st.tuples(st.integers(0, 300), st.just(2)),
        elements=st.one_of(
            st.integers(-5, 5),  # dense: a table over the span
            st.integers(-(2**20), 2**20),  # sparse: a sort of plain integers
            st.integers(-(2**40), 2**40),  # wider than one integer holds: numpy's own
        ),
    )
)
def test_cells_numbered_as_numpy_numbers_them(ij):
    np.testing.assert_array_equal(cell_inverse(ij), _numpy(ij))


def test_a_survey_blocks_cells_in_each_of_the_three_ways():
    rng = np.random.default_rng(7)
    xy = rng.uniform(-300.0, 900.0, (200_000, 2))
    # a table over the span (5.8 k cells; 1.44 M cells, 7.2 per point), a sort (5.76 M
    # cells: 29 per point; 1e-4 m: span >> points)
    for cell_m in (5.0, 1.0, 0.5, 1e-4):
        ij = np.floor(xy / cell_m).astype(np.int64)
        np.testing.assert_array_equal(cell_inverse(ij), _numpy(ij))
    wide = np.array([[-(2**62), 0], [2**62, 5], [0, 0], [-(2**62), 0]])
    np.testing.assert_array_equal(cell_inverse(wide), [0, 2, 1, 0])
    assert cell_inverse(np.zeros((0, 2), dtype=np.int64)).shape == (0,)
