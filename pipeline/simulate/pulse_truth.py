"""The true depth below the sea each pulse saw, remembered across the evaluation's calls.

Evaluation asks for the truth many times over overlapping point sets (the points, the TPU's and
the posteriors' subsets, the per-point file, features). Under a moving sea each call meets the
surface at every pulse's time, which re-synthesises the wave field at every time slab the call
spans: with a 4096-node tile that is ~2.5 s per slab and the slab cache holds only two, so a
survey's evaluation spent ~1000 s re-making the same sea. The sea height is therefore remembered
per ``(pulse, x, y)``; the seabed, cheap and time-independent, is always evaluated.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PulseDepth"]

_M1 = np.uint64(0x9E3779B97F4A7C15)
_M2 = np.uint64(0xBF58476D1CE4E5B9)
_M3 = np.uint64(0x94D049BB133111EB)


def _keys(pulse_id: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """64-bit hash of each ``(pulse, x, y)`` (the exact bits of the coordinates)."""
    with np.errstate(over="ignore"):
        k = pulse_id.astype(np.uint64) * _M1
        k ^= np.ascontiguousarray(x, dtype=np.float64).view(np.uint64) * _M2
        k ^= np.ascontiguousarray(y, dtype=np.float64).view(np.uint64) * _M3
        k ^= k >> np.uint64(31)
        return k * _M1


class PulseDepth:
    """``Truth.depth_m`` at each point's pulse time (pipeline.evaluate's per-pulse truth).

    Parameters
    ----------
    truth : pipeline.simulate.world.Truth
    """

    per_pulse = True

    def __init__(self, truth) -> None:
        self.truth = truth
        self._keys = np.zeros(0, dtype=np.uint64)
        self._sea_m = np.zeros(0)

    def __call__(self, x_m, y_m, pulse_id=None):
        """Depth (m, positive down) at points ``(n,)``, below the sea at their pulses' times."""
        truth = self.truth
        if pulse_id is None or truth.pulse_time_s is None or not hasattr(truth.water, "evolving"):
            return truth.depth_m(x_m, y_m)
        x = np.asarray(x_m, dtype=np.float64).ravel()
        y = np.asarray(y_m, dtype=np.float64).ravel()
        pid = np.asarray(pulse_id).ravel()
        keys = _keys(pid, x, y)
        at = np.minimum(np.searchsorted(self._keys, keys), max(self._keys.size - 1, 0))
        hit = (self._keys[at] == keys) if self._keys.size else np.zeros(keys.size, dtype=bool)
        sea = np.empty(keys.size)
        sea[hit] = self._sea_m[at[hit]]
        miss = np.flatnonzero(~hit)
        if miss.size:
            t = truth.pulse_time_s(pid[miss])
            sea[miss] = truth.water.height_m(x[miss], y[miss], t)
            new_keys, first = np.unique(keys[miss], return_index=True)
            merged = np.concatenate([self._keys, new_keys])
            order = np.argsort(merged, kind="stable")
            self._keys = merged[order]
            self._sea_m = np.concatenate([self._sea_m, sea[miss][first]])[order]
        depth = sea - truth.seabed.height_m(x, y)
        return depth.reshape(np.shape(x_m))
