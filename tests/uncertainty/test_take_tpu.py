"""take_tpu: the rows of a PointTpu, copied, or taken out of it term by term."""

from __future__ import annotations

import numpy as np

from pipeline.uncertainty.tpu_settings import PointTpu, take_tpu


def _tpu(n: int, rng) -> PointTpu:
    col = {name: rng.normal(size=n) for name in ("x", "y", "v", "h", "vr", "vc", "hr", "hc")}
    return PointTpu(
        row=np.arange(n, dtype=np.int64) * 2,
        pulse_id=np.arange(n, dtype=np.int64) + 100,
        xyz_m=rng.normal(size=(n, 3)),
        terms={k: rng.normal(size=(n, 4)) for k in ("pointing", "timing", "wave_entry")},
        sigma_x_m=col["x"],
        sigma_y_m=col["y"],
        sigma_v_m=col["v"],
        sigma_h_m=col["h"],
        sigma_v_random_m=col["vr"],
        sigma_v_correlated_m=col["vc"],
        sigma_h_random_m=col["hr"],
        sigma_h_correlated_m=col["hc"],
        sigma_depth_m=np.abs(col["v"]),
    )


def test_consuming_take_gives_the_rows_a_copy_gives_and_empties_the_source():
    rng = np.random.default_rng(3)
    src = _tpu(50, rng)
    keep = {k: v.copy() for k, v in src.terms.items()}
    index = np.array([7, 3, 3, 49, 0])
    # the reference: each array indexed by hand, independently of take_tpu
    copied = take_tpu(src, index)
    taken = take_tpu(src, index, consume=True)
    assert src.terms == {}  # the source gave its terms up
    assert set(taken.terms) == set(keep)
    for k, a in keep.items():
        np.testing.assert_array_equal(taken.terms[k], a[index])
        np.testing.assert_array_equal(copied.terms[k], a[index])
    for name in ("row", "pulse_id", "xyz_m", "sigma_v_m", "sigma_h_m", "sigma_depth_m"):
        np.testing.assert_array_equal(getattr(taken, name), getattr(src, name)[index])
        np.testing.assert_array_equal(getattr(copied, name), getattr(src, name)[index])
    assert len(taken) == index.size
